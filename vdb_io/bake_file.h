// The baked output VDB: layout, writing (atomic) and reading back (render, info, tests).
// Layout (docs/output_format.md):
//   sh_0 .. sh_{N-1}  Vec3f, SH coefficients of S(x, w) (ACN order, RGB in xyz),
//                     class "unknown", VEC_INVARIANT, world-space directions
//   scatter           Vec3f, direction-averaged S = sh_0 * Y00, class "fog volume"
//   density           the input density (unless --no-density), class "fog volume"
//   emission          Vec3f emitted radiance L_e used by the bake (only with --emission-grid)
//   sun_transmittance_K  float, exact sun term K (core/sun_term.h): the SH hold S without
//                     that sun's single scattering; a renderer adds E T p_HG (metadata
//                     lpm:sun_term_K_*)
// All grids share the input density's transform. `density` keeps its active topology; the
// lighting grids (sh_*, scatter, emission) hold the density's active voxels dilated by the
// trilinear footprint (vdb_io/lighting_topology.h). File metadata keys start with "lpm:".
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <openvdb/openvdb.h>

#include "core/math.h"
#include "core/medium.h"
#include "core/sh_rows.h"

namespace lpm {

/// 2: exact sun terms (sun_transmittance_K grids; the SH then leave out those suns'
/// single scattering). 1: SH only.
constexpr int kBakeFormatVersion = 2;

/// The dense solver result and where it sits in the input's index space.
/// scale == 1: dense voxel d holds the value of input voxel blockMin + d (direct lookup).
/// scale != 1 (--solve-scale): dense voxel d covers index space [corner + d / scale,
/// corner + (d + 1) / scale); an input voxel gets the trilinear interpolation of the dense
/// voxel-centred values at its centre, clamped at the block's border.
struct DenseBake {
    openvdb::Coord blockMin;               ///< index coordinate of dense voxel (0,0,0) (scale 1)
    double scale = 1.0;                    ///< dense voxels per input voxel along each axis
    openvdb::Vec3d corner{0.0, 0.0, 0.0};  ///< index-space low corner of the block (scale != 1)
    bool affine = false;                   ///< block coordinate of input index c = M c + t
    double M[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
    double t[3] = {0, 0, 0};
    int nx = 0, ny = 0, nz = 0;
    int coeffs = 1;             ///< SH coefficients per voxel
    const float* sh = nullptr;  ///< [row][coeff][rgb], x fastest; null for an empty bake
    /// Dense voxel v's row of sh (core/sh_rows.h: ShRows::kNone where none is held, S = 0);
    /// null: row = voxel.
    const std::uint32_t* shRow = nullptr;
    /// When set, sh's storage: the writer frees it once the grids that read sh are built,
    /// so the file is written without it.
    std::vector<float>* releaseSh = nullptr;
    const RGB* emission = nullptr;  ///< per dense voxel, or null
    /// Direction-averaged S per dense voxel [voxel][rgb] (the sun terms' share included);
    /// null: sh_0 * Y00.
    const float* scatter = nullptr;
    /// Per exact sun term (core/sun_term.h): its transmittance per dense voxel.
    std::vector<const float*> sunTransmittance;
    /// Storage layout of `sh`/`emission` (sparse 8^3 tiles); null = dense, x fastest.
    const Medium* layout = nullptr;
    /// Dense voxel v's SH row (coeffs x RGB), null where none is held.
    const float* shAt(size_t v) const {
        if (!shRow) return sh + v * size_t(coeffs) * 3;
        return shRow[v] == ShRows::kNone ? nullptr : sh + size_t(shRow[v]) * size_t(coeffs) * 3;
    }
    size_t index(int x, int y, int z) const {
        if (layout) return layout->index(x, y, z);
        return size_t(x) + size_t(nx) * (size_t(y) + size_t(ny) * z);
    }
    /// Continuous block coordinate along `axis` of input voxel c's centre (scale != 1 or
    /// affine): dense voxel d spans [d, d + 1), its centre at d + 0.5.
    double blockCoord(const openvdb::Coord& c, int axis) const {
        if (affine) return M[axis][0] * c[0] + M[axis][1] * c[1] + M[axis][2] * c[2] + t[axis];
        return (c[axis] - corner[axis]) * scale;
    }
};

struct BakeWriteOptions {
    std::string path;
    std::vector<std::string> inputs;  ///< files the output must never overwrite
    bool half = false;                ///< store floats as 16-bit halves
    bool zip = false;                 ///< zip-compress the grids (else only inactive values are left out)
    bool writeDensity = true;
    std::string densityName = "density";
    /// Also write the constant-free grids extinction and source (renderer_grids.h) with
    /// these medium constants.
    bool rendererGrids = false;
    double densityScale = 1.0;
    RGB albedo{0.9f, 0.9f, 0.9f};
};

struct BakeWriteReport {
    std::vector<std::string> warnings;
    double maxAbsValue = 0;           ///< largest |value| over the SH grids
    std::uint64_t voxelsWritten = 0;  ///< active voxels per lighting grid (density's + shell)
    std::uint64_t shellVoxels = 0;    ///< of which the shell around the density's active voxels
    std::uint64_t shellDropped = 0;   ///< shell voxels without solved S, left inactive (0 from readVolume)
    double seconds = 0;
    std::vector<std::string> gridNames;  ///< the grids written, in file order
};

/// Builds the grids on `density`'s transform (the lighting grids on lightingTopology(),
/// `density` on its own topology) and writes them with `meta` atomically to options.path.
/// Throws OutputError.
BakeWriteReport writeBake(const openvdb::FloatGrid& density, const DenseBake& bake, const openvdb::MetaMap& meta,
                          const BakeWriteOptions& options);

/// Name of the grid of exact sun term k: sun_transmittance_k.
inline std::string sunTransmittanceGridName(int k) { return "sun_transmittance_" + std::to_string(k); }

/// A bake read back.
struct BakeFile {
    std::string path;
    openvdb::GridPtrVec grids;  ///< every grid in the file
    openvdb::MetaMap::Ptr meta;
    std::vector<openvdb::Vec3SGrid::Ptr> sh;  ///< sh_0 .. sh_{N-1} (as many as found in a row)
    openvdb::Vec3SGrid::Ptr scatter, emission;
    openvdb::FloatGrid::Ptr density;
    std::vector<openvdb::FloatGrid::Ptr> sunTransmittance;  ///< sun_transmittance_0.. (as many as found in a row)
    int shOrder = -1;                                       ///< from metadata, -1 if absent
};

/// Reads every grid and the file metadata. Throws InputError if the file cannot be read.
BakeFile readBakeFile(const std::string& path);

/// Reasons `f` is not a valid lpmbake bake (empty when valid).
std::vector<std::string> validateBake(const BakeFile& f);

/// Metadata helpers: value of `key` or `fallback` when absent or of another type.
double metaDouble(const openvdb::MetaMap& m, const std::string& key, double fallback);
int metaInt(const openvdb::MetaMap& m, const std::string& key, int fallback);
std::string metaString(const openvdb::MetaMap& m, const std::string& key, const std::string& fallback = "");
RGB metaRgb(const openvdb::MetaMap& m, const std::string& key, const RGB& fallback);

}  // namespace lpm

// Reads a scalar density grid (and optionally an emission grid) from an OpenVDB file and
// turns it into the solver's dense core Medium.
//
// Conventions (docs/cli.md):
//  - the dense block is the grid's active bounding box plus `pad` voxels on every side
//    (at least vdb_io/lighting_topology.h's kLightingShell: the bake writes S on the
//    active voxels dilated by that shell, so the solver must compute S there; at S = 1
//    the sparse tiles allocated are those holding an active voxel or a shell voxel);
//    VDB voxel centres sit at integer index coordinates, so dense voxel (0,0,0) covers
//    index space [blockMin - 0.5, blockMin + 0.5) and Medium::origin is the world
//    position of index blockMin - 0.5;
//  - sigma_t = value * densityScale, per world unit;
//  - voxel size = lengths of the index->world axis vectors (non-cubic allowed); their
//    directions form Medium::localToWorld;
//  - emission: emitted radiance L_e (pbrt-v4 convention, source term sigma_a * L_e),
//    value * emissionScale, sampled trilinearly at the dense voxel centres in world space.
//  - solveScale S != 1 (--solve-scale): the block is a resampled grid with the input's
//    axes and voxel size / S, covering the active bounding box (plus `pad` solve voxels,
//    raised to ceil(S / 2 + 1/2) for S > 1 so that the shell voxels' centres fall between
//    solve-voxel centres), its low corner on the bounding box's low corner minus the pad.
//    Sheared transforms: the resampled block covers the active voxels plus at least `pad`
//    whole solve voxels per side, more where a shell voxel's centre would otherwise lie
//    within half a solve voxel of the block's border. A solve voxel's
//    sigma_t is the mean of the input over its volume (S < 1: every input voxel weighted
//    by its overlap, i.e. the limit of point sub-samples with nearest-voxel lookups, so
//    optical depth is preserved exactly) or the input voxel containing its centre (S > 1);
//    emission is the mean of ceil(1/S)^3 trilinear sub-samples (S < 1) or the sample at
//    the centre (S > 1). SolveGrid says where the block sits in the input's index space.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <openvdb/openvdb.h>

#include "core/medium.h"

namespace lpm {

struct VolumeReadOptions {
    std::string path;
    std::string gridName = "density";
    int gridIndex = -1;  ///< among grids named gridName; -1 = not given (0, warn if several)
    double densityScale = 1.0;
    bool sanitize = false;         ///< clamp NaN/Inf/negative values to 0 instead of failing
    bool convertLevelSet = false;  ///< convert a level set with tools::sdfToFogVolume
    std::string emissionGrid;      ///< empty = none
    double emissionScale = 1.0;
    std::string temperatureGrid;    ///< empty = none; black-body emission from Kelvin
    double temperatureScale = 1.0;  ///< Kelvin = value * scale + offset
    double temperatureOffset = 0.0;
    double temperatureIntensity = 1.0;    ///< L_e = intensity * blackbody(K), 6500 K -> luminance 1
    std::string workingSpace = "ACEScg";  ///< colour space of the black-body emission
    int pad = 1;  ///< empty voxels added around the active bounding box (>= kLightingShell used)
    std::uint64_t maxDenseVoxels = 1ull << 30;  ///< refuse larger dense blocks (memory guard)
    double solveScale = 1.0;                    ///< solve voxels per input voxel along each axis (--solve-scale)
    /// Range rules: throws SettingError naming the field (densityScale, emissionScale,
    /// temperature*, solveScale in [kMinSolveScale, kMaxSolveScale], maxDenseVoxels).
    void validate() const;
};

/// Below 0.05 a solve voxel spans more than 20 input voxels (nothing of the volume's shape
/// survives); above 8 the block grows 512x for no added detail (the medium is piecewise
/// constant on the input's voxels).
constexpr double kMinSolveScale = 0.05, kMaxSolveScale = 8.0;

/// Where the dense solve block sits in the input grid's index space. With scale == 1 it is
/// the input's own voxels (dense voxel d = index blockMin + d); otherwise solve voxel
/// (a, b, c) covers index space [corner + (a, b, c) / scale, corner + (a+1, b+1, c+1) / scale).
struct SolveGrid {
    double scale = 1.0;
    openvdb::Vec3d corner{0.0, 0.0, 0.0};  ///< index-space position of the block's low corner
    /// Sheared input transforms: the block is an orthonormal grid, and the continuous block
    /// coordinate of input index c is M c + t (voxel centres at integer + 0.5).
    bool affine = false;
    double M[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
    double t[3] = {0, 0, 0};
};

struct VolumeInput {
    openvdb::FloatGrid::Ptr density;  ///< the grid the block was built from (fog volume)
    openvdb::GridBase::Ptr emission;  ///< the emission grid as read (float or Vec3f), or null
    Medium medium;                    ///< albedo/g left at defaults: the caller sets them
    openvdb::Coord blockMin;          ///< index coordinate of dense voxel (0,0,0) (scale 1 only)
    SolveGrid solveGrid;              ///< the block's placement in index space (any scale)
    bool empty = false;               ///< no active voxels: no medium to solve
    std::uint64_t activeVoxels = 0;
    std::uint64_t sanitized = 0;           ///< values clamped because of --sanitize
    std::vector<std::string> gridsInFile;  ///< "name (type)" of every grid, for messages
    std::vector<std::string> warnings;
};

/// Throws InputError with a message naming the file, the grid and the offending value.
VolumeInput readVolume(const VolumeReadOptions& options);

/// Converts an already loaded density grid (used by readVolume and by tests).
void gridToMedium(const openvdb::FloatGrid& grid, const VolumeReadOptions& options, VolumeInput& out);

/// Tells the solver where the bake writes S (Medium::wantedS, lightingVoxelFlags): at
/// scale 1 the density's active voxels and their one-voxel shell; elsewhere (a resampled
/// or sheared block, whose output interpolates) every stored voxel. Worth its 12-20 ms
/// (1M voxels) only when the solve keeps directional SH (core/sh_rows.h).
void markWantedS(VolumeInput& v);

/// "file.vdb": name (type, class, N active voxels), ... of every grid (for `info` and errors).
std::string describeGrid(const openvdb::GridBase& grid);

/// Initialises OpenVDB once (thread-safe, idempotent).
void initOpenVdb();

}  // namespace lpm

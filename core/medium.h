// The discrete problem: a dense block of voxels with constant extinction per voxel,
// a uniform RGB single-scattering albedo, a Henyey-Greenstein phase function and an
// optional per-voxel emitted radiance, lit by an environment, suns and emission.
//
// The block lives in a local frame whose axes are the voxel axes; `localToWorld` is the
// rotation from that frame to world space. Lights and the SH basis are in world space.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/envmap.h"
#include "core/error.h"
#include "core/malloc_policy.h"
#include "core/math.h"

namespace lpm {

struct Medium {
    /// Voxels are stored in 8^3 tiles when the block is sparse: a tile with no active voxel
    /// is never allocated, so memory follows the active region, not the bounding box.
    static constexpr int kTile = 8;
    static constexpr size_t kTileVoxels = size_t(kTile) * kTile * kTile;
    static constexpr size_t npos = ~size_t(0);  ///< index() of a voxel in an unallocated tile

    int nx = 0, ny = 0, nz = 0;    ///< block dimensions in voxels
    Vec3 voxelSize{1, 1, 1};       ///< (dx, dy, dz) in world units along the local axes
    std::vector<float> sigmaT;     ///< extinction per world unit, one per stored voxel (see index())
    RGB albedo{0.9f, 0.9f, 0.9f};  ///< sigma_s / sigma_t per channel, in [0, 1]
    double g = 0.0;                ///< Henyey-Greenstein asymmetry, in (-1, 1)
    std::vector<RGB> emission;     ///< empty, or emitted radiance L_e per stored voxel (source sigma_a L_e)
    Mat3 localToWorld;             ///< rotation, local voxel axes -> world
    Vec3 origin{0, 0, 0};          ///< world position of the grid's corner (voxel 0's low corner)
    /// Empty: dense storage, index x + nx*(y + ny*z). Otherwise one entry per tile
    /// (tx + tnx*(ty + tny*tz)): its slot, or -1 when the tile is not allocated.
    std::vector<std::int32_t> tileSlot;
    /// Empty: the caller reads S at every stored voxel. Otherwise one flag per stored voxel,
    /// 1 where the caller reads S (a bake: the voxels it writes, docs/output_format.md
    /// "Topology"); the solver may hold the SH result of the others nowhere and return 0
    /// there (core/sh_rows.h), and its sweeps skip the chunks of voxels with neither
    /// extinction nor a wanted voxel (core/sweep.cpp): S of an unwanted voxel without
    /// extinction is then not the light there. Cleared by allocate().
    std::vector<std::uint8_t> wantedS;

    bool sparse() const { return !tileSlot.empty(); }
    int tilesX() const { return (nx + kTile - 1) / kTile; }
    int tilesY() const { return (ny + kTile - 1) / kTile; }
    int tilesZ() const { return (nz + kTile - 1) / kTile; }
    /// Number of stored voxels (the size of sigmaT, emission and every per-voxel result).
    size_t voxelCount() const { return sparse() ? storedTiles * kTileVoxels : size_t(nx) * ny * nz; }
    size_t storedTiles = 0;              ///< allocated tiles when sparse (set by allocate())
    std::vector<std::int32_t> slotTile;  ///< inverse of tileSlot (set by allocate())
    size_t blockVoxelCount() const { return size_t(nx) * ny * nz; }
    /// Storage index of voxel (x, y, z) of the block, or npos in an unallocated tile.
    size_t index(int x, int y, int z) const {
        if (!sparse()) return size_t(x) + size_t(nx) * (size_t(y) + size_t(ny) * z);
        const std::int32_t t =
            tileSlot[size_t(x / kTile) + size_t(tilesX()) * (size_t(y / kTile) + size_t(tilesY()) * (z / kTile))];
        if (t < 0) return npos;
        return size_t(t) * kTileVoxels + size_t(x % kTile) + kTile * (size_t(y % kTile) + kTile * size_t(z % kTile));
    }
    /// Block coordinates of stored voxel `v` (may lie outside the block in a border tile).
    void coord(size_t v, int& x, int& y, int& z) const;
    double voxelVolume() const { return voxelSize.x * voxelSize.y * voxelSize.z; }
    int dim(int axis) const { return axis == 0 ? nx : (axis == 1 ? ny : nz); }
    bool hasEmission() const { return !emission.empty(); }

    /// Sizes the block and zeroes storage. `tileActive` (one flag per 8^3 tile, order
    /// tx + tnx*(ty + tny*tz)) selects the tiles to store; null or all set = dense.
    void allocate(int nx_, int ny_, int nz_, const std::vector<std::uint8_t>* tileActive = nullptr,
                  bool withEmission = false);

    /// Throws lpm::Error naming the offending value.
    void validate() const;
};

/// A directional light. `toSun` points from the scene toward the sun (world space);
/// light travels along -toSun. `irradiance` is measured on a plane facing the sun.
struct Sun {
    Vec3 toSun{0, 1, 0};
    RGB irradiance{1, 1, 1};
    double angularDiameterDeg = 0.0;
    /// Throws SettingError (fields toSun, irradiance, angularDiameterDeg).
    void validate() const;
};

/// The medium's constants: albedo in [0, 1] per channel, g in (-1, 1). Throws SettingError
/// (fields albedo, g).
void validateMaterial(const RGB& albedo, double g);

struct Lights {
    const EnvMap* env = nullptr;  ///< may be null (black environment)
    std::vector<Sun> suns;
};

inline void Medium::coord(size_t v, int& x, int& y, int& z) const {
    if (!sparse()) {
        x = int(v % size_t(nx));
        y = int((v / size_t(nx)) % size_t(ny));
        z = int(v / (size_t(nx) * ny));
        return;
    }
    const size_t slot = v / kTileVoxels, local = v % kTileVoxels;
    if (slot >= slotTile.size()) {
        x = y = z = -1;
        return;
    }
    const size_t t = size_t(slotTile[slot]);
    const int tx = int(t % tilesX()), ty = int((t / tilesX()) % tilesY()), tz = int(t / (size_t(tilesX()) * tilesY()));
    x = tx * kTile + int(local % kTile);
    y = ty * kTile + int((local / kTile) % kTile);
    z = tz * kTile + int(local / (kTile * kTile));
}

inline void Medium::allocate(int nx_, int ny_, int nz_, const std::vector<std::uint8_t>* tileActive,
                             bool withEmission) {
    nx = nx_;
    ny = ny_;
    nz = nz_;
    tileSlot.clear();
    slotTile.clear();
    storedTiles = 0;
    if (tileActive) {
        const size_t tiles = size_t(tilesX()) * tilesY() * tilesZ();
        if (tileActive->size() != tiles)
            throw Error("Medium", "tile mask has " + std::to_string(tileActive->size()) + " entries for " +
                                      std::to_string(tiles) + " tiles");
        size_t on = 0;
        for (std::uint8_t a : *tileActive) on += a != 0;
        if (on < tiles) {
            tileSlot.assign(tiles, -1);
            std::int32_t next = 0;
            for (size_t t = 0; t < tiles; ++t)
                if ((*tileActive)[t]) {
                    tileSlot[t] = next++;
                    slotTile.push_back(std::int32_t(t));
                }
            storedTiles = size_t(next);
        }
    }
    assignZeroed(sigmaT, voxelCount());
    wantedS.clear();
    emission.clear();
    if (withEmission) assignZeroed(emission, voxelCount());
}

inline void validateMaterial(const RGB& albedo, double g) {
    for (int c = 0; c < 3; ++c)
        if (!(albedo[c] >= 0 && albedo[c] <= 1))
            throw SettingError("Medium", "albedo", "must lie in [0, 1], got " + std::to_string(albedo[c]));
    if (!(g > -1 && g < 1)) throw SettingError("Medium", "g", "must lie in (-1, 1), got " + std::to_string(g));
}

inline void Sun::validate() const {
    if (!(length(toSun) > 0) || !std::isfinite(length(toSun)))
        throw SettingError("Sun", "toSun",
                           "must be non-zero and finite, got " + std::to_string(toSun.x) + "," +
                               std::to_string(toSun.y) + "," + std::to_string(toSun.z));
    for (int c = 0; c < 3; ++c)
        if (!(irradiance[c] >= 0) || !std::isfinite(irradiance[c]))
            throw SettingError("Sun", "irradiance",
                               "must be finite and non-negative, got " + std::to_string(irradiance[c]));
    if (!(angularDiameterDeg >= 0 && angularDiameterDeg < 180))
        throw SettingError("Sun", "angularDiameterDeg",
                           "must be in [0, 180) degrees, got " + std::to_string(angularDiameterDeg));
}

inline void Medium::validate() const {
    if (nx <= 0 || ny <= 0 || nz <= 0)
        throw Error("Medium", "grid dimensions must be positive, got " + std::to_string(nx) + "x" + std::to_string(ny) +
                                  "x" + std::to_string(nz));
    for (int a = 0; a < 3; ++a)
        if (!(voxelSize[a] > 0) || !std::isfinite(voxelSize[a]))
            throw Error("Medium", "voxel size must be positive and finite, got " + std::to_string(voxelSize[a]));
    if (sigmaT.size() != voxelCount())
        throw Error("Medium", "sigmaT has " + std::to_string(sigmaT.size()) + " values for " +
                                  std::to_string(voxelCount()) + " voxels");
    if (!emission.empty() && emission.size() != voxelCount())
        throw Error("Medium", "emission has " + std::to_string(emission.size()) + " values for " +
                                  std::to_string(voxelCount()) + " voxels");
    if (!wantedS.empty() && wantedS.size() != voxelCount())
        throw Error("Medium", "wantedS has " + std::to_string(wantedS.size()) + " flags for " +
                                  std::to_string(voxelCount()) + " voxels");
    validateMaterial(albedo, g);
    for (float s : sigmaT)
        if (!(s >= 0) || !std::isfinite(s))
            throw Error("Medium", "extinction must be finite and non-negative, got " + std::to_string(s));
}

}  // namespace lpm

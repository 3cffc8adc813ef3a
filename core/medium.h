// The discrete problem: a dense block of voxels with constant extinction per voxel,
// a uniform RGB single-scattering albedo, a Henyey-Greenstein phase function and an
// optional per-voxel emitted radiance, lit by an environment, suns and emission.
//
// The block lives in a local frame whose axes are the voxel axes; `localToWorld` is the
// rotation from that frame to world space. Lights and the SH basis are in world space.
#pragma once

#include <string>
#include <vector>

#include "core/envmap.h"
#include "core/error.h"
#include "core/math.h"

namespace lpm {

struct Medium {
    int nx = 0, ny = 0, nz = 0;
    Vec3 voxelSize{1, 1, 1};       ///< (dx, dy, dz) in world units along the local axes
    std::vector<float> sigmaT;     ///< extinction per world unit, index x + nx*(y + ny*z)
    RGB albedo{0.9f, 0.9f, 0.9f};  ///< sigma_s / sigma_t per channel, in [0, 1]
    double g = 0.0;                ///< Henyey-Greenstein asymmetry, in (-1, 1)
    std::vector<RGB> emission;     ///< empty, or emitted radiance L_e per voxel (source sigma_a L_e)
    Mat3 localToWorld;             ///< rotation, local voxel axes -> world
    Vec3 origin{0, 0, 0};          ///< world position of the grid's corner (voxel 0's low corner)

    size_t voxelCount() const { return size_t(nx) * ny * nz; }
    size_t index(int x, int y, int z) const { return size_t(x) + size_t(nx) * (size_t(y) + size_t(ny) * z); }
    double voxelVolume() const { return voxelSize.x * voxelSize.y * voxelSize.z; }
    int dim(int axis) const { return axis == 0 ? nx : (axis == 1 ? ny : nz); }
    bool hasEmission() const { return !emission.empty(); }

    /// Throws lpm::Error naming the offending value.
    void validate() const;
};

/// A directional light. `toSun` points from the scene toward the sun (world space);
/// light travels along -toSun. `irradiance` is measured on a plane facing the sun.
struct Sun {
    Vec3 toSun{0, 1, 0};
    RGB irradiance{1, 1, 1};
    double angularDiameterDeg = 0.0;
};

struct Lights {
    const EnvMap* env = nullptr;  ///< may be null (black environment)
    std::vector<Sun> suns;
};

inline void Medium::validate() const {
    if (nx <= 0 || ny <= 0 || nz <= 0)
        throw Error("Medium", "grid dimensions must be positive, got " + std::to_string(nx) + "x" +
                                  std::to_string(ny) + "x" + std::to_string(nz));
    for (int a = 0; a < 3; ++a)
        if (!(voxelSize[a] > 0) || !std::isfinite(voxelSize[a]))
            throw Error("Medium", "voxel size must be positive and finite, got " + std::to_string(voxelSize[a]));
    if (sigmaT.size() != voxelCount())
        throw Error("Medium", "sigmaT has " + std::to_string(sigmaT.size()) + " values for " +
                                  std::to_string(voxelCount()) + " voxels");
    if (!emission.empty() && emission.size() != voxelCount())
        throw Error("Medium", "emission has " + std::to_string(emission.size()) + " values for " +
                                  std::to_string(voxelCount()) + " voxels");
    for (int c = 0; c < 3; ++c)
        if (!(albedo[c] >= 0 && albedo[c] <= 1))
            throw Error("Medium", "albedo must lie in [0, 1], got " + std::to_string(albedo[c]));
    if (!(g > -1 && g < 1)) throw Error("Medium", "the asymmetry g must lie in (-1, 1), got " + std::to_string(g));
    for (float s : sigmaT)
        if (!(s >= 0) || !std::isfinite(s))
            throw Error("Medium", "extinction must be finite and non-negative, got " + std::to_string(s));
}

}  // namespace lpm

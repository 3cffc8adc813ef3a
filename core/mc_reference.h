// Monte Carlo reference for the same discrete problem as the LPM solver (same medium,
// lights and SH basis; no code shared with the LPM sweeps). Unbiased estimators with
// standard errors:
//  - SH coefficients of S(x, w) averaged over a voxel (x uniform in the voxel);
//  - a pinhole-camera image of the volume in front of the environment.
// Free flights and transmittance use exact regular tracking through the piecewise-
// constant voxels (delta tracking with a per-voxel majorant equal to sigma_t, which never
// produces null collisions); next-event estimation to the environment (importance-
// sampled) and the suns; Russian roulette on the path throughput. See docs/mc_reference.md.
#pragma once

#include <cstdint>
#include <vector>

#include "core/camera.h"
#include "core/medium.h"

namespace lpm {

struct McSettings {
    std::uint64_t seed = 1;
    int rouletteDepth = 3;  ///< Russian roulette starts after this many collisions
    /// mcRenderImage: add the environment seen through the volume (false: only the light
    /// the volume scatters or emits toward the camera).
    bool background = true;
};

struct McVoxelEstimate {
    size_t voxel = 0;
    int samples = 0;
    std::vector<double> mean;    ///< [coeff][rgb]
    std::vector<double> stdErr;  ///< [coeff][rgb], standard error of the mean
};

/// SH coefficients (orders 0..shOrder) of S averaged over each listed voxel.
std::vector<McVoxelEstimate> mcVoxelSH(const Medium& medium, const Lights& lights, const std::vector<size_t>& voxels,
                                       int samplesPerVoxel, int shOrder, const McSettings& settings = {});

struct McImage {
    int width = 0, height = 0;
    std::vector<double> mean;    ///< [pixel][rgb], row 0 at the top
    std::vector<double> stdErr;  ///< [pixel][rgb]
};

McImage mcRenderImage(const Medium& medium, const Lights& lights, const PinholeCamera& camera, int samplesPerPixel,
                      const McSettings& settings = {});

}  // namespace lpm

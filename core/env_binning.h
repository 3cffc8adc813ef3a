// The environment as the solver sees it: its radiance box-filtered over each direction
// bin of the cube quadrature, with its hot pixels (a sun in an HDRI) taken out and
// returned as suns to sweep in their exact direction. Depends on the environment, the
// quadrature and the medium's frame only, so a sequence bins once (core/lpm_cache.h).
#pragma once

#include <vector>

#include "core/envmap.h"
#include "core/medium.h"
#include "core/quadrature.h"

namespace lpm {

struct EnvBinning {
    /// Per direction i: mean radiance of the light travelling along local direction i
    /// (arriving from world direction -R w_i).
    std::vector<RGB> radiance;
    std::vector<Sun> hotSuns;  ///< hot pixels, touching ones merged (mergeHotPixels)
    double hotShare = 0;       ///< their share of the environment's power
};

/// One sun per group of touching hot pixels (8-neighbours, wrapping in longitude; a sun
/// in an HDRI covers several): the power-weighted mean direction, the summed irradiance,
/// and a disc of the group's solid angle, widened to reach its farthest pixel centre.
std::vector<Sun> mergeHotPixels(const std::vector<EnvHotPixel>& hot, int width);

/// Bins `env` for `quad` in the frame with world-to-local rotation `Rinv`. Pixels holding
/// at least `hotShare` of the power (at most 16, each within a quarter of a bin's solid
/// angle) leave the bins and become hotSuns; hotShare = 0 keeps every pixel in the bins.
EnvBinning binEnvironment(const EnvMap& env, const CubeQuadrature& quad, const Mat3& Rinv, double hotShare);

}  // namespace lpm

// The exact sun term (docs/sun_term.md). Single scattering of a sun is a delta in angle
// times the phase lobe; no low SH order holds it (Henyey-Greenstein g = 0.6 at 128
// degrees: 0.0167 / sr, its order-2 expansion 0.0018, order 3 0.042). So the bake keeps,
// for each sun, the beam's transmittance T(x) beside the SH, and a renderer adds
//   S_sun(x, w) = E T(x) p_HG(g, dot(w_sun, w))      w_sun = -toSun, w = travel direction
// to what the SH grids hold, which is S without that term: smooth multiple scattering
// and the sky. T is the solver's own: the voxel mean of the beam's transmittance from
// the sun's sweep (with delta-M, of the scaled medium the propagation used), so removing
// the term's SH projection takes out exactly what the solver put in.
#pragma once

#include <vector>

#include "core/math.h"

namespace lpm {

struct SunTerm {
    Vec3 toSun{0, 1, 0};      ///< world direction toward the sun (unit)
    RGB irradiance{0, 0, 0};  ///< on a plane facing the sun
    double angularDiameterDeg = 0;
    bool fromEnvironment = false;      ///< a hot pixel of the environment, swept as a sun
    std::vector<float> transmittance;  ///< per stored voxel of the medium, in [0, 1]
};

/// S of the term at a voxel of transmittance T for scattered light travelling along
/// world direction w (unit), per unit E: T p_HG(g, dot(-toSun, w)). The point phase: the
/// disc's width is left out (0.53 degrees changes p by < 0.1% for g <= 0.9).
double sunTermPhase(const SunTerm& t, double g, const Vec3& w);

/// Adds `sign` times the term's SH projection at transmittance T to coeffs [k][rgb]
/// (k < (order + 1)^2): E T g^l Y_k(-toSun) c_l(disc), as the solver deposits it.
void addSunTermSh(const SunTerm& t, double g, int order, float T, double sign, float* coeffs);

/// Takes every term's projection out of `sh` ([voxel][k][rgb], order `order`): what is
/// left is S without the suns' single scattering, which the terms then carry exactly.
void removeSunTermsFromSh(std::vector<float>& sh, int order, const std::vector<SunTerm>& terms, double g);

}  // namespace lpm

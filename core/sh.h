// Real spherical harmonics, orthonormal, ACN index k = l*l + l + m, no Condon-Shortley
// phase, orders 0..3 (16 coefficients). (x, y, z) are world-space components of a unit
// direction. Basis as in docs/conventions.md (solver_notes section 5).
#pragma once

#include "core/math.h"

namespace lpm {

constexpr int kMaxShOrder = 3;
constexpr int shCount(int order) { return (order + 1) * (order + 1); }
constexpr int shBand(int k) { return k >= 9 ? 3 : (k >= 4 ? 2 : (k >= 1 ? 1 : 0)); }
constexpr double kY00 = 0.28209479177387814;  // 1 / (2 sqrt(pi))

/// Evaluates all 16 basis functions at unit direction d.
void shEval(const Vec3& d, double out[16]);

/// Funk-Hecke factor for a uniform cone (cap) of half-angle `halfAngle` radians:
/// convolving a delta direction with the normalised cap multiplies band l by this.
double capBandFactor(int l, double halfAngle);

}  // namespace lpm

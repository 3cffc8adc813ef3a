// Henyey-Greenstein phase function, normalised to 1 over the sphere (pbrt-v4 convention).
// cosTheta is the cosine between the travel directions of incident and scattered light;
// g > 0 scatters forward.
#pragma once

#include <cmath>

#include "core/math.h"

namespace lpm {

inline double henyeyGreenstein(double cosTheta, double g) {
    const double denom = 1 + g * g - 2 * g * cosTheta;
    return kInv4Pi * (1 - g * g) / (denom * std::sqrt(std::fmax(denom, 1e-300)));
}

/// Samples a travel direction scattered from incident travel direction `wi`
/// with density henyeyGreenstein(dot(wi, result), g). u1, u2 in [0,1).
inline Vec3 sampleHenyeyGreenstein(const Vec3& wi, double g, double u1, double u2) {
    double cosTheta;
    if (std::fabs(g) < 1e-3) {
        cosTheta = 1 - 2 * u1;
    } else {
        const double sq = (1 - g * g) / (1 + g - 2 * g * u1);
        cosTheta = (1 + g * g - sq * sq) / (2 * g);
    }
    cosTheta = std::fmin(1.0, std::fmax(-1.0, cosTheta));
    const double sinTheta = std::sqrt(std::fmax(0.0, 1 - cosTheta * cosTheta));
    const double phi = 2 * kPi * u2;
    Vec3 t, b;
    orthonormalBasis(wi, t, b);
    return t * (sinTheta * std::cos(phi)) + b * (sinTheta * std::sin(phi)) + wi * cosTheta;
}

}  // namespace lpm

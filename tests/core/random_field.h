// Random vectors and their dot product for the diffusion tests (operator symmetry,
// preconditioner symmetry, CG right sides).
#pragma once

#include <cstdint>
#include <vector>

#include "core/rng.h"

namespace lpm::test {

/// n values uniform in [-offset, 1 - offset), the same for the same seed.
inline std::vector<float> randomField(std::size_t n, std::uint64_t seed, float offset = 0.25f) {
    Pcg32 rng(seed, 11);
    std::vector<float> x(n);
    for (float& v : x) v = float(rng.uniform()) - offset;
    return x;
}

inline double dot(const std::vector<float>& a, const std::vector<float>& b) {
    double s = 0;
    for (std::size_t i = 0; i < a.size(); ++i) s += double(a[i]) * b[i];
    return s;
}

}  // namespace lpm::test

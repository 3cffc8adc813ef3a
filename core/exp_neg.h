// The sweep kernels' exponential (core/sweep.cpp, core/linear_segment_lanes.h), inline
// so it vectorises inside their lane loops; expNeg (core/sweep.h) is the same, callable.
#pragma once

#include <cstdint>
#include <cstring>

namespace lpm {

// exp(-x), x >= 0: Cody-Waite reduction x = n ln2 - r, |r| <= ln2/2, Cephes' degree-6
// polynomial, 2^n by exponent bits. Above 87 (where e^-x is denormal) exactly 0.
inline float expNegInline(float x) {
    const float xc = x < 87.0f ? x : 87.0f;  // selects, not std::min: keeps the loop branch-free
    const float y = -xc;
    // Round to nearest by adding 1.5 * 2^23 (no libm call, vectorises without SSE4.1).
    const float n = (y * 1.44269504088896341f + 12582912.0f) - 12582912.0f;
    float r = y - n * 0.693359375f;
    r = r + n * 2.12194440e-4f;
    float p = 1.9875691500e-4f;
    p = p * r + 1.3981999507e-3f;
    p = p * r + 8.3334519073e-3f;
    p = p * r + 4.1665795894e-2f;
    p = p * r + 1.6666665459e-1f;
    p = p * r + 5.0000001201e-1f;
    p = p * r * r + r + 1.0f;
    const std::int32_t e = std::int32_t(n) + 127;  // >= 1 for x <= 87
    const std::int32_t bits = e << 23;
    float scale;
    std::memcpy(&scale, &bits, sizeof scale);
    const float value = p * scale;  // computed unconditionally: a select, not a branch, under -ftrapping-math
    return x < 87.0f ? value : 0.0f;
}

}  // namespace lpm

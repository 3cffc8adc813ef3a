// Half-precision coarse buffers (core/half_buffer.h): the conversions are IEEE binary16
// round to nearest even (checked against the neighbours of every result, and exhaustively
// for the way back), the scale keeps every magnitude in range, negation is exact.
#include "core/half_buffer.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/rng.h"

using namespace lpm;

namespace {

/// Whether h is the binary16 nearest to x, ties to the even one.
bool isNearestEven(float x, std::uint16_t h) {
    const double v = floatFromHalf(h), err = std::fabs(v - double(x));
    for (int step : {-1, 1}) {
        const std::uint16_t n = std::uint16_t(h + step);
        if ((n & 0x7c00u) == 0x7c00u || (n & 0x8000u) != (h & 0x8000u)) continue;  // beyond the finite range
        const double other = std::fabs(double(floatFromHalf(n)) - double(x));
        if (other < err || (other == err && (h & 1u))) return false;
    }
    return true;
}

}  // namespace

// Every binary16 pattern decodes to its value (sign, exponent, mantissa; subnormals,
// infinities, NaN) and encodes back to itself.
TEST(HalfBuffer, EveryHalfDecodesExactlyAndComesBack) {
    for (std::uint32_t h = 0; h < 0x10000u; ++h) {
        const float x = floatFromHalf(std::uint16_t(h));
        const int exponent = int(h >> 10) & 31, mantissa = int(h & 1023);
        const double sign = (h & 0x8000u) ? -1.0 : 1.0;
        if (exponent == 31) {
            EXPECT_TRUE(mantissa ? std::isnan(x) : std::isinf(x)) << h;
            if (mantissa == 0) EXPECT_EQ(halfFromFloat(x), h);
            else EXPECT_TRUE(std::isnan(floatFromHalf(halfFromFloat(x)))) << h;
            continue;
        }
        const double want =
            sign * (exponent ? std::ldexp(1024.0 + mantissa, exponent - 25) : std::ldexp(double(mantissa), -24));
        ASSERT_EQ(double(x), want) << h;
        ASSERT_EQ(std::signbit(x), bool(h & 0x8000u)) << h;
        ASSERT_EQ(halfFromFloat(x), h) << h;
    }
}

// Floats across the whole range (normal, subnormal, ties, near the overflow) go to the
// nearest half, ties to even; above the largest half's rounding interval, to infinity.
TEST(HalfBuffer, FloatsRoundToTheNearestHalfTiesToEven) {
    Pcg32 rng(3, 5);
    for (int k = 0; k < 200000; ++k) {
        const float x =
            float((rng.uniform() < 0.5 ? -1.0 : 1.0) * std::ldexp(1.0 + rng.uniform(), int(rng.uniform() * 45) - 28));
        if (std::fabs(x) >= 65520.0f) continue;
        ASSERT_TRUE(isNearestEven(x, halfFromFloat(x))) << x;
    }
    // Exact ties: halfway between neighbours, in the normal and the subnormal range.
    EXPECT_EQ(halfFromFloat(1.0f + 1.0f / 2048), 0x3c00u);     // tie to even (down)
    EXPECT_EQ(halfFromFloat(1.0f + 3.0f / 2048), 0x3c02u);     // tie to even (up)
    EXPECT_EQ(halfFromFloat(std::ldexp(1.0f, -25)), 0x0000u);  // half the smallest subnormal
    EXPECT_EQ(halfFromFloat(std::ldexp(3.0f, -25)), 0x0002u);  // 1.5 subnormal steps
    EXPECT_EQ(halfFromFloat(65504.0f), 0x7bffu);               // the largest half
    EXPECT_EQ(halfFromFloat(65519.0f), 0x7bffu);               // below the rounding limit
    EXPECT_EQ(halfFromFloat(65520.0f), 0x7c00u);               // a tie that rounds to infinity
    EXPECT_EQ(halfFromFloat(-1e30f), 0xfc00u);
    EXPECT_TRUE(std::isnan(floatFromHalf(halfFromFloat(std::numeric_limits<float>::quiet_NaN()))));
}

// The scale maps the largest magnitude into [2^14, 2^15): values of any size keep 2^-11
// relative precision down to 2^-29 of the largest (below it, 2^-25 x scale absolute),
// zeros stay zeros, negation is exact.
TEST(HalfBuffer, ScaledBufferKeepsRelativePrecisionAtAnyMagnitude) {
    for (float magnitude : {1e-30f, 1e-3f, 1.0f, 7e4f, 3e9f, 1e35f}) {
        SCOPED_TRACE(magnitude);
        Pcg32 rng(11, 2);
        std::vector<float> x(5000);
        for (float& v : x)
            v = magnitude * float(rng.uniform() - 0.4) * float(std::ldexp(1.0, -int(rng.uniform() * 20)));
        x[0] = magnitude;
        x[1] = 0.0f;
        HalfBuffer h = HalfBuffer::encode(x);
        EXPECT_EQ(std::ldexp(1.0f, std::ilogb(h.scale)), h.scale);  // a power of two
        EXPECT_GE(magnitude / h.scale, 16384.0f);
        EXPECT_LT(magnitude / h.scale, 32768.0f);
        ASSERT_EQ(h.size(), x.size());
        for (size_t i = 0; i < x.size(); ++i) {
            // Inputs below float's normal range (some at magnitude 1e-30) are zero to the
            // solver's parallel tasks, which flush denormals (core/flush_denormals.h).
            const float bound = std::fabs(x[i]) < std::numeric_limits<float>::min()
                                    ? std::numeric_limits<float>::min()
                                    : std::max(std::ldexp(std::fabs(x[i]), -11), std::ldexp(h.scale, -25));
            ASSERT_LE(std::fabs(h.at(i) - x[i]), bound) << i;
        }
        EXPECT_EQ(h.at(1), 0.0f);
    }
    const HalfBuffer zeros = HalfBuffer::encode(std::vector<float>(10, 0.0f));
    EXPECT_EQ(zeros.scale, 1.0f);
    for (size_t i = 0; i < zeros.size(); ++i) EXPECT_EQ(zeros.at(i), 0.0f);
}

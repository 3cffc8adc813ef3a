// bfloat16 (core/bf16.h): every pattern decodes exactly and comes back; floats round to
// the nearest bfloat16, ties to even, within 2^-8 relative; infinities and NaN survive.
#include "core/bf16.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>

#include "core/rng.h"

using namespace lpm;

namespace {

float fromBits(std::uint32_t f) {
    float x;
    std::memcpy(&x, &f, sizeof x);
    return x;
}

/// Whether h is the bfloat16 nearest to the finite x, ties to the even one.
bool isNearestEven(float x, Bf16 h) {
    const double err = std::fabs(double(floatFromBf16(h)) - double(x));
    for (int step : {-1, 1}) {
        const Bf16 n{std::uint16_t(h.bits + step)};
        if ((n.bits & 0x7f80u) == 0x7f80u || (n.bits & 0x8000u) != (h.bits & 0x8000u)) continue;
        const double other = std::fabs(double(floatFromBf16(n)) - double(x));
        if (other < err || (other == err && (h.bits & 1u))) return false;
    }
    return true;
}

}  // namespace

TEST(Bf16, EveryPatternDecodesExactlyAndComesBack) {
    for (std::uint32_t b = 0; b < 0x10000u; ++b) {
        const float x = floatFromBf16(Bf16{std::uint16_t(b)});
        const float want = fromBits(b << 16);
        if (std::isnan(want)) {
            EXPECT_TRUE(std::isnan(x)) << b;
            EXPECT_TRUE(std::isnan(floatFromBf16(bf16FromFloat(x)))) << b;
            continue;
        }
        ASSERT_EQ(std::memcmp(&x, &want, sizeof x), 0) << b;
        ASSERT_EQ(bf16FromFloat(x).bits, b) << b;
    }
}

TEST(Bf16, FloatsRoundToTheNearestTiesToEvenWithin2ToMinus8) {
    Pcg32 rng(7, 11);
    double worst = 0;
    for (int k = 0; k < 300000; ++k) {
        const float x = fromBits(std::uint32_t(rng.uniform() * 4294967296.0));
        if (!std::isfinite(x) || std::fabs(x) >= 3.38e38f) continue;
        const Bf16 h = bf16FromFloat(x);
        ASSERT_TRUE(isNearestEven(x, h)) << x;
        if (std::fabs(x) >= std::numeric_limits<float>::min())
            worst = std::max(worst, std::fabs(double(floatFromBf16(h)) - x) / std::fabs(double(x)));
    }
    EXPECT_LE(worst, std::ldexp(1.0, -8));
    EXPECT_GT(worst, std::ldexp(1.0, -9));  // the bound is reached, not loose
    // Ties: halfway between two bfloat16 values goes to the even mantissa.
    EXPECT_EQ(bf16FromFloat(fromBits(0x3f808000u)).bits, 0x3f80u);
    EXPECT_EQ(bf16FromFloat(fromBits(0x3f818000u)).bits, 0x3f82u);
    EXPECT_EQ(bf16FromFloat(fromBits(0x3f808001u)).bits, 0x3f81u);
}

TEST(Bf16, InfinityNanAndTheTopOfTheRange) {
    const float inf = std::numeric_limits<float>::infinity();
    EXPECT_EQ(floatFromBf16(bf16FromFloat(inf)), inf);
    EXPECT_EQ(floatFromBf16(bf16FromFloat(-inf)), -inf);
    EXPECT_TRUE(std::isnan(floatFromBf16(bf16FromFloat(std::numeric_limits<float>::quiet_NaN()))));
    EXPECT_TRUE(std::isnan(floatFromBf16(bf16FromFloat(fromBits(0x7f800001u)))));     // payload in the dropped bits
    EXPECT_EQ(floatFromBf16(bf16FromFloat(std::numeric_limits<float>::max())), inf);  // within half an ulp of it
    EXPECT_EQ(floatFromBf16(bf16FromFloat(fromBits(0x7f7f0000u))), fromBits(0x7f7f0000u));
    EXPECT_EQ(bf16FromFloat(-0.0f).bits, 0x8000u);
}

// The SH result held compactly while the coarse grid solves (core/held_sh.h): its storage
// is freed while held; band 0 comes back bit for bit, the directional bands as their
// nearest binary16 under one power-of-two scale, within 2^-11 of each value.
#include "core/held_sh.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/error.h"
#include "core/rng.h"

using namespace lpm;

TEST(HeldSh, Band0ExactlyTheOtherBandsWithinHalfPrecision) {
    for (int coeffs : {4, 9}) {
        SCOPED_TRACE(coeffs);
        const size_t rows = 5000, width = size_t(coeffs) * 3;
        std::vector<float> sh(rows * width);
        Pcg32 rng(17, uint64_t(coeffs));
        for (size_t row = 0; row < rows; ++row) {
            const double brightness = std::ldexp(1.0, int(rng.uniform() * 40) - 20);  // 2^-20 .. 2^19
            for (size_t i = 0; i < width; ++i)
                sh[row * width + i] = float(brightness * (i < 3 ? 0.5 + rng.uniform() : rng.uniform() - 0.5));
        }
        const std::vector<float> before = sh;
        HeldSh held(sh, coeffs);
        EXPECT_EQ(held.rows(), rows);
        EXPECT_EQ(sh.size(), before.size());  // its storage kept (its pages given back)
        held.restore(sh);
        ASSERT_EQ(sh.size(), before.size());
        float largest = 0;
        for (float v : before) largest = std::max(largest, std::fabs(v));
        size_t rounded = 0;
        for (size_t i = 0; i < sh.size(); ++i) {
            if (i % width < 3) {
                ASSERT_EQ(sh[i], before[i]) << i;
                continue;
            }
            const float v = before[i];
            if (std::fabs(v) >= std::ldexp(largest, -28))
                ASSERT_LE(std::fabs(sh[i] - v), std::ldexp(std::fabs(v), -11)) << i;
            else ASSERT_LE(std::fabs(sh[i] - v), std::ldexp(largest, -39)) << i;
            rounded += sh[i] != v;
        }
        EXPECT_GT(rounded, sh.size() / 2);  // the directional bands were held in half precision
    }
}

TEST(HeldSh, RefusesAnIsotropicResultOrRowsThatDoNotDivide) {
    std::vector<float> sh(30, 1.0f);
    EXPECT_THROW(HeldSh(sh, 1), Error);
    EXPECT_THROW(HeldSh(sh, 4), Error);  // 30 values are not rows of 12
    EXPECT_EQ(sh.size(), 30u);
}

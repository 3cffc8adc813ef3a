// Environment binning and the solver's precomputation cache (core/env_binning.h,
// core/lpm_cache.h).
#include <gtest/gtest.h>

#include "core/env_binning.h"
#include "core/lpm_cache.h"
#include "core/lpm_solver.h"
#include "test_scenes.h"

using namespace lpm;

namespace {

/// A 64x32 map, radiance 1 (RGB 1, 0.5, 0.25), with one pixel of `hot` at (40, 9).
EnvMap mapWithHotPixel(float hot) {
    std::vector<RGB> px(64 * 32, RGB(1.0f, 0.5f, 0.25f));
    px[9 * 64 + 40] = RGB(hot);
    return EnvMap(64, 32, px);
}

double binnedPower(const EnvBinning& b, const CubeQuadrature& q, int c) {
    double p = 0;
    for (int i = 0; i < q.count(); ++i) p += b.radiance[i][c] * q.weight(i);
    return p;
}

}  // namespace

TEST(EnvBinning, ConstantMapGivesConstantBins) {
    const EnvMap env(64, 32, std::vector<RGB>(64 * 32, RGB(1.0f, 0.5f, 0.25f)));
    const CubeQuadrature q(4);
    const EnvBinning b = binEnvironment(env, q, Mat3::identity(), 0.0);
    ASSERT_EQ(int(b.radiance.size()), q.count());
    EXPECT_TRUE(b.hotSuns.empty());
    for (const RGB& L : b.radiance) {
        EXPECT_NEAR(L.r, 1.0, 1e-5);
        EXPECT_NEAR(L.b, 0.25, 1e-5);
    }
}

TEST(EnvBinning, HotPixelBecomesASunAndPowerIsKept) {
    const EnvMap env = mapWithHotPixel(5e4f);
    const CubeQuadrature q(4);
    const EnvBinning all = binEnvironment(env, q, Mat3::identity(), 0.0);
    const EnvBinning hot = binEnvironment(env, q, Mat3::identity(), 0.01);
    ASSERT_EQ(hot.hotSuns.size(), 1u);
    EXPECT_GT(hot.hotShare, 0.5);
    // The bins are those of the map with that pixel black, and the sun carries the
    // pixel's radiance times its solid angle (row 9 of 32, one of 64 columns).
    const EnvBinning black = binEnvironment(mapWithHotPixel(0.0f), q, Mat3::identity(), 0.0);
    for (int i = 0; i < q.count(); ++i)
        for (int c = 0; c < 3; ++c) EXPECT_EQ(hot.radiance[i][c], black.radiance[i][c]) << i;
    const double omega = (2 * kPi / 64) * (std::cos(9 * kPi / 32) - std::cos(10 * kPi / 32));
    EXPECT_NEAR(hot.hotSuns[0].irradiance.r, 5e4 * omega, 1e-3 * 5e4 * omega);
    // It points where the pixel is: light travels away from the sun, into a bin that
    // the pixel brightens when binned (the pixel straddles two bins here).
    EXPECT_GT(all.radiance[q.indexOf(-hot.hotSuns[0].toSun)].r, 1000.0f);
    EXPECT_GT(binnedPower(all, q, 0), binnedPower(hot, q, 0) + 0.9 * 5e4 * omega);
}

TEST(LpmCache, ComputesOnceAndSolvesIdentically) {
    const Medium m = test::makeVolume(test::VolumeKind::Cloud, 12, 4.0);
    const EnvMap env = mapWithHotPixel(5e3f);
    Lights lights;
    lights.env = &env;
    LpmSettings s;
    s.directionsPerFace = 2;
    s.tolerance = 1e-2;
    const LpmResult plain = solveLpm(m, lights, s);
    s.cache = std::make_shared<LpmCache>();
    const LpmResult first = solveLpm(m, lights, s);
    const LpmResult second = solveLpm(m, lights, s);
    EXPECT_EQ(s.cache->formFactorsComputed(), 1);
    EXPECT_EQ(s.cache->envBinningsComputed(), 1);
    EXPECT_EQ(plain.sh, first.sh);  // bit-identical with and without the cache
    EXPECT_EQ(first.sh, second.sh);
    EXPECT_EQ(plain.decisions, second.decisions);
    // Other keys are computed anew, and a forgotten environment is binned again.
    EXPECT_NE(s.cache->formFactors(2, 0, 0.5).get(), s.cache->formFactors(2, 0, 0.0).get());
    s.cache->forgetEnvironments();
    solveLpm(m, lights, s);
    EXPECT_EQ(s.cache->envBinningsComputed(), 2);
}

// Environment binning and the solver's precomputation cache (core/env_binning.h,
// core/lpm_cache.h).
#include <algorithm>
#include <cmath>

#include <gtest/gtest.h>

#include "core/env_binning.h"
#include "core/lpm_cache.h"
#include "core/lpm_solver.h"
#include "core/parallel.h"
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

TEST(EnvBinning, TouchingHotPixelsAreOneSun) {
    // A 3 x 3 sun at columns 40-42, rows 9-11, a lone hot pixel far away, and a pair that
    // touches across the longitude seam (columns 63 and 0): three suns.
    std::vector<RGB> px(64 * 32, RGB(0.1f));
    for (int y = 9; y <= 11; ++y)
        for (int x = 40; x <= 42; ++x) px[size_t(y) * 64 + x] = RGB(2e4f);
    px[25 * 64 + 10] = RGB(3e4f);
    px[16 * 64 + 63] = px[16 * 64 + 0] = RGB(3e4f);
    const EnvMap env(64, 32, px);
    const CubeQuadrature q(4);
    const EnvBinning b = binEnvironment(env, q, Mat3::identity(), 0.005);
    ASSERT_EQ(b.hotSuns.size(), 3u);
    const std::vector<EnvHotPixel> hot = env.hotPixels(0.005, 16);
    ASSERT_EQ(hot.size(), 12u);
    // The big sun: the summed irradiance, toward the centre pixel, a disc reaching the corners.
    double e = 0;
    Vec3 centre{0, 0, 0};
    for (const EnvHotPixel& h : hot)
        if (h.x >= 40 && h.x <= 42) e += h.radiance.r * h.omega;
    for (const EnvHotPixel& h : hot)
        if (h.x == 41 && h.y == 10) centre = h.toward;
    const Sun* big = nullptr;
    for (const Sun& s : b.hotSuns)
        if (s.irradiance.r > 0.8 * e) big = &s;
    ASSERT_NE(big, nullptr);
    EXPECT_NEAR(big->irradiance.r, e, 1e-4 * e);
    EXPECT_GT(dot(big->toSun, centre), std::cos(0.02));  // within about a third of a pixel
    const double pixelDeg = 180.0 / 32;
    EXPECT_GT(big->angularDiameterDeg, 2 * pixelDeg);  // the 3 x 3 block is ~3 pixels across
    EXPECT_LT(big->angularDiameterDeg, 4 * pixelDeg);
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

TEST(EnvBinning, SameBinsForAnyThreadCountAndAsOneSerialSum) {
    // A 512x256 map of uneven radiance: its rows are binned in blocks over the threads.
    std::vector<RGB> px;
    for (int y = 0; y < 256; ++y)
        for (int x = 0; x < 512; ++x)
            px.push_back(RGB(float((x * 7 + y * 3) % 101) + 0.25f, float((x ^ y) % 17), float(y % 5) + 1.0f));
    const EnvMap env(512, 256, px, 33.0);
    const CubeQuadrature q(6);
    const Mat3 R = Mat3::rotation({0.3, 1, 0.2}, 0.4);
    EnvBinning one, two;
    {
        ThreadLimit limit(1);
        one = binEnvironment(env, q, R, 0.0);
    }
    {
        ThreadLimit limit(2);
        two = binEnvironment(env, q, R, 0.0);
    }
    // The same sub-pixels summed in one serial pass (sub-pixel rule of binEnvironment).
    const int sub = std::clamp(int(std::ceil(std::sqrt(1024.0 * q.count() / (512.0 * 256)))), 1, 256);
    std::vector<double> acc(size_t(q.count()) * 4, 0.0);
    env.forEachSubPixelInRows(sub, 0, 256 * sub, [&](const Vec3& toward, double omega, const RGB& L) {
        const int i = q.indexOf(R * (-toward));
        for (int c = 0; c < 3; ++c) acc[size_t(i) * 4 + c] += L[c] * omega;
        acc[size_t(i) * 4 + 3] += omega;
    });
    for (int i = 0; i < q.count(); ++i)
        for (int c = 0; c < 3; ++c) {
            EXPECT_EQ(one.radiance[i][c], two.radiance[i][c]) << i;
            const double serial = acc[size_t(i) * 4 + c] / acc[size_t(i) * 4 + 3];
            EXPECT_NEAR(one.radiance[i][c], serial, 1e-6 * serial + 1e-7) << i;
        }
}

// Lat-long environment: ImfEnvmap orientation, rotation, sampling density, sub-pixels.
#include "core/envmap.h"

#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "core/error.h"
#include "core/rng.h"

using namespace lpm;

namespace {
// An 8x4 map whose pixel (x, y) holds (x, y, 1).
EnvMap codedMap(double rotate = 0) {
    std::vector<RGB> px;
    for (int y = 0; y < 4; ++y)
        for (int x = 0; x < 8; ++x) px.push_back(RGB(float(x), float(y), 1.0f));
    return EnvMap(8, 4, px, rotate);
}
}  // namespace

TEST(EnvMap, ImfEnvmapOrientation) {
    const EnvMap m = codedMap();
    // +Z: longitude 0 -> u = 0.5 (column 4 of 8), just above the horizon -> row 1.
    EXPECT_EQ(m.lookup(normalize(Vec3{0, 0.1, 1})).r, 4.0f);
    EXPECT_EQ(m.lookup(normalize(Vec3{0, 0.1, 1})).g, 1.0f);
    // +X: longitude +pi/2 -> u = 0.25 (column 2); -X -> u = 0.75 (column 6).
    EXPECT_EQ(m.lookup(normalize(Vec3{1, 0.1, 0})).r, 2.0f);
    EXPECT_EQ(m.lookup(normalize(Vec3{-1, 0.1, 0})).r, 6.0f);
    // -Z: longitude pi -> u = 0 (column 0; or wraps to 7 just past it).
    EXPECT_EQ(m.lookup(normalize(Vec3{0.01, 0.1, -1})).r, 0.0f);
    // Up is the top row, down the bottom row.
    EXPECT_EQ(m.lookup(Vec3{0, 1, 0}).g, 0.0f);
    EXPECT_EQ(m.lookup(Vec3{0, -1, 0}).g, 3.0f);
}

TEST(EnvMap, RotationAboutY) {
    // Rotating the environment by +90 degrees about +Y brings what was at +Z to +X.
    const EnvMap m = codedMap(90.0);
    EXPECT_EQ(m.lookup(normalize(Vec3{1, 0.1, 0})).r, 4.0f);
}

TEST(EnvMap, SubPixelsCoverTheSphere) {
    const EnvMap m = codedMap();
    double total = 0, weighted = 0;
    m.forEachSubPixelInRows(3, 0, 3 * m.height(), [&](const Vec3& d, double w, const RGB& L) {
        EXPECT_NEAR(length(d), 1.0, 1e-9);
        EXPECT_EQ(m.lookup(d).r, L.r);
        EXPECT_EQ(m.lookup(d).g, L.g);
        total += w;
        weighted += w * L.average();
    });
    EXPECT_NEAR(total, kFourPi, 1e-9);
    EXPECT_NEAR(weighted, m.integral(), 1e-9 * m.integral());
}

TEST(EnvMap, SamplingPdfMatchesLookupAndIntegratesToOne) {
    const EnvMap m = codedMap(30.0);
    Pcg32 rng(1, 2);
    // Unbiased estimate of Int L_avg dw: mean of L/pdf equals the integral.
    double est = 0;
    const int n = 200000;
    for (int i = 0; i < n; ++i) {
        Vec3 d;
        double pdf;
        const RGB L = m.sample(rng.uniform(), rng.uniform(), d, pdf);
        ASSERT_GT(pdf, 0);
        EXPECT_NEAR(pdf, m.pdf(d), 1e-6 * pdf);
        EXPECT_EQ(L.r, m.lookup(d).r);
        est += L.average() / pdf / n;
    }
    EXPECT_NEAR(est / m.integral(), 1.0, 1e-6);  // pdf proportional to L: zero variance
    // pdf integrates to 1 over the sphere.
    double total = 0;
    m.forEachSubPixelInRows(4, 0, 4 * m.height(), [&](const Vec3& d, double w, const RGB&) { total += m.pdf(d) * w; });
    EXPECT_NEAR(total, 1.0, 1e-9);
}

TEST(EnvMap, RejectsBadPixels) {
    EXPECT_THROW(EnvMap(2, 1, {RGB(1.f), RGB(-1.f)}), Error);
    EXPECT_THROW(EnvMap(2, 1, {RGB(1.f), RGB(NAN)}), Error);
    EXPECT_THROW(EnvMap(2, 2, {RGB(1.f)}), Error);
}

TEST(EnvMap, SmoothLookupInterpolatesBetweenPixelCentres) {
    const EnvMap m = codedMap();
    // At a pixel centre the smooth lookup equals the pixel.
    const double lat = kPi / 2 - 1.5 / 4 * kPi, lon = kPi - 2 * kPi * 2.5 / 8;
    const Vec3 d{std::cos(lat) * std::sin(lon), std::sin(lat), std::cos(lat) * std::cos(lon)};
    EXPECT_NEAR(m.lookupSmooth(d).r, 2.0f, 1e-4);
    EXPECT_NEAR(m.lookupSmooth(d).g, 1.0f, 1e-4);
    // Half-way between columns 2 and 3 (same row): the mean.
    const double lon2 = kPi - 2 * kPi * 3.0 / 8;
    const Vec3 e{std::cos(lat) * std::sin(lon2), std::sin(lat), std::cos(lat) * std::cos(lon2)};
    EXPECT_NEAR(m.lookupSmooth(e).r, 2.5f, 1e-4);
}

TEST(EnvMap, UpAxisZTurnsTheZenithToPlusZ) {
    std::vector<RGB> px;
    for (int y = 0; y < 4; ++y)
        for (int x = 0; x < 8; ++x) px.push_back(RGB(float(x), float(y), 1.0f));
    const EnvMap m(8, 4, px, 0.0, 1.0f, UpAxis::Z);
    // The image's top row is world +Z, its bottom row world -Z.
    EXPECT_EQ(m.lookup(Vec3{0, 0, 1}).g, 0.0f);
    EXPECT_EQ(m.lookup(Vec3{0, 0, -1}).g, 3.0f);
    // The image centre (longitude 0) faces world -Y; +X stays +X (column 2).
    EXPECT_EQ(m.lookup(normalize(Vec3{0, -1, 0.1})).r, 4.0f);
    EXPECT_EQ(m.lookup(normalize(Vec3{0, -1, 0.1})).g, 1.0f);
    EXPECT_EQ(m.lookup(normalize(Vec3{1, 0, 0.1})).r, 2.0f);
    // --env-rotate turns about the up axis: +90 brings the centre from -Y to +X.
    const EnvMap r(8, 4, px, 90.0, 1.0f, UpAxis::Z);
    EXPECT_EQ(r.lookup(normalize(Vec3{1, 0, 0.1})).r, 4.0f);
    // upAxisToWorld is the same turn as the map's.
    const Vec3 img = normalize(Vec3{0.3, 0.5, 0.8});
    const Vec3 w = upAxisToWorld(UpAxis::Z, img);
    EXPECT_EQ(m.lookup(w).r, EnvMap(8, 4, px).lookup(img).r);
    EXPECT_EQ(m.lookup(w).g, EnvMap(8, 4, px).lookup(img).g);
}

TEST(EnvMap, SubPixelRowsAreIndependent) {
    // Any split of the rows visits the same sub-pixels with the same values, in order.
    const EnvMap m = codedMap(20.0);
    std::vector<double> whole, split;
    auto into = [](std::vector<double>& v) {
        return [&v](const Vec3& d, double w, const RGB& L) {
            v.insert(v.end(), {d.x, d.y, d.z, w, double(L.r), double(L.g)});
        };
    };
    m.forEachSubPixelInRows(3, 0, 12, into(whole));
    m.forEachSubPixelInRows(3, 0, 5, into(split));
    m.forEachSubPixelInRows(3, 5, 7, into(split));
    m.forEachSubPixelInRows(3, 7, 99, into(split));  // rows past the last are none
    ASSERT_EQ(whole.size(), size_t(24 * 12 * 6));
    EXPECT_EQ(whole, split);
}

TEST(EnvMap, SamplingTableBuiltOnceWhateverTheThreads) {
    // The column table is built on the first sample(): threads sampling a fresh map at once
    // get exactly what one thread gets from another fresh map.
    std::vector<RGB> px;
    for (int i = 0; i < 256 * 128; ++i) px.push_back(RGB(float(i % 97) + 0.5f, float(i % 13), 1.0f));
    const EnvMap alone(256, 128, px, 10.0), shared(256, 128, px, 10.0);
    auto draws = [](const EnvMap& m, std::uint64_t seed) {
        Pcg32 rng(seed, 3);
        std::vector<double> out;
        for (int i = 0; i < 2000; ++i) {
            Vec3 d;
            double pdf = 0;
            const RGB L = m.sample(rng.uniform(), rng.uniform(), d, pdf);
            out.insert(out.end(), {d.x, d.y, d.z, pdf, double(L.r), m.pdf(d)});
        }
        return out;
    };
    std::vector<std::vector<double>> got(4);
    std::vector<std::thread> threads;
    for (int t = 0; t < 4; ++t) threads.emplace_back([&, t] { got[size_t(t)] = draws(shared, std::uint64_t(t + 1)); });
    for (auto& t : threads) t.join();
    for (int t = 0; t < 4; ++t) EXPECT_EQ(got[size_t(t)], draws(alone, std::uint64_t(t + 1))) << t;
}

TEST(EnvMap, HotPixelShareIsItsSamplingProbability) {
    std::vector<RGB> px(64 * 32, RGB(1.0f));
    px[5 * 64 + 17] = RGB(2e4f);
    px[20 * 64 + 3] = RGB(9e3f, 1e4f, 1.1e4f);
    const EnvMap m(64, 32, px);
    const std::vector<EnvHotPixel> hot = m.hotPixels(0.01, 16);
    ASSERT_EQ(hot.size(), 2u);
    EXPECT_EQ(hot[0].x, 17);  // the larger share first
    EXPECT_EQ(hot[1].y, 20);
    for (const EnvHotPixel& h : hot) {
        EXPECT_NEAR(h.share, m.pdf(h.toward) * h.omega, 1e-12);
        EXPECT_EQ(h.radiance.r, m.pixel(h.x, h.y).r);
    }
    EXPECT_EQ(m.hotPixels(0.01, 1).size(), 1u);
    EXPECT_TRUE(m.hotPixels(0.9, 16).empty());
}

TEST(EnvMap, ReleasedPixelsKeepTheSummaryAndRefuseReads) {
    EnvMap m = codedMap(15.0);
    const double integral = m.integral();
    const float most = m.maxValue();
    const RGB before = m.lookup(normalize(Vec3{0.2, 0.3, 1}));
    EXPECT_EQ(before.r, m.pixel(4, 1).r);
    m.releasePixels();
    EXPECT_FALSE(m.hasPixels());
    EXPECT_EQ(m.integral(), integral);
    EXPECT_EQ(m.maxValue(), most);
    EXPECT_EQ(m.width(), 8);
    EXPECT_THROW(m.lookup(normalize(Vec3{0.2, 0.3, 1})), Error);
    EXPECT_THROW(m.pixel(0, 0), Error);
    EXPECT_THROW(m.hotPixels(0.1, 4), Error);
    Vec3 d;
    double pdf = 0;
    EXPECT_THROW(m.sample(0.5, 0.5, d, pdf), Error);
    EXPECT_THROW(m.forEachSubPixelInRows(1, 0, 4, [](const Vec3&, double, const RGB&) {}), Error);
}

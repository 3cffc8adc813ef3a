// vdb_io/env_reader: lat-long orientation, channels, NaN policy, size checks, colour.
#include "vdb_io/env_reader.h"

#include <gtest/gtest.h>

#include "test_helpers.h"
#include "vdb_io/io_error.h"

using namespace lpm;
using lpmtest::dataPath;
using lpmtest::expectThrowWith;

namespace {

EnvReadOptions identity(const std::string& path) {
    EnvReadOptions o;
    o.path = path;
    o.colorSpace = "lin_rec709";  // same as the working space: pixels pass unchanged
    o.workingSpace = "lin_rec709";
    return o;
}

RGB code(const Vec3& d) { return RGB(float(d.x + 1), float(d.y + 1), float(d.z + 1)); }

}  // namespace

// Each pixel stores its own direction: lookups must return the code of the direction asked
// for, which checks the loader (no flip, no transpose) and core/envmap together.
TEST(EnvReader, DirectionCodedLatLong) {
    const std::string dir = lpmtest::scratchDir();
    const int W = 128, H = 64;
    lpmtest::writeLatLong(dir + "/dir.exr", W, H, code);
    const EnvInput e = readEnvironment(identity(dir + "/dir.exr"));
    ASSERT_TRUE(e.env);
    EXPECT_EQ(e.width, W);
    EXPECT_EQ(e.height, H);
    const double tol = 2 * kPi / H;  // one pixel of angle
    for (const Vec3& d : {Vec3(1, 0, 0), Vec3(-1, 0, 0), Vec3(0, 0, 1), Vec3(0, 0, -1), Vec3(0, 1, 0),
                          Vec3(0, -1, 0), normalize(Vec3(0.4, 0.5, -0.7)), normalize(Vec3(-0.8, -0.3, 0.2))}) {
        const RGB c = e.env->lookup(d);
        EXPECT_NEAR(c.r - 1, d.x, tol) << d.x << "," << d.y << "," << d.z;
        EXPECT_NEAR(c.g - 1, d.y, tol);
        EXPECT_NEAR(c.b - 1, d.z, tol);
    }
    // --env-rotate 90: the light that came from +Z now comes from R(+Z) = +X (right-handed about +Y).
    EnvReadOptions o = identity(dir + "/dir.exr");
    o.rotateYDeg = 90;
    const EnvInput r = readEnvironment(o);
    const RGB c = r.env->lookup(Vec3(1, 0, 0));
    EXPECT_NEAR(c.b - 1, 1.0, tol);
    EXPECT_NEAR(c.r - 1, 0.0, tol);
}

// OrientationLatLong.exr (openexr-images) is labelled +X at u = 1/4, +Z at the centre, -X at
// u = 3/4 along the horizon (checked by eye). The loader must read MIP level 0 (1024x512),
// drop alpha, and hand core the pixels in place.
TEST(EnvReader, OrientationLatLongExr) {
    const std::string path = dataPath("env/OrientationLatLong.exr");
    const EnvInput e = readEnvironment(identity(path));
    EXPECT_EQ(e.width, 1024);
    EXPECT_EQ(e.height, 512);
    EXPECT_EQ(e.fileChannels, 4);
    auto in = OIIO::ImageInput::open(path);
    ASSERT_TRUE(in);
    std::vector<float> raw(1024 * 512 * 4);
    ASSERT_TRUE(in->read_image(0, 0, 0, 4, OIIO::TypeDesc::FLOAT, raw.data()));
    auto rawAt = [&](int x, int y) { return RGB(raw[(y * 1024 + x) * 4], raw[(y * 1024 + x) * 4 + 1], raw[(y * 1024 + x) * 4 + 2]); };
    struct Probe { Vec3 d; int x, y; };
    // Directions slightly off the pixel boundaries so the pixel is unambiguous: u = 1/4 + e
    // is column 256, v = 1/2 - e is row 255.
    for (const Probe& p : {Probe{normalize(Vec3(1, 0.001, 0.001)), 256, 255}, Probe{normalize(Vec3(-0.001, 0.001, 1)), 512, 255},
                           Probe{normalize(Vec3(-1, 0.001, -0.001)), 768, 255}, Probe{Vec3(0, 1, 0), 512, 0}}) {
        const RGB a = e.env->lookup(p.d), b = rawAt(p.x, p.y);
        for (int c = 0; c < 3; ++c) EXPECT_FLOAT_EQ(a[c], std::max(0.f, b[c])) << "pixel " << p.x << "," << p.y;
    }
}

TEST(EnvReader, NanInfPixelsAndSizeChecks) {
    const std::string dir = lpmtest::scratchDir();
    const std::string path = dataPath("env/BrightRingsNanInf.exr");
    EnvReadOptions o = identity(path);
    expectThrowWith<InputError>([&] { readEnvironment(o); }, {"BrightRingsNanInf.exr", "NaN or infinite", "--sanitize"});
    o.sanitize = true;  // pixels fixed, but the image is square: not a lat-long
    expectThrowWith<InputError>([&] { readEnvironment(o); }, {"800x800", "lat-long", "2 x height"});

    // The top half of the same file is 2:1 and still holds NaN/Inf pixels.
    int w, h, ch;
    std::string cs;
    std::vector<std::string> warn;
    std::vector<float> px = readRgbImage(path, w, h, ch, cs, warn);
    std::vector<float> top(px.begin(), px.begin() + size_t(w) * (h / 2) * 3);
    size_t bad = 0;
    for (float v : top) bad += !std::isfinite(v);
    ASSERT_GT(bad, 0u) << "the crop must keep some NaN/Inf pixels for this test to mean anything";
    auto out = OIIO::ImageOutput::create(dir + "/top.exr");
    out->open(dir + "/top.exr", OIIO::ImageSpec(w, h / 2, 3, OIIO::TypeDesc::FLOAT));
    out->write_image(OIIO::TypeDesc::FLOAT, top.data());
    out->close();
    o.path = dir + "/top.exr";
    o.sanitize = false;
    expectThrowWith<InputError>([&] { readEnvironment(o); }, {std::to_string(bad) + " NaN"});
    o.sanitize = true;
    const EnvInput e = readEnvironment(o);
    EXPECT_EQ(e.sanitized, bad);
    for (int y = 0; y < e.height; ++y)
        for (int x = 0; x < e.width; ++x)
            for (int c = 0; c < 3; ++c) ASSERT_TRUE(std::isfinite(e.env->pixel(x, y)[c]));
}

TEST(EnvReader, GreyReplicatedAndColourConverted) {
    const std::string dir = lpmtest::scratchDir();
    {
        std::vector<float> g(8 * 4, 0.5f);
        auto out = OIIO::ImageOutput::create(dir + "/grey.exr");
        out->open(dir + "/grey.exr", OIIO::ImageSpec(8, 4, 1, OIIO::TypeDesc::FLOAT));
        out->write_image(OIIO::TypeDesc::FLOAT, g.data());
        out->close();
    }
    const EnvInput e = readEnvironment(identity(dir + "/grey.exr"));
    EXPECT_EQ(e.fileChannels, 1);
    const RGB c = e.env->pixel(3, 2);
    EXPECT_FLOAT_EQ(c.r, 0.5f);
    EXPECT_FLOAT_EQ(c.g, 0.5f);
    EXPECT_FLOAT_EQ(c.b, 0.5f);

    // Default colour space: the file's ("Linear" for EXR) -> lin_rec709, converted to ACEScg.
    lpmtest::writeLatLong(dir + "/red.exr", 8, 4, [](const Vec3&) { return RGB(1, 0, 0); });
    EnvReadOptions o;
    o.path = dir + "/red.exr";
    const EnvInput r = readEnvironment(o);
    EXPECT_EQ(r.colorSpace, "lin_rec709");
    EXPECT_EQ(r.workingSpace, "ACEScg");
    EXPECT_NEAR(r.env->pixel(0, 0).r, 0.613097, 2e-5);
    EXPECT_NEAR(r.env->pixel(0, 0).g, 0.070194, 2e-5);
    // Scale applies after conversion.
    o.scale = 2;
    EXPECT_NEAR(readEnvironment(o).env->pixel(0, 0).r, 2 * 0.613097, 4e-5);
}

TEST(EnvReader, HdrFileAndErrors) {
    const EnvInput e = readEnvironment([] {
        EnvReadOptions o;
        o.path = dataPath("env/rooftop_small.hdr");
        return o;
    }());
    EXPECT_EQ(e.width, 300);
    EXPECT_EQ(e.height, 150);
    EXPECT_EQ(e.colorSpace, "lin_rec709");
    EXPECT_GT(e.env->integral(), 0);
    EnvReadOptions o;
    o.path = "/nonexistent/sky.exr";
    expectThrowWith<InputError>([&] { readEnvironment(o); }, {"/nonexistent/sky.exr"});
    o.path = dataPath("env/rooftop_small.hdr");
    o.colorSpace = "bogus_space";
    expectThrowWith<InputError>([&] { readEnvironment(o); }, {"bogus_space"});
}

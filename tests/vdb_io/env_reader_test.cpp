// vdb_io/env_reader: lat-long orientation, channels, NaN policy, size checks, colour.
#include "vdb_io/env_reader.h"

#include <sys/resource.h>

#include <cstdint>
#include <iostream>

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
    for (const Vec3& d : {Vec3(1, 0, 0), Vec3(-1, 0, 0), Vec3(0, 0, 1), Vec3(0, 0, -1), Vec3(0, 1, 0), Vec3(0, -1, 0),
                          normalize(Vec3(0.4, 0.5, -0.7)), normalize(Vec3(-0.8, -0.3, 0.2))})
    {
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
    auto rawAt = [&](int x, int y) {
        return RGB(raw[(y * 1024 + x) * 4], raw[(y * 1024 + x) * 4 + 1], raw[(y * 1024 + x) * 4 + 2]);
    };
    struct Probe {
        Vec3 d;
        int x, y;
    };
    // Directions slightly off the pixel boundaries so the pixel is unambiguous: u = 1/4 + e
    // is column 256, v = 1/2 - e is row 255.
    for (const Probe& p :
         {Probe{normalize(Vec3(1, 0.001, 0.001)), 256, 255}, Probe{normalize(Vec3(-0.001, 0.001, 1)), 512, 255},
          Probe{normalize(Vec3(-1, 0.001, -0.001)), 768, 255}, Probe{Vec3(0, 1, 0), 512, 0}})
    {
        const RGB a = e.env->lookup(p.d), b = rawAt(p.x, p.y);
        for (int c = 0; c < 3; ++c) EXPECT_FLOAT_EQ(a[c], std::max(0.f, b[c])) << "pixel " << p.x << "," << p.y;
    }
}

TEST(EnvReader, NanInfPixelsAndSizeChecks) {
    const std::string dir = lpmtest::scratchDir();
    const std::string path = dataPath("env/BrightRingsNanInf.exr");
    EnvReadOptions o = identity(path);
    expectThrowWith<InputError>([&] { readEnvironment(o); },
                                {"BrightRingsNanInf.exr", "NaN or infinite", "--sanitize"});
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

namespace {

/// Reads `path` as an environment; returns "" on success (with the pixels in `px`) or the
/// error message. Any exception other than InputError is a failure of the test.
/// readEnvironment, or with `inProcess` the same after decoding in this process (the
/// helper gives the same image and message, image_helper_test; it costs 0.5 s a read).
std::string tryRead(const std::string& path, std::vector<RGB>& px, bool inProcess = false) {
    try {
        DecodedImage image;
        if (inProcess) try
            {
                image = decodeImageFile(path);
            } catch (const std::runtime_error& e) {
                throw InputError("env", e.what());
            }
        const EnvInput e =
            inProcess ? environmentFromImage(identity(path), std::move(image)) : readEnvironment(identity(path));
        px.assign(size_t(e.width) * e.height, RGB(0.f));
        for (int y = 0; y < e.height; ++y)
            for (int x = 0; x < e.width; ++x) px[size_t(y) * e.width + x] = e.env->pixel(x, y);
        return "";
    } catch (const InputError& e) {
        return e.what();
    }
}

bool samePixels(const std::vector<RGB>& a, const std::vector<RGB>& b) {
    if (a.size() != b.size()) return false;
    for (size_t i = 0; i < a.size(); ++i)
        for (int c = 0; c < 3; ++c)
            if (a[i][c] != b[i][c]) return false;
    return true;
}

void expectNamedOneLine(const std::string& what, const std::string& path) {
    EXPECT_NE(what.find(path), std::string::npos) << what;
    EXPECT_EQ(what.find('\n'), std::string::npos) << what;
}

}  // namespace

// Truncated, byte-flipped, empty and foreign files: each is refused with one line naming
// the file, or (where the damage misses every pixel lpmbake reads) gives exactly the
// intact file's pixels; never a crash, never NaN. Cut points run from inside the header
// to one byte short. Files: the bundled RLE .hdr, a scanline zip EXR written here, and
// the bundled tiled, MIP-mapped EXR (lpmbake reads level 0 only, so a cut that keeps
// level 0 whole is read correctly: that case must match the intact pixels).
TEST(EnvReader, TruncatedFlippedAndForeignFiles) {
    const std::string dir = lpmtest::scratchDir();
    const std::string scan = dir + "/scanline.exr";
    lpmtest::writeLatLong(scan, 64, 32, [](const Vec3& d) { return code(d); });
    struct Source {
        std::string path, ext;
        bool singleLevel;  // every byte after the header belongs to the pixels read
    };
    const std::vector<Source> sources = {{dataPath("env/rooftop_small.hdr"), ".hdr", true},
                                         {scan, ".exr", true},
                                         {dataPath("env/OrientationLatLong.exr"), ".exr", false}};
    for (const Source& s : sources) {
        SCOPED_TRACE(s.path);
        const std::string bytes = lpmtest::readBytes(s.path);
        ASSERT_GT(bytes.size(), 2000u);
        std::vector<RGB> intact;
        ASSERT_EQ(tryRead(s.path, intact), "");

        int refusedCuts = 0;
        for (size_t cut : {size_t(0), size_t(1), size_t(10), size_t(100), bytes.size() / 4, bytes.size() / 2,
                           bytes.size() * 9 / 10, bytes.size() - 100, bytes.size() - 1})
        {
            SCOPED_TRACE("cut at byte " + std::to_string(cut));
            const std::string path = dir + "/cut" + std::to_string(cut) + s.ext;
            lpmtest::writeBytes(path, bytes.substr(0, cut));
            std::vector<RGB> px;
            const std::string what = tryRead(path, px, true);
            if (what.empty()) {
                EXPECT_FALSE(s.singleLevel) << "a truncated single-level image was read";
                EXPECT_TRUE(samePixels(px, intact)) << "a truncated file was read with different pixels";
            } else {
                expectNamedOneLine(what, path);
                ++refusedCuts;
            }
        }
        EXPECT_GE(refusedCuts, 6);

        // Byte flips at 40 fixed pseudo-random offsets (header and pixels): refused, or
        // read with finite, non-negative pixels. Formats without checksums (RLE .hdr,
        // zip EXR past its zlib stream checks) can decode a flipped pixel byte as another
        // valid value; that cannot be detected and is not counted as a failure.
        std::uint64_t state = 0x9E3779B97F4A7C15ull;
        int refusedFlips = 0, sameFlips = 0;
        for (int i = 0; i < 40; ++i) {
            state = state * 6364136223846793005ull + 1442695040888963407ull;
            const size_t pos = i < 8 ? size_t(i) * 7 : size_t((state >> 33) % bytes.size());
            SCOPED_TRACE("flip at byte " + std::to_string(pos));
            std::string flipped = bytes;
            flipped[pos] = char(~flipped[pos]);
            const std::string path = dir + "/flip" + std::to_string(pos) + s.ext;
            lpmtest::writeBytes(path, flipped);
            std::vector<RGB> px;
            const std::string what = tryRead(path, px, true);
            if (!what.empty()) {
                expectNamedOneLine(what, path);
                ++refusedFlips;
                continue;
            }
            sameFlips += samePixels(px, intact);
            for (const RGB& p : px)
                for (int c = 0; c < 3; ++c) ASSERT_TRUE(std::isfinite(p[c]) && p[c] >= 0.f);
        }
        EXPECT_GE(refusedFlips, 4) << "the magic number and format flips at least are refused";
        std::cout << s.path << ": " << refusedCuts << "/9 cuts refused, " << refusedFlips << "/40 flips refused, "
                  << sameFlips << " read unchanged\n";
    }

    // Not an image at all, under both extensions.
    for (const std::string ext : {".exr", ".hdr"}) {
        const std::string path = dir + "/text" + ext;
        lpmtest::writeBytes(path, "this is a note, not an image\n");
        std::vector<RGB> px;
        expectNamedOneLine(tryRead(path, px), path);
    }
}

// A header claiming an enormous image (a corrupt or hostile file) is refused from its
// header, before the pixel buffer is allocated: 80000 x 40000 RGB floats would be 38 GB.
TEST(EnvReader, HugeDimensionsRefusedBeforeAllocating) {
    const std::string dir = lpmtest::scratchDir();
    const std::string path = dir + "/huge.hdr";
    lpmtest::writeBytes(path, "#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 40000 +X 80000\n" + std::string(64, '\x01'));
    rusage before{};
    ::getrusage(RUSAGE_SELF, &before);
    expectThrowWith<InputError>([&] { readEnvironment(identity(path)); },
                                {path, "80000x40000", "limit", "32768x16384", "downsample"});
    rusage after{}, helper{};
    ::getrusage(RUSAGE_SELF, &after);
    ::getrusage(RUSAGE_CHILDREN, &helper);                        // the image helper that read the header
    EXPECT_LT(after.ru_maxrss - before.ru_maxrss, 256L * 1024L);  // KiB
    EXPECT_GT(helper.ru_maxrss, 0L) << "the image was not read by a helper process";
    EXPECT_LT(helper.ru_maxrss, 512L * 1024L);  // OpenImageIO's own start-up is ~130 MiB
    // The largest accepted size is stated exactly.
    EXPECT_EQ(kMaxEnvPixels, std::int64_t(32768) * 16384);
}

TEST(EnvReader, OptionsNameTheFieldOutOfRange) {
    EnvReadOptions o;
    EXPECT_NO_THROW(o.validate());
    o.scale = -2;
    try {
        o.validate();
        ADD_FAILURE() << "a negative scale passed";
    } catch (const SettingError& e) {
        EXPECT_EQ(e.field(), "scale");
    }
    o.scale = 1;
    o.rotateYDeg = NAN;
    EXPECT_THROW(o.validate(), SettingError);
}

TEST(EnvReader, NonFiniteAndNegativeValuesCountedInEveryChunk) {
    // 512 x 256 pixels: the checks run in chunks over the threads; every chunk's finds count.
    DecodedImage image;
    image.width = 512;
    image.height = 256;
    image.fileChannels = 3;
    image.rgb.assign(size_t(512) * 256 * 3, 0.5f);
    const std::vector<size_t> nan = {0, 70000, 200001, 393215}, negative = {5, 131072, 300000, 393214};
    for (size_t i : nan) image.rgb[i] = i % 2 ? INFINITY : NAN;
    for (size_t i : negative) image.rgb[i] = -2.0f;
    EnvReadOptions o = identity("counted.exr");
    expectThrowWith<InputError>([&] { environmentFromImage(o, image); }, {"counted.exr", "4 NaN or infinite"});
    o.sanitize = true;
    const EnvInput e = environmentFromImage(o, image);
    EXPECT_EQ(e.sanitized, 4u);
    EXPECT_EQ(e.negativeClamped, 4u);
    for (size_t i : nan) EXPECT_EQ(e.env->pixel(int(i / 3 % 512), int(i / 3 / 512))[int(i % 3)], 0.0f) << i;
    for (size_t i : negative) EXPECT_EQ(e.env->pixel(int(i / 3 % 512), int(i / 3 / 512))[int(i % 3)], 0.0f) << i;
    EXPECT_EQ(e.env->pixel(100, 100).g, 0.5f);
}

// vdb_io/image_helper: images read and written in the helper process lpmbake-image come
// out exactly as the in-process codec makes them; every way the helper can fail (missing,
// failing, killed, never waited for) is one line and leaves no process behind.
#include "vdb_io/image_helper.h"

#include <sys/stat.h>
#include <sys/wait.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <stdexcept>

#include <gtest/gtest.h>

#include "test_helpers.h"
#include "vdb_io/image_codec.h"

using namespace lpm;
using lpmtest::dataPath;

namespace {

/// Same pixels and header; the warnings, which name the file, only when both are one file.
void expectSameImage(const DecodedImage& a, const DecodedImage& b, bool sameFile = true) {
    EXPECT_EQ(a.width, b.width);
    EXPECT_EQ(a.height, b.height);
    EXPECT_EQ(a.fileChannels, b.fileChannels);
    EXPECT_EQ(a.fileColorSpace, b.fileColorSpace);
    if (sameFile) {
        EXPECT_EQ(a.warnings, b.warnings);
    }
    EXPECT_EQ(a.warnings.size(), b.warnings.size());
    ASSERT_EQ(a.rgb.size(), b.rgb.size());
    EXPECT_EQ(std::memcmp(a.rgb.data(), b.rgb.data(), a.rgb.size() * sizeof(float)), 0);
}

/// The decoded-image cache (image_cache.h) is off here, so every decode runs the helper
/// these tests are about; the cache's own tests below turn it on for their scope.
const bool kCacheOff = ::setenv("LPMBAKE_IMAGE_CACHE", "off", 1) == 0;

/// LPMBAKE_IMAGE_CACHE at `dir` for one scope.
struct CacheAt {
    explicit CacheAt(const std::string& dir) { ::setenv("LPMBAKE_IMAGE_CACHE", dir.c_str(), 1); }
    ~CacheAt() { ::setenv("LPMBAKE_IMAGE_CACHE", "off", 1); }
};

/// LPMBAKE_IMAGE_HELPER set for one scope.
struct HelperOverride {
    explicit HelperOverride(const std::string& path) { ::setenv("LPMBAKE_IMAGE_HELPER", path.c_str(), 1); }
    ~HelperOverride() { ::unsetenv("LPMBAKE_IMAGE_HELPER"); }
};

std::string script(const std::string& name, const std::string& body) {
    const std::string path = lpmtest::scratchDir() + "/" + name;
    lpmtest::writeBytes(path, "#!/bin/sh\n" + body + "\n");
    ::chmod(path.c_str(), 0755);
    return path;
}

std::string decodeError(const std::string& path) {
    try {
        (void)decodeImageWithHelper(path);
    } catch (const std::runtime_error& e) {
        return e.what();
    }
    ADD_FAILURE() << "decoded " << path;
    return "";
}

}  // namespace

TEST(ImageHelper, FoundWithoutBeingToldWhere) {
    ::unsetenv("LPMBAKE_IMAGE_HELPER");
    const std::filesystem::path p = imageHelperPath();
    EXPECT_EQ(p.filename(), "lpmbake-image");
    EXPECT_TRUE(std::filesystem::is_regular_file(p));
}

TEST(ImageHelper, DecodesExactlyAsTheCodecInProcess) {
    const std::string grey = lpmtest::scratchDir() + "/grey2.exr";
    {
        ImageToEncode g;  // a 2-channel file: grey + alpha, read as grey with a warning
        g.width = 4;
        g.height = 2;
        g.rgb.assign(4 * 2 * 3, 0.25f);
        encodeImageFile(grey, grey, g);
    }
    for (const std::string& path : {dataPath("env/rooftop_small.hdr"), dataPath("env/OrientationLatLong.exr"),
                                    dataPath("env/BrightRingsNanInf.exr"), grey})
    {
        SCOPED_TRACE(path);
        expectSameImage(decodeImageWithHelper(path), decodeImageFile(path));
    }
    // A damaged file: the same message either way.
    const std::string cut = lpmtest::scratchDir() + "/cut.exr";
    lpmtest::writeBytes(cut, lpmtest::readBytes(dataPath("env/OrientationLatLong.exr")).substr(0, 400));
    std::string inProcess;
    try {
        (void)decodeImageFile(cut);
    } catch (const std::runtime_error& e) {
        inProcess = e.what();
    }
    EXPECT_FALSE(inProcess.empty());
    EXPECT_EQ(decodeError(cut), inProcess);
}

TEST(ImageHelper, EncodesExactlyAsTheCodecInProcess) {
    const std::string dir = lpmtest::scratchDir();
    for (const bool png : {false, true}) {
        ImageToEncode img;
        img.width = 16;
        img.height = 8;
        img.png = png;
        // A fixed DateTime: without one the EXR writer stamps the second it writes, and the
        // two writes here can fall in different seconds.
        img.attributes = {{"Software", "lpmbake test"},
                          {"oiio:ColorSpace", png ? "sRGB" : "ACEScg"},
                          {"DateTime", "2026:12:05 10:00:00"}};
        if (!png) img.chromaticities = {0.713f, 0.293f, 0.165f, 0.830f, 0.128f, 0.044f, 0.32168f, 0.33767f};
        for (int i = 0; i < 16 * 8 * 3; ++i) img.rgb.push_back(float(i % 97) / 96.f);
        const std::string ext = png ? ".png" : ".exr";
        encodeImageWithHelper(dir + "/helper" + ext, "shown" + ext, img);
        encodeImageFile(dir + "/direct" + ext, "shown" + ext, img);
        EXPECT_EQ(lpmtest::readBytes(dir + "/helper" + ext), lpmtest::readBytes(dir + "/direct" + ext)) << ext;
        expectSameImage(decodeImageFile(dir + "/helper" + ext), decodeImageFile(dir + "/direct" + ext), false);
    }
}

TEST(ImageHelper, EveryFailureIsOneLine) {
    const std::string missing = lpmtest::scratchDir() + "/no such.exr";
    const std::string why = decodeError(missing);
    EXPECT_NE(why.find("cannot read image '" + missing + "'"), std::string::npos) << why;
    EXPECT_EQ(why.find('\n'), std::string::npos) << why;
    {
        HelperOverride h("/nonexistent/lpmbake-image");
        const std::string w = decodeError(missing);
        EXPECT_NE(w.find("cannot run /nonexistent/lpmbake-image"), std::string::npos) << w;
    }
    {
        HelperOverride h(script("fails.sh", "exit 4"));
        const std::string w = decodeError(missing);
        EXPECT_NE(w.find("failed with exit code 4"), std::string::npos) << w;
    }
    {
        HelperOverride h(script("says.sh", "echo \"first\" >&2; echo \"second\" >&2; exit 1"));
        EXPECT_EQ(decodeError(missing), "first second");
    }
    {
        HelperOverride h(script("killed.sh", "kill -SEGV $$"));
        const std::string w = decodeError(missing);
        EXPECT_NE(w.find("died of signal 11"), std::string::npos) << w;
    }
    {
        HelperOverride h(script("garbage.sh", "echo not an image"));
        const std::string w = decodeError(missing);
        EXPECT_NE(w.find("not an lpmbake-image stream"), std::string::npos) << w;
    }
}

TEST(ImageHelper, ADecodeNeverWaitedForIsStoppedAndReaped) {
    HelperOverride h(script("slow.sh", "exec sleep 60"));
    const auto t0 = std::chrono::steady_clock::now();
    {
        ImageDecode pending(dataPath("env/rooftop_small.hdr"));
    }
    EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(30));
    EXPECT_EQ(::waitpid(-1, nullptr, WNOHANG), -1);  // no child left, not even a zombie
    EXPECT_EQ(errno, ECHILD);
}

// A helper that dies without reading the image: lpmbake gets its message, not SIGPIPE.
TEST(ImageHelper, AnEncoderThatDiesEarlyIsOneLineNotSigpipe) {
    ImageToEncode img;
    img.width = 256;  // 768 KiB: far more than a pipe holds
    img.height = 256;
    img.rgb.assign(256 * 256 * 3, 0.5f);
    const std::string out = lpmtest::scratchDir() + "/never.exr";
    auto encodeError = [&] {
        try {
            encodeImageWithHelper(out, out, img);
        } catch (const std::runtime_error& e) {
            return std::string(e.what());
        }
        ADD_FAILURE() << "encoded";
        return std::string();
    };
    {
        HelperOverride h(script("refuses.sh", "echo \"cannot write here\" >&2; exit 3"));
        EXPECT_EQ(encodeError(), "cannot write here");
    }
    {
        HelperOverride h(script("crashes.sh", "kill -SEGV $$"));
        const std::string w = encodeError();
        EXPECT_NE(w.find("died of signal 11"), std::string::npos) << w;
    }
    EXPECT_FALSE(std::filesystem::exists(out));
}

TEST(ImageHelper, AnEncodeNeverFinishedIsStoppedAndReaped) {
    HelperOverride h(script("slow_encoder.sh", "exec sleep 60"));
    const auto t0 = std::chrono::steady_clock::now();
    {
        ImageEncode pending(lpmtest::scratchDir() + "/x.png", "x.png");
    }
    EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(30));
    EXPECT_EQ(::waitpid(-1, nullptr, WNOHANG), -1);
    EXPECT_EQ(errno, ECHILD);
}

TEST(ImageHelper, TheDecodedImagesFileGoesWhenItIsRead) {
    // The helper's output (the image again, in memory) is closed once read, not kept as
    // long as the ImageDecode (a bake keeps that to its end): no descriptor stays open.
    auto openDescriptors = [] {
        size_t n = 0;
        for ([[maybe_unused]] const auto& e : std::filesystem::directory_iterator("/proc/self/fd")) ++n;
        return n;
    };
    const size_t before = openDescriptors();
    ImageDecode decode(dataPath("env/rooftop_small.hdr"));
    EXPECT_GT(openDescriptors(), before);
    const DecodedImage image = decode.wait();
    EXPECT_EQ(image.width, 300);
    EXPECT_EQ(openDescriptors(), before);
    EXPECT_THROW(decode.wait(), std::runtime_error);  // once
}

namespace {

/// A helper that appends a line to `log` for each run, then runs the real one.
std::string countingHelper(const std::string& log) {
    ::unsetenv("LPMBAKE_IMAGE_HELPER");
    return script("counting.sh", "echo run >> '" + log + "'\nexec '" + imageHelperPath() + "' \"$@\"");
}

size_t runsIn(const std::string& log) {
    const std::string s = lpmtest::readBytes(log);
    return size_t(std::count(s.begin(), s.end(), '\n'));
}

void writeGrey(const std::string& path, float value) {
    ImageToEncode g;  // chromaticities: decoded with a warning that names the file
    g.width = 4;
    g.height = 2;
    g.chromaticities = {0.713f, 0.293f, 0.165f, 0.830f, 0.128f, 0.044f, 0.32168f, 0.33767f};
    g.rgb.assign(4 * 2 * 3, value);
    encodeImageFile(path, path, g);
}

}  // namespace

TEST(ImageHelper, ACachedImageIsReadWithoutStartingTheHelper) {
    ASSERT_TRUE(kCacheOff);
    const std::string dir = lpmtest::scratchDir(), log = dir + "/runs", grey = dir + "/grey.exr";
    CacheAt cache(dir + "/cache");
    HelperOverride h(countingHelper(log));
    writeGrey(grey, 0.25f);
    ImageDecode first(grey);
    const DecodedImage decoded = first.wait();
    EXPECT_FALSE(first.cacheHit());
    EXPECT_NE(first.cacheNote().find("decoded and stored in the image cache " + dir + "/cache"), std::string::npos)
        << first.cacheNote();
    EXPECT_EQ(runsIn(log), 1u);
    ASSERT_EQ(decoded.warnings.size(), 1u);
    ImageDecode second(grey);
    const DecodedImage cached = second.wait();
    EXPECT_TRUE(second.cacheHit());
    EXPECT_EQ(second.cacheNote(), "read from the image cache " + dir + "/cache");
    EXPECT_EQ(runsIn(log), 1u);  // no helper this time
    expectSameImage(cached, decoded);
    // The file changes: decoded again, the new pixels.
    writeGrey(grey, 0.5f);
    ImageDecode third(grey);
    const DecodedImage changed = third.wait();
    EXPECT_FALSE(third.cacheHit());
    EXPECT_EQ(runsIn(log), 2u);
    ASSERT_FALSE(changed.rgb.empty());
    EXPECT_EQ(changed.rgb[0], 0.5f);
}

TEST(ImageHelper, AFailedDecodeIsNotCached) {
    const std::string dir = lpmtest::scratchDir(), log = dir + "/runs", cut = dir + "/cut.exr";
    CacheAt cache(dir + "/cache");
    HelperOverride h(countingHelper(log));
    lpmtest::writeBytes(cut, lpmtest::readBytes(dataPath("env/OrientationLatLong.exr")).substr(0, 400));
    const std::string error = decodeError(cut);
    EXPECT_FALSE(error.empty());
    EXPECT_EQ(decodeError(cut), error);
    EXPECT_EQ(runsIn(log), 2u);
    std::error_code ec;
    for (const auto& e : std::filesystem::directory_iterator(dir + "/cache", ec)) ADD_FAILURE() << e.path();
}

TEST(ImageHelper, ADamagedCacheEntryIsDecodedAgainAndReplaced) {
    const std::string dir = lpmtest::scratchDir(), log = dir + "/runs", grey = dir + "/grey.exr";
    CacheAt cache(dir + "/cache");
    HelperOverride h(countingHelper(log));
    writeGrey(grey, 0.25f);
    const DecodedImage decoded = ImageDecode(grey).wait();
    std::filesystem::path entry;
    for (const auto& e : std::filesystem::directory_iterator(dir + "/cache")) entry = e.path();
    ASSERT_EQ(entry.extension(), ".lpmimg");
    std::string bytes = lpmtest::readBytes(entry);
    bytes[bytes.size() - 16 - 5] ^= 0x40;  // a float's byte: the stream still parses
    lpmtest::writeBytes(entry, bytes);
    ImageDecode again(grey);
    expectSameImage(again.wait(), decoded);
    EXPECT_FALSE(again.cacheHit());
    EXPECT_EQ(runsIn(log), 2u);
    ImageDecode third(grey);  // the entry was stored again, whole
    expectSameImage(third.wait(), decoded);
    EXPECT_TRUE(third.cacheHit());
    EXPECT_EQ(runsIn(log), 2u);
    // A header that does not parse (std::stoi's logic_error, not a runtime_error).
    bytes = lpmtest::readBytes(entry);
    const size_t width = bytes.find("width 4");
    ASSERT_NE(width, std::string::npos);
    bytes[width + 6] = '?';
    lpmtest::writeBytes(entry, bytes);
    ImageDecode fourth(grey);
    expectSameImage(fourth.wait(), decoded);
    EXPECT_FALSE(fourth.cacheHit());
    EXPECT_EQ(runsIn(log), 3u);
}

TEST(ImageHelper, ACacheThatCannotBeWrittenOnlyMeansNoCache) {
    const std::string dir = lpmtest::scratchDir(), blocker = dir + "/a-file";
    lpmtest::writeBytes(blocker, "not a directory");
    CacheAt cache(blocker + "/images");  // cannot be created, even by root
    ImageDecode decode(dataPath("env/rooftop_small.hdr"));
    const DecodedImage image = decode.wait();
    EXPECT_EQ(image.width, 300);
    EXPECT_FALSE(decode.cacheHit());
    EXPECT_NE(decode.cacheNote().find("decoded; not cached: cannot create " + blocker + "/images"), std::string::npos)
        << decode.cacheNote();
}

TEST(ImageHelper, AnImageRewrittenWhileDecodedIsNotCached) {
    // The key hashes the bytes before the helper reads them: a sky rewritten in between
    // (an artist saving over it mid-bake) must not be stored under the old bytes' key.
    const std::string dir = lpmtest::scratchDir(), grey = dir + "/grey.exr";
    CacheAt cache(dir + "/cache");
    ::unsetenv("LPMBAKE_IMAGE_HELPER");
    HelperOverride h(
        script("rewrites.sh", "touch -d '2001-01-01 00:00' '" + grey + "'\nexec '" + imageHelperPath() + "' \"$@\""));
    writeGrey(grey, 0.25f);  // after script(), which empties the test's directory
    ImageDecode decode(grey);
    (void)decode.wait();
    EXPECT_FALSE(decode.cacheHit());
    EXPECT_NE(decode.cacheNote().find("not cached: the file changed while it was decoded"), std::string::npos)
        << decode.cacheNote();
    std::error_code ec;
    for (const auto& e : std::filesystem::directory_iterator(dir + "/cache", ec)) ADD_FAILURE() << e.path();
}

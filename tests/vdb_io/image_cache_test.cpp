// vdb_io/image_cache: an entry gives back exactly the stream stored, is keyed by every
// byte of the image, its name and the helper, is missed (and removed) when damaged, and
// the least recently used entries go first once the cache is over its limit.
#include "vdb_io/image_cache.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <initializer_list>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "test_helpers.h"

using namespace lpm;
namespace fs = std::filesystem;

namespace {

/// A file holding `bytes`, open for reading (closed by the caller).
int streamOf(const std::string& path, const std::string& bytes) {
    fs::create_directories(fs::path(path).parent_path());
    lpmtest::writeBytes(path, bytes);
    return ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
}

std::string readAllFrom(int fd) {
    std::string s;
    char buf[4096];
    ssize_t n;
    while ((n = ::read(fd, buf, sizeof buf)) > 0) s.append(buf, size_t(n));
    return s;
}

/// The entry's stream, or "<miss>": opened, read as a reader does (the floats after the
/// header go to memory, here the second half), and checked.
std::string cached(const ImageCacheConfig& cache, const std::string& key) {
    const int fd = openCachedImage(cache, key);
    if (fd < 0) return "<miss>";
    std::string s = readAllFrom(fd);
    s.resize(s.size() - 16);  // the trailer: hash and magic word
    const size_t head = s.size() / 2;
    const std::string tail = s.substr(head);
    const bool intact = cachedImageIntact(cache, key, fd, tail.data(), tail.size());
    ::close(fd);
    return intact ? s : "<miss>";
}

void store(const ImageCacheConfig& cache, const std::string& key, const std::string& bytes) {
    const int fd = streamOf((cache.dir.parent_path() / ("stream-" + key)).string(), bytes);
    ASSERT_GE(fd, 0);
    EXPECT_EQ(storeCachedImage(cache, key, fd), "");
    ::close(fd);
}

void setModified(const fs::path& p, time_t secondsAgo) {
    const timespec t[2] = {{0, UTIME_OMIT}, {std::time(nullptr) - secondsAgo, 0}};
    ASSERT_EQ(::utimensat(AT_FDCWD, p.c_str(), t, 0), 0) << p;
}

/// Environment variables set for one scope, restored after.
struct EnvSet {
    std::vector<std::pair<std::string, std::string>> saved;
    std::vector<std::string> unset;
    EnvSet(std::initializer_list<std::pair<std::string, const char*>> vars) {
        for (const auto& [name, value] : vars) {
            if (const char* old = std::getenv(name.c_str())) saved.emplace_back(name, old);
            else unset.push_back(name);
            if (value) ::setenv(name.c_str(), value, 1);
            else ::unsetenv(name.c_str());
        }
    }
    ~EnvSet() {
        for (const auto& [name, value] : saved) ::setenv(name.c_str(), value.c_str(), 1);
        for (const auto& name : unset) ::unsetenv(name.c_str());
    }
    EnvSet(const EnvSet&) = delete;
    EnvSet& operator=(const EnvSet&) = delete;
};

}  // namespace

TEST(ImageCache, KeyChangesWithEveryByteTheNameAndTheHelper) {
    const std::string dir = lpmtest::scratchDir();
    const std::string helper = dir + "/helper", a = dir + "/a.exr", b = dir + "/b.exr";
    lpmtest::writeBytes(helper, "helper build 1");
    std::string bytes(5 << 20, 'x');  // past the first 4 MiB read
    lpmtest::writeBytes(a, bytes);
    lpmtest::writeBytes(b, bytes);
    const std::string key = imageCacheKey(a, helper);
    ASSERT_EQ(key.size(), 32u);
    EXPECT_EQ(imageCacheKey(a, helper), key);
    EXPECT_NE(imageCacheKey(b, helper), key);  // the warnings name the file
    bytes[bytes.size() - 1] = 'z';             // the last byte, in the second chunk
    lpmtest::writeBytes(a, bytes);
    const std::string changed = imageCacheKey(a, helper);
    EXPECT_NE(changed, key);
    setModified(helper, 7200);  // another build of the helper
    EXPECT_NE(imageCacheKey(a, helper), changed);
    EXPECT_EQ(imageCacheKey(dir + "/missing.exr", helper), "");
    EXPECT_EQ(imageCacheKey(a, dir + "/no-helper"), "");
    EXPECT_EQ(imageCacheKey(dir, helper), "");  // a directory is not an image
}

TEST(ImageCache, AnEntryGivesBackTheStreamStored) {
    const ImageCacheConfig cache{lpmtest::scratchDir() + "/cache/images", 1 << 20};
    EXPECT_EQ(cached(cache, "k1"), "<miss>");
    std::string stream = "lpmbake-image 1\nwidth 1\n";
    for (int i = 0; i < 1000; ++i) stream += char(i * 7);
    store(cache, "k1", stream);  // creates the directories
    EXPECT_EQ(cached(cache, "k1"), stream);
    EXPECT_EQ(fs::file_size(cache.dir / "k1.lpmimg"), stream.size() + 16);
    // Stored again (two processes decoding the same sky): still one whole entry.
    store(cache, "k1", stream);
    EXPECT_EQ(cached(cache, "k1"), stream);
    size_t files = 0;
    for (const auto& e : fs::directory_iterator(cache.dir)) files += e.is_regular_file();
    EXPECT_EQ(files, 1u);
}

TEST(ImageCache, ADamagedOrTornEntryIsMissedAndRemoved) {
    const ImageCacheConfig cache{lpmtest::scratchDir() + "/images", 1 << 20};
    const std::string stream(5000, 'p');
    store(cache, "flip", stream);
    std::string entry = lpmtest::readBytes(cache.dir / "flip.lpmimg");
    entry[2500] = 'q';
    lpmtest::writeBytes(cache.dir / "flip.lpmimg", entry);
    EXPECT_EQ(cached(cache, "flip"), "<miss>");
    EXPECT_FALSE(fs::exists(cache.dir / "flip.lpmimg"));
    store(cache, "head", stream);  // a byte the check reads from the file, not from memory
    entry = lpmtest::readBytes(cache.dir / "head.lpmimg");
    entry[10] = 'q';
    lpmtest::writeBytes(cache.dir / "head.lpmimg", entry);
    EXPECT_EQ(cached(cache, "head"), "<miss>");
    EXPECT_FALSE(fs::exists(cache.dir / "head.lpmimg"));
    store(cache, "torn", stream);
    entry = lpmtest::readBytes(cache.dir / "torn.lpmimg");
    lpmtest::writeBytes(cache.dir / "torn.lpmimg", entry.substr(0, entry.size() - 100));
    EXPECT_EQ(cached(cache, "torn"), "<miss>");
    EXPECT_FALSE(fs::exists(cache.dir / "torn.lpmimg"));
    lpmtest::writeBytes(cache.dir / "empty.lpmimg", "");
    EXPECT_EQ(cached(cache, "empty"), "<miss>");
    store(cache, "fine", stream);
    EXPECT_EQ(cached(cache, "fine"), stream);
}

TEST(ImageCache, TheLeastRecentlyUsedGoFirstOverTheLimit) {
    const std::string entry(1000, 'e');
    const ImageCacheConfig cache{lpmtest::scratchDir() + "/images", 3 * (1000 + 16)};
    for (const char* k : {"e1", "e2", "e3"}) store(cache, k, entry);
    setModified(cache.dir / "e1.lpmimg", 300);
    setModified(cache.dir / "e2.lpmimg", 200);
    setModified(cache.dir / "e3.lpmimg", 100);
    EXPECT_EQ(cached(cache, "e1"), entry);  // used now: e2 is the least recently used
    store(cache, "e4", entry);
    EXPECT_TRUE(fs::exists(cache.dir / "e1.lpmimg"));
    EXPECT_FALSE(fs::exists(cache.dir / "e2.lpmimg"));
    EXPECT_TRUE(fs::exists(cache.dir / "e3.lpmimg"));
    EXPECT_TRUE(fs::exists(cache.dir / "e4.lpmimg"));
    // An image larger than the whole cache is not stored, and evicts nothing.
    const int fd = streamOf((cache.dir.parent_path() / "big").string(), std::string(4000, 'b'));
    EXPECT_NE(storeCachedImage(cache, "big", fd).find("larger than the cache's limit"), std::string::npos);
    ::close(fd);
    EXPECT_FALSE(fs::exists(cache.dir / "big.lpmimg"));
    EXPECT_TRUE(fs::exists(cache.dir / "e3.lpmimg"));
}

TEST(ImageCache, TemporaryFilesOfAnInterruptedStoreGoAfterAnHour) {
    const ImageCacheConfig cache{lpmtest::scratchDir() + "/images", 1 << 20};
    fs::create_directories(cache.dir);
    lpmtest::writeBytes(cache.dir / "old.lpmimg.tmp.1.0", "half an entry");
    lpmtest::writeBytes(cache.dir / "new.lpmimg.tmp.2.0", "being written");
    lpmtest::writeBytes(cache.dir / "notes.tmp.txt", "a file of the user's, in a directory given as the cache");
    setModified(cache.dir / "old.lpmimg.tmp.1.0", 7200);
    setModified(cache.dir / "notes.tmp.txt", 7200);
    store(cache, "k", "stream");
    EXPECT_FALSE(fs::exists(cache.dir / "old.lpmimg.tmp.1.0"));
    EXPECT_TRUE(fs::exists(cache.dir / "new.lpmimg.tmp.2.0"));  // another process may be writing it
    EXPECT_TRUE(fs::exists(cache.dir / "notes.tmp.txt"));       // not ours
}

TEST(ImageCache, ConcurrentStoresLeaveOneWholeEntryAndNoTemporaryFile) {
    const std::string dir = lpmtest::scratchDir();
    const ImageCacheConfig cache{dir + "/images", 64 << 20};
    std::string stream(3 << 20, 's');
    for (size_t i = 0; i < stream.size(); i += 4099) stream[i] = char(i);
    const std::string path = dir + "/stream";
    lpmtest::writeBytes(path, stream);
    std::vector<std::thread> threads;
    std::vector<std::string> results(4);
    for (int t = 0; t < 4; ++t)
        threads.emplace_back([&, t] {
            const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
            results[size_t(t)] = storeCachedImage(cache, "same", fd);
            ::close(fd);
        });
    for (auto& t : threads) t.join();
    for (const auto& r : results) EXPECT_EQ(r, "");
    EXPECT_EQ(cached(cache, "same"), stream);
    for (const auto& e : fs::directory_iterator(cache.dir)) EXPECT_EQ(e.path().filename(), "same.lpmimg");
}

TEST(ImageCache, WhereItLivesAndItsLimitComeFromTheEnvironment) {
    {
        EnvSet env{{"LPMBAKE_IMAGE_CACHE", "/farm/scratch/skies"}, {"LPMBAKE_IMAGE_CACHE_MIB", "512"}};
        const auto c = imageCacheFromEnvironment();
        ASSERT_TRUE(c);
        EXPECT_EQ(c->dir, "/farm/scratch/skies");
        EXPECT_EQ(c->limitBytes, std::uint64_t(512) << 20);
    }
    {
        EnvSet env{{"LPMBAKE_IMAGE_CACHE", nullptr},
                   {"LPMBAKE_IMAGE_CACHE_MIB", nullptr},
                   {"XDG_CACHE_HOME", "/x/cache"},
                   {"HOME", "/home/td"}};
        const auto c = imageCacheFromEnvironment();
        ASSERT_TRUE(c);
        EXPECT_EQ(c->dir, "/x/cache/lpmbake/images");
        EXPECT_EQ(c->limitBytes, std::uint64_t(2048) << 20);
    }
    {
        EnvSet env{{"LPMBAKE_IMAGE_CACHE", ""}, {"XDG_CACHE_HOME", nullptr}, {"HOME", "/home/td"}};
        const auto c = imageCacheFromEnvironment();
        ASSERT_TRUE(c);
        EXPECT_EQ(c->dir, "/home/td/.cache/lpmbake/images");
    }
    {
        EnvSet env{{"LPMBAKE_IMAGE_CACHE", nullptr}, {"XDG_CACHE_HOME", nullptr}, {"HOME", nullptr}};
        EXPECT_FALSE(imageCacheFromEnvironment());  // nowhere to put it
    }
    {
        EnvSet env{{"LPMBAKE_IMAGE_CACHE", "off"}};
        EXPECT_FALSE(imageCacheFromEnvironment());
    }
    {
        EnvSet env{{"LPMBAKE_IMAGE_CACHE", "/c"}, {"LPMBAKE_IMAGE_CACHE_MIB", "0"}};
        EXPECT_FALSE(imageCacheFromEnvironment());
    }
    for (const char* bad : {"lots", "-5", "12MB"}) {
        EnvSet env{{"LPMBAKE_IMAGE_CACHE", "/c"}, {"LPMBAKE_IMAGE_CACHE_MIB", bad}};
        lpmtest::expectThrowWith<std::runtime_error>(
            [] { (void)imageCacheFromEnvironment(); },
            {"LPMBAKE_IMAGE_CACHE_MIB", std::string("'") + bad + "'", "not a number of MiB"});
    }
}

// The decoded-image cache (image_cache.h).
#include "vdb_io/image_cache.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#include <xxhash.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <memory>
#include <stdexcept>
#include <utility>
#include <vector>

namespace lpm {

namespace fs = std::filesystem;

namespace {

constexpr char kTrailerMagic[8] = {'L', 'P', 'M', 'I', 'M', 'G', 'C', '1'};
constexpr std::size_t kTrailerBytes = 16;  // XXH3-64 of the stream, then the magic word
constexpr std::size_t kChunk = std::size_t(4) << 20;
const char* kEntrySuffix = ".lpmimg";
const char* kTempMarker = ".lpmimg.tmp.";  // only names with it are ever taken for a store's leftovers

/// A file descriptor closed when it goes out of scope.
struct Fd {
    int fd = -1;
    explicit Fd(int f) : fd(f) {}
    ~Fd() {
        if (fd >= 0) ::close(fd);
    }
    Fd(const Fd&) = delete;
    Fd& operator=(const Fd&) = delete;
    int release() { return std::exchange(fd, -1); }
};

std::int64_t nanoseconds(const timespec& t) { return std::int64_t(t.tv_sec) * 1000000000 + t.tv_nsec; }

std::uint64_t limitFromEnvironment() {
    const char* mib = std::getenv("LPMBAKE_IMAGE_CACHE_MIB");
    if (!mib || !*mib) return std::uint64_t(2048) << 20;
    char* end = nullptr;
    errno = 0;
    const unsigned long long v = std::strtoull(mib, &end, 10);
    if (errno != 0 || *end != '\0' || mib[0] == '-' || v > (std::uint64_t(1) << 40))
        throw std::runtime_error(std::string("LPMBAKE_IMAGE_CACHE_MIB: '") + mib +
                                 "' is not a number of MiB (0 turns the image cache off)");
    return std::uint64_t(v) << 20;
}

/// The stream's length and its trailer's hash; false when the entry has no whole trailer.
bool readTrailer(int fd, std::size_t& streamBytes, XXH64_hash_t& hash) {
    struct stat st {};
    if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode) || std::size_t(st.st_size) <= kTrailerBytes) return false;
    streamBytes = std::size_t(st.st_size) - kTrailerBytes;
    char trailer[kTrailerBytes];
    if (::pread(fd, trailer, sizeof trailer, off_t(streamBytes)) != ssize_t(sizeof trailer) ||
        std::memcmp(trailer + 8, kTrailerMagic, 8) != 0)
        return false;
    std::memcpy(&hash, trailer, 8);
    return true;
}

/// The XXH3-64 of the stream's first `headBytes` bytes, read from `fd`, then of `tail`.
XXH64_hash_t hashOfStream(int fd, std::size_t headBytes, const void* tail, std::size_t tailBytes) {
    std::unique_ptr<XXH3_state_t, decltype(&XXH3_freeState)> state(XXH3_createState(), &XXH3_freeState);
    if (!state || XXH3_64bits_reset(state.get()) != XXH_OK) return 0;
    std::vector<char> buf(std::min(headBytes, kChunk));
    for (std::size_t at = 0; at < headBytes;) {
        const ssize_t n = ::pread(fd, buf.data(), std::min(buf.size(), headBytes - at), off_t(at));
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) return 0;
        XXH3_64bits_update(state.get(), buf.data(), std::size_t(n));
        at += std::size_t(n);
    }
    XXH3_64bits_update(state.get(), tail, tailBytes);
    return XXH3_64bits_digest(state.get());
}

struct Entry {
    fs::path path;
    std::int64_t usedNs = 0;
    std::uint64_t bytes = 0;
};

/// Removes the least recently used entries (never `keep`) until the rest fit the limit,
/// and temporary files an interrupted store left more than an hour ago.
void evict(const ImageCacheConfig& cache, const fs::path& keep) {
    std::vector<Entry> entries;
    std::uint64_t total = 0;
    std::error_code ec;
    const std::int64_t hourAgo = (std::int64_t(std::time(nullptr)) - 3600) * 1000000000;
    for (const fs::directory_entry& e : fs::directory_iterator(cache.dir, ec)) {
        struct stat st {};
        if (::lstat(e.path().c_str(), &st) != 0 || !S_ISREG(st.st_mode)) continue;
        const std::string name = e.path().filename().string();
        if (name.find(kTempMarker) != std::string::npos) {
            if (nanoseconds(st.st_mtim) < hourAgo) ::unlink(e.path().c_str());
        } else if (e.path().extension() == kEntrySuffix) {
            entries.push_back({e.path(), nanoseconds(st.st_mtim), std::uint64_t(st.st_size)});
            total += std::uint64_t(st.st_size);
        }
    }
    std::sort(entries.begin(), entries.end(), [](const Entry& a, const Entry& b) { return a.usedNs < b.usedNs; });
    for (const Entry& e : entries) {
        if (total <= cache.limitBytes) break;
        if (e.path == keep) continue;
        if (::unlink(e.path.c_str()) == 0) total -= e.bytes;
    }
}

bool writeAll(int fd, const void* data, std::size_t bytes) {
    const char* p = static_cast<const char*>(data);
    while (bytes > 0) {
        const ssize_t n = ::write(fd, p, bytes);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) return false;
        p += n;
        bytes -= std::size_t(n);
    }
    return true;
}

/// Copies `streamFd` into `out` and appends the trailer; "" or what failed.
std::string copyWithTrailer(int streamFd, int out) {
    std::unique_ptr<XXH3_state_t, decltype(&XXH3_freeState)> state(XXH3_createState(), &XXH3_freeState);
    if (!state || XXH3_64bits_reset(state.get()) != XXH_OK) return "cannot hash";
    std::vector<char> buf(kChunk);
    off_t offset = 0;
    for (;;) {
        const ssize_t n = ::pread(streamFd, buf.data(), buf.size(), offset);
        if (n < 0 && errno == EINTR) continue;
        if (n < 0) return std::string("cannot read the decoded image: ") + std::strerror(errno);
        if (n == 0) break;
        XXH3_64bits_update(state.get(), buf.data(), std::size_t(n));
        if (!writeAll(out, buf.data(), std::size_t(n))) return std::strerror(errno);
        offset += n;
    }
    const XXH64_hash_t hash = XXH3_64bits_digest(state.get());
    char trailer[kTrailerBytes];
    std::memcpy(trailer, &hash, 8);
    std::memcpy(trailer + 8, kTrailerMagic, 8);
    if (!writeAll(out, trailer, sizeof trailer)) return std::strerror(errno);
    return "";
}

fs::path entryPath(const ImageCacheConfig& cache, const std::string& key) { return cache.dir / (key + kEntrySuffix); }

}  // namespace

std::optional<ImageCacheConfig> imageCacheFromEnvironment() {
    ImageCacheConfig cache;
    const char* set = std::getenv("LPMBAKE_IMAGE_CACHE");
    const char* xdg = std::getenv("XDG_CACHE_HOME");
    const char* home = std::getenv("HOME");
    if (set && *set) {
        if (std::string(set) == "off") return std::nullopt;
        cache.dir = set;
    } else if (xdg && xdg[0] == '/') {
        cache.dir = fs::path(xdg) / "lpmbake" / "images";
    } else if (home && home[0] == '/') {
        cache.dir = fs::path(home) / ".cache" / "lpmbake" / "images";
    } else {
        return std::nullopt;
    }
    cache.limitBytes = limitFromEnvironment();
    if (cache.limitBytes == 0) return std::nullopt;
    return cache;
}

std::string imageCacheKey(const std::string& imagePath, const std::string& helperPath) {
    struct stat helper {};
    if (::stat(helperPath.c_str(), &helper) != 0) return "";
    Fd image(::open(imagePath.c_str(), O_RDONLY | O_CLOEXEC));
    struct stat st {};
    if (image.fd < 0 || ::fstat(image.fd, &st) != 0 || !S_ISREG(st.st_mode)) return "";
    std::unique_ptr<XXH3_state_t, decltype(&XXH3_freeState)> state(XXH3_createState(), &XXH3_freeState);
    if (!state || XXH3_128bits_reset(state.get()) != XXH_OK) return "";
    const std::string salt = std::string("lpmbake-image-cache 1 ") + LPM_VERSION_STRING + "\n" + helperPath + "\n" +
                             std::to_string(helper.st_size) + " " + std::to_string(nanoseconds(helper.st_mtim)) + "\n" +
                             imagePath + "\n";
    XXH3_128bits_update(state.get(), salt.data(), salt.size());
    std::vector<char> buf(kChunk);
    for (;;) {
        const ssize_t n = ::read(image.fd, buf.data(), buf.size());
        if (n < 0 && errno == EINTR) continue;
        if (n < 0) return "";
        if (n == 0) break;
        XXH3_128bits_update(state.get(), buf.data(), std::size_t(n));
    }
    const XXH128_hash_t h = XXH3_128bits_digest(state.get());
    char hex[33];
    std::snprintf(hex, sizeof hex, "%016llx%016llx", static_cast<unsigned long long>(h.high64),
                  static_cast<unsigned long long>(h.low64));
    return hex;
}

std::string imageFileStamp(const std::string& imagePath) {
    struct stat st {};
    if (::stat(imagePath.c_str(), &st) != 0) return "";
    return std::to_string(st.st_dev) + " " + std::to_string(st.st_ino) + " " + std::to_string(st.st_size) + " " +
           std::to_string(nanoseconds(st.st_mtim)) + " " + std::to_string(nanoseconds(st.st_ctim));
}

int openCachedImage(const ImageCacheConfig& cache, const std::string& key) {
    const fs::path path = entryPath(cache, key);
    Fd entry(::open(path.c_str(), O_RDONLY | O_CLOEXEC));
    if (entry.fd < 0) return -1;
    std::size_t streamBytes = 0;
    XXH64_hash_t stored = 0;
    if (!readTrailer(entry.fd, streamBytes, stored)) {
        removeCachedImage(cache, key);  // torn: the next decode stores it again
        return -1;
    }
    ::futimens(entry.fd, nullptr);  // used now: the last to be evicted
    return entry.release();
}

bool cachedImageIntact(const ImageCacheConfig& cache, const std::string& key, int fd, const void* tail,
                       std::size_t tailBytes) {
    std::size_t streamBytes = 0;
    XXH64_hash_t stored = 0;
    const bool intact = readTrailer(fd, streamBytes, stored) && tailBytes <= streamBytes &&
                        hashOfStream(fd, streamBytes - tailBytes, tail, tailBytes) == stored;
    if (!intact) removeCachedImage(cache, key);
    return intact;
}

void removeCachedImage(const ImageCacheConfig& cache, const std::string& key) {
    ::unlink(entryPath(cache, key).c_str());
}

std::string storeCachedImage(const ImageCacheConfig& cache, const std::string& key, int streamFd) {
    static std::atomic<unsigned> serial{0};
    struct stat st {};
    if (::fstat(streamFd, &st) != 0) return std::string("cannot measure the decoded image: ") + std::strerror(errno);
    if (std::uint64_t(st.st_size) + kTrailerBytes > cache.limitBytes)
        return "the decoded image (" + std::to_string(st.st_size >> 20) + " MiB) is larger than the cache's limit";
    std::error_code ec;
    fs::create_directories(cache.dir, ec);
    if (ec) return "cannot create " + cache.dir.string() + ": " + ec.message();
    const fs::path final = entryPath(cache, key);
    const fs::path temp = cache.dir / (key + kTempMarker + std::to_string(::getpid()) + "." + std::to_string(serial++));
    std::string failed;
    {
        Fd out(::open(temp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644));
        if (out.fd < 0) return "cannot create " + temp.string() + ": " + std::strerror(errno);
        failed = copyWithTrailer(streamFd, out.fd);
        if (failed.empty() && ::close(out.release()) != 0) failed = std::strerror(errno);
    }
    if (failed.empty() && ::rename(temp.c_str(), final.c_str()) != 0) failed = std::strerror(errno);
    if (!failed.empty()) {
        ::unlink(temp.c_str());
        return "cannot write " + final.string() + ": " + failed;
    }
    evict(cache, final);
    return "";
}

}  // namespace lpm

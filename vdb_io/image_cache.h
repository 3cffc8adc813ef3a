// The decoded-image cache: the image helper's output stream (image_protocol.h) kept on
// disk, so a process that bakes with a sky another process already decoded reads the
// decoded floats instead of starting lpmbake-image (OpenImageIO's 0.4-0.6 s load, plus
// the decode: 1.6-2.1 s for an 8192 x 4096 EXR). docs/image_cache.md has the design.
//
// An entry is named by the XXH3-128 of the helper's identity (path, size, modification
// time), the image path as given (the helper's warnings name it) and every byte of the
// image file: a changed file, another helper build or another name is another entry. An
// entry is the stream followed by its XXH3-64 and a magic word; one that fails the check
// is removed and missed. Entries are written to a temporary name and renamed, so
// concurrent processes see whole entries or none; the least recently used go once the
// directory holds more than its limit. A cache that cannot be read or written is a miss,
// never an error.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>

namespace lpm {

struct ImageCacheConfig {
    std::filesystem::path dir;
    std::uint64_t limitBytes = 0;
};

/// From the environment: LPMBAKE_IMAGE_CACHE (a directory; "off" turns the cache off),
/// else $XDG_CACHE_HOME/lpmbake/images, else $HOME/.cache/lpmbake/images;
/// LPMBAKE_IMAGE_CACHE_MIB, the limit (default 2048). nullopt: off, or no home to put it in.
std::optional<ImageCacheConfig> imageCacheFromEnvironment();

/// The entry name (32 hex digits) for decoding `imagePath` with the helper at `helperPath`
/// (this lpmbake's version, the helper's path, size and modification time, the path as
/// given, the file's bytes); "" when either cannot be read.
std::string imageCacheKey(const std::string& imagePath, const std::string& helperPath);

/// The image file's version as the file system tells it (device, inode, size,
/// modification and change times), "" if it cannot be read: taken before the key and
/// compared before the store, so an image rewritten while the helper decoded it is not
/// stored under the old bytes' key.
std::string imageFileStamp(const std::string& imagePath);

/// A descriptor at the start of entry `key`'s stream, or -1 (none, or torn: no trailer,
/// removed). The caller closes it and checks what it read with cachedImageIntact. Marks
/// the entry used.
int openCachedImage(const ImageCacheConfig& cache, const std::string& key);

/// True when entry `key`, open as `fd`, is intact: the XXH3-64 of its stream, whose last
/// `tailBytes` bytes the caller read into `tail` (the floats: hashed in memory, not read
/// twice), matches the trailer. Otherwise removes the entry.
bool cachedImageIntact(const ImageCacheConfig& cache, const std::string& key, int fd, const void* tail,
                       std::size_t tailBytes);

/// Removes entry `key` (one the reader found unreadable); a missing entry is no error.
void removeCachedImage(const ImageCacheConfig& cache, const std::string& key);

/// Stores the whole content of `streamFd` (read from offset 0) as entry `key`, then removes
/// the least recently used entries until the cache is within its limit. Returns "" or
/// why the entry was not stored. Never throws.
std::string storeCachedImage(const ImageCacheConfig& cache, const std::string& key, int streamFd);

}  // namespace lpm

// lpmbake's way to image files: it runs the helper lpmbake-image (image_helper_main.cpp),
// which links OpenImageIO, and exchanges pixels with it through an anonymous in-memory
// file (a decoded image) or a pipe (an image to write) (image_protocol.h). lpmbake itself
// never loads OpenImageIO: that library and the ~260 it needs take 0.42-0.54 s to load
// and 95 MiB of resident memory (its string table, the relocations of its dependencies)
// that a bake would carry through its solve. docs/image_helper.md has the measurements.
#pragma once

#include <memory>
#include <optional>
#include <string>

#include "vdb_io/image_cache.h"
#include "vdb_io/image_codec.h"

namespace lpm {

/// The helper's path: $LPMBAKE_IMAGE_HELPER if set, else lpmbake-image beside the running
/// executable, in ../libexec/lpmbake from it, or in the build tree this was compiled in.
/// Throws std::runtime_error listing where it looked.
std::string imageHelperPath();

/// decodeImageFile (image_codec.h) in a helper process started by the constructor, so the
/// caller can do other work (read the volume) while OpenImageIO loads and decodes.
/// Problems starting the helper are reported by wait(), like the helper's own errors.
/// A helper never waited for is stopped (SIGTERM) and reaped by the destructor.
/// With the decoded-image cache on (image_cache.h) an image decoded before by another
/// process is read from the cache and no helper starts; one the helper decodes is stored.
class ImageDecode {
public:
    explicit ImageDecode(const std::string& path);
    ~ImageDecode();
    ImageDecode(const ImageDecode&) = delete;
    ImageDecode& operator=(const ImageDecode&) = delete;
    /// The decoded image; throws std::runtime_error as decodeImageWithHelper does. Once.
    DecodedImage wait();
    /// What the cache did, for -v: "" (cache off), read from it, stored in it, or why not.
    const std::string& cacheNote() const { return cacheNote_; }
    /// True when wait() read the image from the cache.
    bool cacheHit() const { return cacheHit_; }

private:
    struct Run;
    void startHelper();
    DecodedImage readCached();
    std::unique_ptr<Run> run_;
    std::string startError_;
    std::string path_, helper_;
    std::optional<ImageCacheConfig> cache_;
    std::string cacheKey_, cacheNote_, imageStamp_;
    int cachedFd_ = -1;
    bool cacheHit_ = false;
};

/// encodeImageFile (image_codec.h) in a helper process started by the constructor and fed
/// through a pipe by finish(), so OpenImageIO loads while the caller renders. Problems
/// starting it are reported by finish(). A helper never finished is stopped and reaped.
class ImageEncode {
public:
    ImageEncode(const std::string& writePath, const std::string& shownPath);
    ~ImageEncode();
    ImageEncode(const ImageEncode&) = delete;
    ImageEncode& operator=(const ImageEncode&) = delete;
    /// Sends the image and waits for the file to be written; throws std::runtime_error. Once.
    void finish(const ImageToEncode& image);

private:
    struct Run;
    std::unique_ptr<Run> run_;
    std::string startError_;
};

/// decodeImageFile / encodeImageFile (image_codec.h) in the helper process. Throw
/// std::runtime_error with the helper's one-line message, or saying why the helper
/// could not run or died.
DecodedImage decodeImageWithHelper(const std::string& path);
void encodeImageWithHelper(const std::string& writePath, const std::string& shownPath, const ImageToEncode& image);

}  // namespace lpm

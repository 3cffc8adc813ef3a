// Image files through OpenImageIO: decode an environment to float RGB, encode a render
// to PNG or EXR. Only the helper process lpmbake-image (image_helper_main.cpp) and tools
// that write images of their own link this; lpmbake reaches it through image_helper.h,
// so a bake never loads OpenImageIO and the 260 libraries it brings (docs/image_helper.md).
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace lpm {

/// An image as float RGB, interleaved, top row first (OIIO's order).
struct DecodedImage {
    int width = 0, height = 0;
    int fileChannels = 0;               ///< channels in the file (1 and 2 are read as grey)
    std::string fileColorSpace;         ///< the file's oiio:ColorSpace, "" if it has none
    std::vector<std::string> warnings;  ///< one line each
    std::vector<float> rgb;             ///< width * height * 3
};

/// What writePreviewImage hands the writer: float RGB (already display-encoded and in
/// [0, 1] for PNG) and the header attributes.
struct ImageToEncode {
    int width = 0, height = 0;
    bool png = false;  ///< 8-bit PNG; else half-float EXR with zip compression
    std::vector<std::pair<std::string, std::string>> attributes;  ///< string attributes
    std::vector<float> chromaticities;                            ///< empty or 8 values (EXR only)
    std::vector<float> rgb;                                       ///< width * height * 3
};

/// The largest image decodeImageFile reads or encodeImageFile writes: 2^29 pixels
/// (32768 x 16384, 6 GiB as float RGB). A corrupt header can claim any size; refusing
/// it keeps that from becoming a many-gigabyte allocation before a pixel is read.
inline constexpr std::int64_t kMaxEnvPixels = std::int64_t(1) << 29;

/// Reads subimage 0 at full resolution. Throws std::runtime_error with a one-line message
/// naming `path` (no component prefix: callers add theirs).
DecodedImage decodeImageFile(const std::string& path);

/// Writes `image` to `writePath` (format by its extension); `shownPath` is the name error
/// messages use. Throws std::runtime_error with a one-line message.
void encodeImageFile(const std::string& writePath, const std::string& shownPath, const ImageToEncode& image);

}  // namespace lpm

// Loads a lat-long environment image (any format OpenImageIO reads) into a core EnvMap in
// the working colour space. Orientation: OpenEXR ImfEnvmap, +Y up (see core/envmap.h).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "core/envmap.h"
#include "vdb_io/image_codec.h"  // kMaxEnvPixels
#include "vdb_io/image_helper.h"

namespace lpm {

struct EnvReadOptions {
    std::string path;
    std::string colorSpace;  ///< empty: the file's oiio:ColorSpace if the config knows it, else lin_rec709
    std::string workingSpace = "ACEScg";
    double rotateYDeg = 0.0;
    float scale = 1.0f;
    UpAxis up = UpAxis::Y;  ///< the scene's up axis (core/envmap.h)
    bool sanitize = false;  ///< NaN/Inf pixels -> 0 instead of an error
    /// Throws SettingError (scale finite and >= 0, rotateYDeg finite).
    void validate() const;
};

struct EnvInput {
    std::unique_ptr<EnvMap> env;
    int width = 0, height = 0, fileChannels = 0;
    std::string colorSpace;             ///< colour space the pixels were read as (canonical name)
    std::string workingSpace;           ///< canonical name of the working space
    std::uint64_t sanitized = 0;        ///< NaN/Inf pixel values set to 0
    std::uint64_t negativeClamped = 0;  ///< negative values (in the file or out of gamut) set to 0
    std::vector<std::string> warnings;
};

/// Throws InputError naming the file and the problem (size, channels, NaN count, colour space).
EnvInput readEnvironment(const EnvReadOptions& options);

/// The same for an image whose decoding `decode` started earlier (image_helper.h) from
/// options.path, so that OpenImageIO loads in the helper while the caller reads the volume.
EnvInput readEnvironment(const EnvReadOptions& options, ImageDecode& decode);

/// What readEnvironment does once the pixels are decoded: NaN policy, colour conversion,
/// lat-long checks. (Tests that read hundreds of damaged files decode them in process.)
EnvInput environmentFromImage(const EnvReadOptions& options, DecodedImage image);

/// The most pixels an environment image may have (32768 x 16384); larger ones are refused.

/// Reads an image as packed RGB floats (first 3 channels, grey replicated), top row first,
/// at full resolution. Throws InputError. Exposed for tests and the renderer.
std::vector<float> readRgbImage(const std::string& path, int& width, int& height, int& channels,
                                std::string& fileColorSpace, std::vector<std::string>& warnings);

}  // namespace lpm

// Environment images: read by the image helper (OpenImageIO), NaN policy, OCIO conversion, lat-long checks.
#include "vdb_io/env_reader.h"

#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <utility>

#include "vdb_io/color.h"
#include "vdb_io/image_helper.h"
#include "vdb_io/io_error.h"

namespace lpm {

namespace {

const char* kComp = "env";

/// The helper's decoded image, its errors as InputError.
DecodedImage waitForImage(ImageDecode& decode) {
    try {
        return decode.wait();
    } catch (const std::runtime_error& e) {
        throw InputError(kComp, e.what());
    }
}

}  // namespace

std::vector<float> readRgbImage(const std::string& path, int& width, int& height, int& channels,
                                std::string& fileColorSpace, std::vector<std::string>& warnings) {
    ImageDecode decode(path);
    DecodedImage img = waitForImage(decode);
    width = img.width;
    height = img.height;
    channels = img.fileChannels;
    fileColorSpace = img.fileColorSpace;
    warnings.insert(warnings.end(), img.warnings.begin(), img.warnings.end());
    return std::move(img.rgb);
}

void EnvReadOptions::validate() const {
    if (!(scale >= 0) || !std::isfinite(scale))
        throw SettingError(kComp, "scale", "must be finite and non-negative, got " + std::to_string(scale));
    if (!std::isfinite(rotateYDeg)) throw SettingError(kComp, "rotateYDeg", "must be finite");
}

EnvInput readEnvironment(const EnvReadOptions& o) {
    o.validate();
    ImageDecode decode(o.path);
    return readEnvironment(o, decode);
}

EnvInput readEnvironment(const EnvReadOptions& o, ImageDecode& decode) {
    o.validate();
    return environmentFromImage(o, waitForImage(decode));
}

EnvInput environmentFromImage(const EnvReadOptions& o, DecodedImage image) {
    o.validate();
    EnvInput out;
    out.width = image.width;
    out.height = image.height;
    out.fileChannels = image.fileChannels;
    out.warnings = std::move(image.warnings);
    const std::string fileSpace = image.fileColorSpace;
    std::vector<float> rgb = std::move(image.rgb);

    // NaN/Inf first: they are a property of the pixels whatever the layout.
    std::uint64_t bad = 0;
    for (float& v : rgb)
        if (!std::isfinite(v)) {
            ++bad;
            if (o.sanitize) v = 0.f;
        }
    if (bad && !o.sanitize)
        throw InputError(kComp, "'" + o.path + "' has " + std::to_string(bad) +
                                    " NaN or infinite pixel value(s); pass --sanitize to set them to 0");
    if (bad)
        out.warnings.push_back("'" + o.path + "': --sanitize set " + std::to_string(bad) +
                               " NaN/infinite pixel value(s) to 0");
    out.sanitized = bad;

    if (out.width != 2 * out.height)
        throw InputError(kComp, "'" + o.path + "' is " + std::to_string(out.width) + "x" + std::to_string(out.height) +
                                    "; an environment must be a lat-long image with width = 2 x height");

    if (!o.colorSpace.empty()) {
        out.colorSpace = canonicalColorSpace(o.colorSpace);
    } else if (colorSpaceKnown(fileSpace)) {
        out.colorSpace = canonicalColorSpace(fileSpace);
    } else {
        out.colorSpace = canonicalColorSpace("lin_rec709");
        out.warnings.push_back("'" + o.path + "' " +
                               (fileSpace.empty()
                                    ? std::string("declares no colour space")
                                    : "declares colour space '" + fileSpace + "', unknown to the OCIO config") +
                               ": reading it as lin_rec709 (set --env-colorspace)");
    }
    out.workingSpace = canonicalColorSpace(o.workingSpace);
    convertColor(rgb, out.colorSpace, out.workingSpace);

    // Negative values are legal in files and appear when converting out-of-gamut colours;
    // radiance cannot be negative, so clamp them (counted, reported).
    std::vector<RGB> pixels(size_t(out.width) * out.height);
    for (size_t p = 0; p < pixels.size(); ++p)
        for (int c = 0; c < 3; ++c) {
            float v = rgb[p * 3 + c];
            if (!std::isfinite(v)) v = 0.f;  // a conversion cannot make NaN from finite input, but be safe
            if (v < 0) {
                v = 0;
                ++out.negativeClamped;
            }
            pixels[p][c] = v;
        }
    if (out.negativeClamped)
        out.warnings.push_back("'" + o.path + "': " + std::to_string(out.negativeClamped) +
                               " negative pixel value(s) (in the file or outside the working gamut) clamped to 0");
    out.env = std::make_unique<EnvMap>(out.width, out.height, std::move(pixels), o.rotateYDeg, o.scale, o.up);
    return out;
}

}  // namespace lpm

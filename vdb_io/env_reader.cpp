// Environment images: read by the image helper (OpenImageIO), NaN policy, OCIO conversion, lat-long checks.
#include "vdb_io/env_reader.h"

#include <cmath>
#include <cstdint>
#include <numeric>
#include <stdexcept>
#include <utility>

#include "core/parallel.h"
#include "vdb_io/color.h"
#include "vdb_io/image_helper.h"
#include "vdb_io/io_error.h"

namespace lpm {

namespace {

const char* kComp = "env";

constexpr size_t kChunk = size_t(1) << 16;  // values per parallel chunk

/// Counts the non-finite values of rgb and, with `zero`, sets them to 0 (over the threads).
std::uint64_t nonFinite(std::vector<float>& rgb, bool zero) {
    std::vector<std::uint64_t> bad((rgb.size() + kChunk - 1) / kChunk, 0);
    parallelForChunks(rgb.size(), kChunk, [&](size_t b, size_t e) {
        std::uint64_t n = 0;
        for (size_t i = b; i < e; ++i)
            if (!std::isfinite(rgb[i])) {
                ++n;
                if (zero) rgb[i] = 0.f;
            }
        bad[b / kChunk] = n;
    });
    return std::accumulate(bad.begin(), bad.end(), std::uint64_t(0));
}

/// Sets rgb's negative (and any non-finite) values to 0, over the threads; returns how
/// many were negative (radiance cannot be negative; files hold such values, and
/// conversions out of gamut make them).
std::uint64_t clampNegatives(std::vector<float>& rgb) {
    std::vector<std::uint64_t> clamped((rgb.size() + kChunk - 1) / kChunk, 0);
    parallelForChunks(rgb.size(), kChunk, [&](size_t b, size_t e) {
        std::uint64_t n = 0;
        for (size_t i = b; i < e; ++i) {
            if (!std::isfinite(rgb[i])) rgb[i] = 0.f;  // a conversion cannot make NaN from finite input, but be safe
            if (rgb[i] < 0) {
                rgb[i] = 0.f;
                ++n;
            }
        }
        clamped[b / kChunk] = n;
    });
    return std::accumulate(clamped.begin(), clamped.end(), std::uint64_t(0));
}

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
    const std::uint64_t bad = nonFinite(rgb, o.sanitize);
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

    out.negativeClamped = clampNegatives(rgb);
    if (out.negativeClamped)
        out.warnings.push_back("'" + o.path + "': " + std::to_string(out.negativeClamped) +
                               " negative pixel value(s) (in the file or outside the working gamut) clamped to 0");
    // The decoded values become the map's pixels: one copy of the image (400 MB at 8K).
    out.env = std::make_unique<EnvMap>(out.width, out.height, std::move(rgb), o.rotateYDeg, o.scale, o.up);
    return out;
}

}  // namespace lpm

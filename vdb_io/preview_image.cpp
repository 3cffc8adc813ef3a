// Preview image writing (preview_image.h).
#include "vdb_io/preview_image.h"

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <utility>

#include "vdb_io/color.h"
#include "vdb_io/image_helper.h"
#include "vdb_io/io_error.h"

namespace lpm {

namespace {

std::string extension(const std::string& path) {
    std::string e = std::filesystem::path(path).extension().string();
    std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    return e;
}

/// EXR chromaticities for the colour spaces of the shipped config (so other tools know
/// the primaries; OIIO 2.4 does not write oiio:ColorSpace into EXR headers).
bool chromaticities(const std::string& space, float c[8]) {
    static const float ap1[8] = {0.713f, 0.293f, 0.165f, 0.830f, 0.128f, 0.044f, 0.32168f, 0.33767f};
    static const float ap0[8] = {0.7347f, 0.2653f, 0.0f, 1.0f, 0.0001f, -0.077f, 0.32168f, 0.33767f};
    static const float r709[8] = {0.64f, 0.33f, 0.30f, 0.60f, 0.15f, 0.06f, 0.3127f, 0.3290f};
    const float* p = space == "ACEScg" ? ap1 : space == "ACES2065-1" ? ap0 : space == "lin_rec709" ? r709 : nullptr;
    if (!p) return false;
    std::copy(p, p + 8, c);
    return true;
}

}  // namespace

bool isPreviewImagePath(const std::string& path) {
    const std::string e = extension(path);
    return e == ".exr" || e == ".png";
}

std::string previewImageEncoding(const std::string& path, const std::string& working) {
    return extension(path) == ".png" ? "sRGB view" : working + " scene-linear";
}

void writePreviewImage(AtomicOutput& out, std::vector<float> img, int width, int height, const std::string& working) {
    ImageEncode encode(out.tempPath(), out.finalPath());
    writePreviewImage(out, encode, std::move(img), width, height, working);
}

void writePreviewImage(AtomicOutput& out, ImageEncode& encode, std::vector<float> img, int width, int height,
                       const std::string& working) {
    ImageToEncode image;
    image.width = width;
    image.height = height;
    image.png = extension(out.finalPath()) == ".png";
    image.attributes.emplace_back("Software", std::string("lpmbake ") + LPM_VERSION_STRING);
    if (image.png) {
        convertToDisplay(img, working);  // config's default display and view (sRGB / Standard)
        for (float& c : img) c = std::clamp(c, 0.f, 1.f);
        image.attributes.emplace_back("oiio:ColorSpace", "sRGB");
    } else {
        image.attributes.emplace_back("oiio:ColorSpace", working);
        image.attributes.emplace_back("lpm:colorspace", working);
        float ch[8];
        if (chromaticities(canonicalColorSpace(working), ch)) image.chromaticities.assign(ch, ch + 8);
    }
    image.rgb = std::move(img);
    try {
        encode.finish(image);
    } catch (const std::runtime_error& e) {
        const std::string why = out.failureReason();
        throw OutputError("render", why.empty() ? e.what() : "cannot write '" + out.finalPath() + "': " + why);
    }
    out.commit();
}

}  // namespace lpm

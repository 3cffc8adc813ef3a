// Preview image writing (preview_image.h).
#include "vdb_io/preview_image.h"

#include <algorithm>
#include <cctype>
#include <filesystem>

#include <OpenImageIO/imageio.h>

#include "vdb_io/color.h"
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
    const bool png = extension(out.finalPath()) == ".png";
    OIIO::ImageSpec spec(width, height, 3, png ? OIIO::TypeDesc::UINT8 : OIIO::TypeDesc::HALF);
    spec.attribute("Software", std::string("lpmbake ") + LPM_VERSION_STRING);
    if (png) {
        convertToDisplay(img, working);  // config's default display and view (sRGB / Standard)
        for (float& c : img) c = std::clamp(c, 0.f, 1.f);
        spec.attribute("oiio:ColorSpace", "sRGB");
    } else {
        spec.attribute("oiio:ColorSpace", working);
        spec.attribute("lpm:colorspace", working);
        float ch[8];
        if (chromaticities(canonicalColorSpace(working), ch))
            spec.attribute("chromaticities", OIIO::TypeDesc(OIIO::TypeDesc::FLOAT, 8), ch);
        spec.attribute("compression", "zip");
    }
    auto writer = OIIO::ImageOutput::create(out.tempPath());
    if (!writer)
        throw OutputError("render", "cannot create an image writer for '" + out.finalPath() + "': " + OIIO::geterror());
    if (!writer->open(out.tempPath(), spec) || !writer->write_image(OIIO::TypeDesc::FLOAT, img.data()) ||
        !writer->close()) {
        const std::string why = out.failureReason();
        throw OutputError("render",
                          "cannot write '" + out.finalPath() + "': " + (why.empty() ? writer->geterror() : why));
    }
    out.commit();
}

}  // namespace lpm

// Image files through OpenImageIO (image_codec.h).
#include "vdb_io/image_codec.h"

#include <algorithm>
#include <stdexcept>

#include <OpenImageIO/imageio.h>

#include "core/malloc_policy.h"

namespace lpm {

namespace {

void checkSize(const std::string& path, int width, int height, int channels) {
    if (width <= 0 || height <= 0 || channels <= 0)
        throw std::runtime_error("image '" + path + "' is empty (" + std::to_string(width) + "x" +
                                 std::to_string(height) + ", " + std::to_string(channels) + " channels)");
    if (std::int64_t(width) * height > kMaxEnvPixels)
        throw std::runtime_error("image '" + path + "' is " + std::to_string(width) + "x" + std::to_string(height) +
                                 ", more than lpmbake's limit of " + std::to_string(kMaxEnvPixels) +
                                 " pixels (32768x16384); downsample it");
}

}  // namespace

DecodedImage decodeImageFile(const std::string& path) {
    auto in = OIIO::ImageInput::open(path);
    if (!in) throw std::runtime_error("cannot read image '" + path + "': " + OIIO::geterror());
    const OIIO::ImageSpec& spec = in->spec();  // subimage 0, MIP level 0: full resolution
    DecodedImage img;
    img.width = spec.width;
    img.height = spec.height;
    img.fileChannels = spec.nchannels;
    checkSize(path, img.width, img.height, img.fileChannels);
    img.fileColorSpace = spec.get_string_attribute("oiio:ColorSpace");
    if (spec.find_attribute("chromaticities"))
        img.warnings.push_back("'" + path +
                               "' has a chromaticities attribute, which lpmbake does not read; say which "
                               "colour space the pixels are in with --env-colorspace");
    const int nread = std::min(img.fileChannels, 3);
    const size_t pixels = size_t(img.width) * img.height;
    std::vector<float> buf;
    assignZeroed(buf, pixels * nread);  // on huge pages: an 8K map is 400 MB, faulted in 4 KiB pages otherwise
    if (!in->read_image(0, 0, 0, nread, OIIO::TypeDesc::FLOAT, buf.data()))
        throw std::runtime_error("cannot read the pixels of '" + path + "': " + in->geterror());
    in->close();
    if (nread == 3) {
        img.rgb = std::move(buf);
        return img;
    }
    // Grey (or grey + alpha): replicate the first channel.
    assignZeroed(img.rgb, pixels * 3);
    for (size_t p = 0; p < pixels; ++p) img.rgb[p * 3] = img.rgb[p * 3 + 1] = img.rgb[p * 3 + 2] = buf[p * nread];
    if (nread == 2) img.warnings.push_back("'" + path + "' has 2 channels: using the first as grey");
    return img;
}

void encodeImageFile(const std::string& writePath, const std::string& shownPath, const ImageToEncode& image) {
    if (image.rgb.size() != size_t(image.width) * image.height * 3 || image.width <= 0 || image.height <= 0)
        throw std::runtime_error("cannot write '" + shownPath + "': " + std::to_string(image.rgb.size()) +
                                 " values for a " + std::to_string(image.width) + "x" + std::to_string(image.height) +
                                 " RGB image");
    OIIO::ImageSpec spec(image.width, image.height, 3, image.png ? OIIO::TypeDesc::UINT8 : OIIO::TypeDesc::HALF);
    for (const auto& [name, value] : image.attributes) spec.attribute(name, value);
    if (image.chromaticities.size() == 8)
        spec.attribute("chromaticities", OIIO::TypeDesc(OIIO::TypeDesc::FLOAT, 8), image.chromaticities.data());
    if (!image.png) spec.attribute("compression", "zip");
    auto writer = OIIO::ImageOutput::create(writePath);
    if (!writer) throw std::runtime_error("cannot create an image writer for '" + shownPath + "': " + OIIO::geterror());
    if (!writer->open(writePath, spec) || !writer->write_image(OIIO::TypeDesc::FLOAT, image.rgb.data()) ||
        !writer->close())
        throw std::runtime_error("cannot write '" + shownPath + "': " + writer->geterror());
}

}  // namespace lpm

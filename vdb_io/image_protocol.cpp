// The image helper's byte stream (image_protocol.h).
#include "vdb_io/image_protocol.h"

#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <sstream>
#include <stdexcept>

namespace lpm {

namespace {

const char* kMagic = "lpmbake-image 1";

void writeAll(int fd, const void* data, size_t bytes) {
    const char* p = static_cast<const char*>(data);
    while (bytes > 0) {
        const ssize_t n = ::write(fd, p, bytes);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) throw std::runtime_error(std::string("image stream: write failed: ") + std::strerror(errno));
        p += n;
        bytes -= size_t(n);
    }
}

void readAll(int fd, void* data, size_t bytes) {
    char* p = static_cast<char*>(data);
    while (bytes > 0) {
        const ssize_t n = ::read(fd, p, bytes);
        if (n < 0 && errno == EINTR) continue;
        if (n < 0) throw std::runtime_error(std::string("image stream: read failed: ") + std::strerror(errno));
        if (n == 0) throw std::runtime_error("image stream: ends " + std::to_string(bytes) + " bytes early");
        p += n;
        bytes -= size_t(n);
    }
}

std::string oneLine(std::string s) {
    for (char& c : s)
        if (c == '\n' || c == '\r') c = ' ';
    return s;
}

/// One header line, without its newline; the header is short, so byte by byte is fine.
std::string readLine(int fd) {
    std::string line;
    char c = 0;
    for (;;) {
        readAll(fd, &c, 1);
        if (c == '\n') return line;
        line += c;
        if (line.size() > 65536) throw std::runtime_error("image stream: header line longer than 64 KiB");
    }
}

/// Header lines until "floats N": calls onLine(key, value) for each, returns N.
template <class OnLine>
size_t readHeader(int fd, OnLine onLine) {
    if (readLine(fd) != kMagic) throw std::runtime_error("image stream: not an lpmbake-image stream");
    for (;;) {
        const std::string line = readLine(fd);
        const size_t space = line.find(' ');
        const std::string key = line.substr(0, space);
        const std::string value = space == std::string::npos ? "" : line.substr(space + 1);
        if (key == "floats") return size_t(std::stoull(value));
        onLine(key, value);
    }
}

void writeSizeAndFloats(int fd, std::ostringstream& head, int width, int height, const std::vector<float>& rgb) {
    std::ostringstream size;
    size << kMagic << "\nwidth " << width << "\nheight " << height << "\n";
    const std::string text = size.str() + head.str() + "floats " + std::to_string(rgb.size()) + "\n";
    writeAll(fd, text.data(), text.size());
    writeAll(fd, rgb.data(), rgb.size() * sizeof(float));
}

/// The float block after the header: exactly width * height * 3 values of an image within
/// kMaxEnvPixels.
std::vector<float> readFloats(int fd, size_t count, int width, int height, FloatStorage storage = nullptr) {
    if (width <= 0 || height <= 0 || std::int64_t(width) * height > kMaxEnvPixels ||
        count != size_t(width) * size_t(height) * 3)
        throw std::runtime_error("image stream: " + std::to_string(count) + " floats for a " + std::to_string(width) +
                                 "x" + std::to_string(height) + " RGB image");
    std::vector<float> rgb;
    if (storage) storage(rgb, count);
    else rgb.resize(count);
    readAll(fd, rgb.data(), count * sizeof(float));
    return rgb;
}

}  // namespace

void writeDecodedImage(int fd, const DecodedImage& image) {
    std::ostringstream head;
    head << "channels " << image.fileChannels << "\ncolorspace " << oneLine(image.fileColorSpace) << "\n";
    for (const auto& w : image.warnings) head << "warning " << oneLine(w) << "\n";
    writeSizeAndFloats(fd, head, image.width, image.height, image.rgb);
}

DecodedImage readDecodedImage(int fd, FloatStorage storage) {
    DecodedImage image;
    const size_t count = readHeader(fd, [&](const std::string& key, const std::string& value) {
        if (key == "width") image.width = std::stoi(value);
        else if (key == "height") image.height = std::stoi(value);
        else if (key == "channels") image.fileChannels = std::stoi(value);
        else if (key == "colorspace") image.fileColorSpace = value;
        else if (key == "warning") image.warnings.push_back(value);
        else throw std::runtime_error("image stream: unknown header line '" + key + "'");
    });
    image.rgb = readFloats(fd, count, image.width, image.height, storage);
    return image;
}

void writeImageToEncode(int fd, const ImageToEncode& image) {
    std::ostringstream head;
    head.precision(9);
    head << "png " << (image.png ? 1 : 0) << "\n";
    for (const auto& [name, value] : image.attributes)
        head << "attribute " << oneLine(name) << " " << oneLine(value) << "\n";
    if (!image.chromaticities.empty()) {
        head << "chromaticities";
        for (float c : image.chromaticities) head << " " << c;
        head << "\n";
    }
    writeSizeAndFloats(fd, head, image.width, image.height, image.rgb);
}

ImageToEncode readImageToEncode(int fd) {
    ImageToEncode image;
    const size_t count = readHeader(fd, [&](const std::string& key, const std::string& value) {
        if (key == "width") image.width = std::stoi(value);
        else if (key == "height") image.height = std::stoi(value);
        else if (key == "png") image.png = value == "1";
        else if (key == "attribute") {
            const size_t space = value.find(' ');
            image.attributes.emplace_back(value.substr(0, space),
                                          space == std::string::npos ? "" : value.substr(space + 1));
        } else if (key == "chromaticities") {
            std::istringstream in(value);
            float c = 0.f;
            while (in >> c) image.chromaticities.push_back(c);
            if (image.chromaticities.size() != 8)
                throw std::runtime_error("image stream: chromaticities need 8 values");
        } else throw std::runtime_error("image stream: unknown header line '" + key + "'");
    });
    image.rgb = readFloats(fd, count, image.width, image.height);
    return image;
}

}  // namespace lpm

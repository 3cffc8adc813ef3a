// vdb_io/image_protocol: the byte stream between lpmbake and lpmbake-image carries every
// field and every float bit for bit, and refuses streams that do not add up.
#include "vdb_io/image_protocol.h"

#include <sys/mman.h>
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <string>

#include <gtest/gtest.h>

using namespace lpm;

namespace {

/// An anonymous file to write a stream into and read it back.
struct Stream {
    int fd = ::memfd_create("image_protocol_test", MFD_CLOEXEC);
    ~Stream() { ::close(fd); }
    void rewind() const { ::lseek(fd, 0, SEEK_SET); }
    void write(const std::string& bytes) const {
        ASSERT_EQ(::write(fd, bytes.data(), bytes.size()), ssize_t(bytes.size()));
    }
};

/// Every float class a decoder can meet: NaN (with a payload), infinities, denormals, -0.
std::vector<float> awkwardFloats(size_t n) {
    std::vector<float> v(n);
    for (size_t i = 0; i < n; ++i) v[i] = float(i) * 0.37f - 3.f;
    const unsigned nanPayload = 0x7fc12345u;
    std::memcpy(&v[0], &nanPayload, 4);
    v[1] = std::numeric_limits<float>::infinity();
    v[2] = -std::numeric_limits<float>::infinity();
    v[3] = std::numeric_limits<float>::denorm_min();
    v[4] = -0.f;
    return v;
}

void expectSameBits(const std::vector<float>& a, const std::vector<float>& b) {
    ASSERT_EQ(a.size(), b.size());
    EXPECT_EQ(std::memcmp(a.data(), b.data(), a.size() * sizeof(float)), 0);
}

}  // namespace

TEST(ImageProtocol, DecodedImageComesBackBitForBit) {
    DecodedImage img;
    img.width = 4;
    img.height = 2;
    img.fileChannels = 2;
    img.fileColorSpace = "lin_rec709";
    img.warnings = {"'a b.exr' has 2 channels: using the first as grey", "two\nlines"};
    img.rgb = awkwardFloats(4 * 2 * 3);
    Stream s;
    writeDecodedImage(s.fd, img);
    s.rewind();
    const DecodedImage back = readDecodedImage(s.fd);
    EXPECT_EQ(back.width, 4);
    EXPECT_EQ(back.height, 2);
    EXPECT_EQ(back.fileChannels, 2);
    EXPECT_EQ(back.fileColorSpace, "lin_rec709");
    ASSERT_EQ(back.warnings.size(), 2u);
    EXPECT_EQ(back.warnings[0], img.warnings[0]);
    EXPECT_EQ(back.warnings[1], "two lines");  // one line each
    expectSameBits(back.rgb, img.rgb);
}

TEST(ImageProtocol, ImageToEncodeComesBackBitForBit) {
    ImageToEncode img;
    img.width = 3;
    img.height = 5;
    img.png = false;
    img.attributes = {{"Software", "lpmbake 0.1.0"}, {"oiio:ColorSpace", "ACEScg"}, {"empty", ""}};
    img.chromaticities = {0.713f, 0.293f, 0.165f, 0.830f, 0.128f, 0.044f, 0.32168f, 0.33767f};
    img.rgb = awkwardFloats(3 * 5 * 3);
    Stream s;
    writeImageToEncode(s.fd, img);
    s.rewind();
    const ImageToEncode back = readImageToEncode(s.fd);
    EXPECT_EQ(back.width, 3);
    EXPECT_EQ(back.height, 5);
    EXPECT_FALSE(back.png);
    EXPECT_EQ(back.attributes, img.attributes);
    expectSameBits(back.chromaticities, img.chromaticities);
    expectSameBits(back.rgb, img.rgb);

    img.png = true;
    img.chromaticities.clear();
    Stream s2;
    writeImageToEncode(s2.fd, img);
    s2.rewind();
    const ImageToEncode png = readImageToEncode(s2.fd);
    EXPECT_TRUE(png.png);
    EXPECT_TRUE(png.chromaticities.empty());
}

TEST(ImageProtocol, RefusesStreamsThatDoNotAddUp) {
    auto refuses = [](const std::string& bytes, const std::string& part) {
        Stream s;
        s.write(bytes);
        s.rewind();
        try {
            (void)readDecodedImage(s.fd);
            ADD_FAILURE() << "accepted: " << part;
        } catch (const std::runtime_error& e) {
            EXPECT_NE(std::string(e.what()).find(part), std::string::npos) << e.what();
        }
    };
    refuses("", "ends");
    refuses("P6\n", "not an lpmbake-image stream");
    refuses("lpmbake-image 1\nwidth 2\nheight 1\nfloats 5\n", "5 floats for a 2x1");
    refuses("lpmbake-image 1\nwidth 65536\nheight 65536\nfloats 12884901888\n", "floats for a 65536x65536");
    refuses("lpmbake-image 1\nwidth 1\nheight 1\nfloats 3\n" + std::string(8, '\0'), "4 bytes early");
    refuses("lpmbake-image 1\nwidth 1\nbogus 1\n", "unknown header line 'bogus'");
}

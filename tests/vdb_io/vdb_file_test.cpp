// vdb_io/vdb_file: the layout walk accepts every valid way OpenVDB stores a grid, and
// refuses corrupt chunk lengths before OpenVDB reads them (a fuzzing finding: a stored
// chunk longer than its buffer overflowed the heap inside OpenVDB's Blosc reader).
#include "vdb_io/vdb_file.h"

#include <gtest/gtest.h>

#include <cstring>
#include <fstream>

#include "test_helpers.h"
#include "vdb_io/io_error.h"

using namespace lpm;

namespace {

/// A float grid whose leaves exercise every mask-compression case: active values,
/// inactive background, inactive -background and inactive non-background values.
openvdb::FloatGrid::Ptr mixedFloatGrid() {
    auto g = openvdb::FloatGrid::create(0.5f);
    g->setName("f");
    auto acc = g->getAccessor();
    for (int i = 0; i < 40; ++i)
        for (int j = 0; j < 20; ++j) acc.setValue(openvdb::Coord(i, j, (i * 7 + j * 3) % 30), float(i + j) * 0.25f);
    acc.setValueOff(openvdb::Coord(1, 1, 1), 7.f);              // one non-background inactive value
    acc.setValueOff(openvdb::Coord(9, 0, 0), -0.5f);            // -background
    acc.setValueOff(openvdb::Coord(17, 2, 5), 3.f);             // a second inactive value
    acc.setValueOff(openvdb::Coord(18, 2, 5), -9.f);            // and a third (no mask compression)
    g->tree().addTile(1, openvdb::Coord(64, 0, 0), 2.f, true);  // an active tile
    return g;
}

template <typename GridT>
double checksum(const GridT& g) {
    double s = 0.0;
    for (auto it = g.tree().cbeginValueAll(); it; ++it) {
        const auto v = *it;
        if constexpr (std::is_arithmetic_v<std::decay_t<decltype(v)>>) s += double(v) * (it.isValueOn() ? 3.0 : 1.0);
        else s += double(v[0] + 2 * v[1] + 3 * v[2]) * (it.isValueOn() ? 3.0 : 1.0);
    }
    return s;
}

/// `good` with `width` bytes at `at` replaced by the low bytes of `value`.
std::string patched(const std::string& good, size_t at, std::int64_t value, size_t width) {
    std::string b = good;
    std::memcpy(&b[at], &value, width);
    return b;
}

struct Corruption {
    std::string name, bytes;
    std::vector<std::string> expect;  ///< parts of the one-line error (the path is added)
};

/// Writes each corrupted file and expects `read(path)` to refuse it with an InputError
/// naming the file and every expected part.
template <typename Read>
void expectEachRefused(const std::string& dir, const std::vector<Corruption>& cases, Read read) {
    for (const Corruption& c : cases) {
        SCOPED_TRACE(c.name);
        const std::string path = dir + "/" + c.name + ".vdb";
        lpmtest::writeBytes(path, c.bytes);
        std::vector<std::string> expect = c.expect;
        expect.push_back(path);
        lpmtest::expectThrowWith<InputError>([&] { read(path); }, expect);
    }
}

}  // namespace

TEST(VdbFile, EveryCompressionHalfAndValueTypeReadsBack) {
    initOpenVdb();
    const std::string dir = lpmtest::scratchDir();
    using openvdb::io::COMPRESS_ACTIVE_MASK;
    using openvdb::io::COMPRESS_BLOSC;
    using openvdb::io::COMPRESS_NONE;
    using openvdb::io::COMPRESS_ZIP;
    for (std::uint32_t comp :
         std::vector<std::uint32_t>{COMPRESS_NONE, COMPRESS_ZIP, COMPRESS_BLOSC, COMPRESS_ACTIVE_MASK,
                                    COMPRESS_ZIP | COMPRESS_ACTIVE_MASK, COMPRESS_BLOSC | COMPRESS_ACTIVE_MASK})
    {
        for (bool halfFloats : {false, true}) {
            SCOPED_TRACE("compression " + std::to_string(comp) + (halfFloats ? ", half" : ""));
            auto f = mixedFloatGrid();
            auto v = openvdb::Vec3SGrid::create(openvdb::Vec3s(0.f));
            v->setName("v");
            v->tree().setValue(openvdb::Coord(3, 4, 5), openvdb::Vec3s(1.f, 2.f, 3.f));
            v->tree().setValue(openvdb::Coord(300, -4, 5), openvdb::Vec3s(-1.f, 0.5f, 8.f));
            auto d = openvdb::DoubleGrid::create(1.0);
            d->setName("d");
            d->tree().setValue(openvdb::Coord(-20, 4, 5), 4.0);
            auto n = openvdb::Int32Grid::create(0);
            n->setName("n");
            n->tree().setValue(openvdb::Coord(0, 0, 0), 42);
            n->tree().setValueOff(openvdb::Coord(1, 0, 0), 5);
            for (auto& g : openvdb::GridPtrVec{f, v, d, n}) g->setSaveFloatAsHalf(halfFloats);
            const std::string path = dir + "/c" + std::to_string(comp) + (halfFloats ? "h" : "") + ".vdb";
            openvdb::io::File out(path);
            out.setCompression(comp);
            out.write(openvdb::GridPtrVec{f, v, d, n});
            out.close();

            VdbFile file(path);
            ASSERT_EQ(file.gridMetadata()->size(), 4u);
            auto rf = openvdb::gridPtrCast<openvdb::FloatGrid>(file.readGrid("f"));
            auto rv = openvdb::gridPtrCast<openvdb::Vec3SGrid>(file.readGrid("v"));
            auto rd = openvdb::gridPtrCast<openvdb::DoubleGrid>(file.readGrid("d"));
            auto rn = openvdb::gridPtrCast<openvdb::Int32Grid>(file.readGrid("n"));
            ASSERT_TRUE(rf && rv && rd && rn);
            EXPECT_EQ(rf->activeVoxelCount(), f->activeVoxelCount());
            // Halves of these values are exact (small multiples of 1/4).
            EXPECT_DOUBLE_EQ(checksum(*rf), checksum(*f));
            EXPECT_DOUBLE_EQ(checksum(*rv), checksum(*v));
            EXPECT_DOUBLE_EQ(checksum(*rd), checksum(*d));
            EXPECT_DOUBLE_EQ(checksum(*rn), checksum(*n));
            EXPECT_EQ(file.readAllGrids().size(), 4u);
        }
    }
}

// Every length and offset of the header, grid list and grid metadata is checked before
// OpenVDB reads it. Each corrupted field of a real file is named without OpenVDB ever
// allocating what the field asks for.
TEST(VdbFile, LayoutCheckNamesEachCorruptField) {
    const std::string dir = lpmtest::scratchDir();
    const std::string good = lpmtest::readBytes(lpmtest::dataPath("vdb/torus01.vdb"));
    // The grid descriptor: name, type "Tree_float_5_4_3", empty instance parent, then the
    // grid, block and end byte offsets.
    const size_t type = good.find("Tree_float_5_4_3");
    ASSERT_NE(type, std::string::npos);
    const size_t offsets = type + 16 + 4;
    std::int64_t gridPos = 0;
    std::memcpy(&gridPos, good.data() + offsets, 8);
    ASSERT_GT(gridPos, 0);
    const std::vector<Corruption> cases = {
        {"empty", "", {"the file is empty"}},
        {"text", "this is a text file, not a volume\n", {"not an OpenVDB file"}},
        // The file-metadata count (right after the 57-byte header) says 4 billion entries.
        {"meta_count", patched(good, 57, 0xFFFFFFFFu, 4), {"corrupt", "the file metadata"}},
        // The grid name's length says 2 GB.
        {"name_length", patched(good, type - 4 - 17 - 4, 0x7FFFFFFFu, 4), {"corrupt", "a grid name", "2147483647"}},
        // The end offset lies past the end of the file; the block offset before the grid's.
        {"end_offset",
         patched(good, offsets + 16, std::uint64_t(good.size()) + 1, 8),
         {"truncated", "voxel_fog_density"}},
        {"block_offset", patched(good, offsets + 8, 1, 8), {"corrupt", "byte offsets"}},
        // The grid's first metadata name length (after its compression flags and the
        // metadata count) runs past the grid's metadata part.
        {"grid_meta",
         patched(good, size_t(gridPos) + 8, 0x00FFFFFFu, 4),
         {"corrupt", "the metadata of grid 'voxel_fog_density'", "past the end of its part"}},
        // The grid's first metadata entry is '_bifrost_volume_index' (int32): its byte count
        // must be 4, since OpenVDB reads 4 bytes whatever it says.
        {"typed_meta",
         patched(good, size_t(gridPos) + 4 + 4 + 4 + 21 + 4 + 5, 1000, 4),
         {"corrupt", "'_bifrost_volume_index' (int32)", "says 1000 bytes; the type has 4"}},
        // Layouts the walk does not know are refused by name: a streamed file (no grid
        // offsets: byte 20) and a pre-3.0 format version (bytes 8-11).
        {"streamed", patched(good, 20, 0, 1), {"streamed VDB"}},
        {"old_format", patched(good, 8, 220, 4), {"file format 220", "re-save"}},
    };
    expectEachRefused(dir, cases, [](const std::string& path) {
        VdbFile file(path);
        file.gridMetadata();
        file.readGrid("voxel_fog_density");
    });
    // The untouched file still reads.
    EXPECT_NO_THROW(VdbFile(lpmtest::dataPath("vdb/torus01.vdb")).readGrid("voxel_fog_density"));
}

// One leaf of 512 active floats, Blosc-compressed: the grid's data part (from the
// descriptor's block offset) is the leaf's value mask (64 bytes), its compression flag
// (1 byte), then the chunk: a 64-bit length and the Blosc buffer (16-byte header whose
// last word is the compressed size). Each corrupted field is refused, naming the grid.
TEST(VdbFile, CorruptChunkLengthsAreRefusedBeforeOpenVdbReadsThem) {
    initOpenVdb();
    const std::string dir = lpmtest::scratchDir();
    auto g = openvdb::FloatGrid::create(0.f);
    g->setName("density");
    for (int i = 0; i < 512; ++i) g->tree().setValue(openvdb::Coord(i & 7, (i >> 3) & 7, i >> 6), float(i % 13) + 0.5f);
    const std::string goodPath = dir + "/good.vdb";
    openvdb::io::File out(goodPath);
    out.setCompression(openvdb::io::COMPRESS_BLOSC | openvdb::io::COMPRESS_ACTIVE_MASK);
    out.write(openvdb::GridPtrVec{g});
    out.close();
    const std::string good = lpmtest::readBytes(goodPath);
    const size_t type = good.find("Tree_float_5_4_3");
    ASSERT_NE(type, std::string::npos);
    std::int64_t blockPos = 0;
    std::memcpy(&blockPos, good.data() + type + 16 + 4 + 8, 8);
    const size_t lengthAt = size_t(blockPos) + 64 + 1;
    std::int64_t length = 0;
    std::memcpy(&length, good.data() + lengthAt, 8);
    ASSERT_GT(length, 16) << "expected a Blosc-compressed chunk";
    std::uint32_t cbytes = 0;
    std::memcpy(&cbytes, good.data() + lengthAt + 8 + 12, 4);
    ASSERT_EQ(std::int64_t(cbytes), length);
    EXPECT_EQ(VdbFile(goodPath).readGrid("density")->activeVoxelCount(), 512);

    const std::vector<Corruption> cases = {
        // Stored (negative length) but longer than the leaf's 2048 bytes: OpenVDB 10 reads
        // it into the 2048-byte buffer first and checks afterwards (a heap overflow).
        {"stored_too_long",
         patched(good, lengthAt, -2048 - 4096, 8),
         {"grid 'density'", "stores 6144 bytes where 2048 are expected"}},
        // A compressed length far beyond the file: OpenVDB allocates it.
        {"huge_length",
         patched(good, lengthAt, std::int64_t(1) << 40, 8),
         {"grid 'density'", "compressed chunk", "needs 1099511627776 bytes"}},
        // Blosc's own header disagrees with the chunk length: Blosc would read past it.
        {"blosc_header",
         patched(good, lengthAt + 8 + 12, std::int64_t(cbytes) + 5000, 4),
         {"grid 'density'", "Blosc chunk", "says it holds"}},
    };
    expectEachRefused(dir, cases, [](const std::string& path) {
        VdbFile file(path);  // the header and grid list are intact
        file.readGrid("density");
    });
}

TEST(VdbFile, UnsupportedTreeTypeIsNamedNotRead) {
    initOpenVdb();
    const std::string dir = lpmtest::scratchDir();
    auto b = openvdb::BoolGrid::create(false);
    b->setName("mask");
    b->tree().setValue(openvdb::Coord(1, 2, 3), true);
    lpmtest::writeVdb(dir + "/bool.vdb", {b});
    VdbFile file(dir + "/bool.vdb");
    lpmtest::expectThrowWith<InputError>([&] { file.readGrid("mask"); }, {"mask", "Tree_bool_5_4_3", "does not read"});
}

// Half or full floats is decided by the grid's is_saved_as_half_float metadata, read as
// MetaMap::readMeta reads it, whatever its type: a fuzzed file retyped it from "bool" to
// an unknown type (which reads as true), and OpenVDB then read full-float chunks as half
// floats (a Blosc-stored chunk of 8182 bytes into a 20-byte buffer under ASan). The walk
// must decide as OpenVDB does, and a grid whose parts then end in the wrong place is
// refused, in every compression. (Genuine half-float files read back in the test above.)
TEST(VdbFile, HalfFloatFlagIsDecidedAsOpenVdbDecidesIt) {
    initOpenVdb();
    const std::string dir = lpmtest::scratchDir();
    const std::string flag = std::string("is_saved_as_half_float") + std::string("\x04\0\0\0bool\x01\0\0\0", 12);
    for (const std::uint32_t comp : std::vector<std::uint32_t>{
             openvdb::io::COMPRESS_NONE, openvdb::io::COMPRESS_ZIP | openvdb::io::COMPRESS_ACTIVE_MASK,
             openvdb::io::COMPRESS_BLOSC | openvdb::io::COMPRESS_ACTIVE_MASK})
    {
        SCOPED_TRACE("compression " + std::to_string(comp));
        const openvdb::FloatGrid::Ptr g = mixedFloatGrid();
        g->setSaveFloatAsHalf(false);  // writes the metadata entry, as Houdini's files have it
        const std::string path = dir + "/c" + std::to_string(comp) + ".vdb";
        openvdb::io::File out(path);
        out.setCompression(comp);
        out.write(openvdb::GridPtrVec{g});
        out.close();
        EXPECT_DOUBLE_EQ(checksum(*openvdb::gridPtrCast<openvdb::FloatGrid>(VdbFile(path).readGrid("f"))),
                         checksum(*g));

        std::string bytes = lpmtest::readBytes(path);
        const size_t at = bytes.find(flag);
        ASSERT_NE(at, std::string::npos);
        ASSERT_EQ(bytes[at + flag.size()], '\0') << "saved as full floats";
        bytes.replace(at + 26, 4, "doub");  // an unknown type of 1 byte (0): reads as true
        const std::string bad = dir + "/retyped" + std::to_string(comp) + ".vdb";
        lpmtest::writeBytes(bad, bytes);
        lpmtest::expectThrowWith<InputError>([&] { VdbFile(bad).readGrid("f"); }, {bad, "grid 'f'", "corrupt"});
    }
    // The fuzzing input itself (densityAndHeat.vdb retyped and crossed over).
    const std::string found = std::string(LPM_SOURCE_DIR) + "/tests/fuzz/regressions/vdb_half_flag_overflow.vdb";
    lpmtest::expectThrowWith<InputError>([&] { VdbFile(found).readGrid("density"); }, {"grid 'density'", "corrupt"});
}

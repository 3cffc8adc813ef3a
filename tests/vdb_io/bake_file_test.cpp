// vdb_io/bake_file: output layout (names, classes, topology, values), metadata, half
// storage, reading back and validation.
#include "vdb_io/bake_file.h"
#include "vdb_io/bake_schema.h"

#include <gtest/gtest.h>

#include "core/sh.h"
#include "core/sh_rows.h"
#include "test_helpers.h"
#include "vdb_io/io_error.h"

using namespace lpm;

namespace {

struct Fixture {
    openvdb::FloatGrid::Ptr density;
    std::vector<float> sh;
    DenseBake bake;
};

/// A sparse density (two separate blobs) and a dense result with a distinct value per
/// (voxel, coefficient, channel), laid out like the solver's.
Fixture makeFixture(int coeffs, float scale = 1.f) {
    Fixture f;
    f.density = lpmtest::cubeGrid(3, 1.f, 0.5);
    f.density->tree().setValue(openvdb::Coord(6, 1, 1), 2.f);
    f.density->transform().postTranslate(openvdb::Vec3d(1, 2, 3));
    f.bake.blockMin = openvdb::Coord(-1);
    f.bake.nx = 9;
    f.bake.ny = 5;
    f.bake.nz = 5;
    f.bake.coeffs = coeffs;
    f.sh.resize(size_t(9 * 5 * 5) * coeffs * 3);
    for (size_t i = 0; i < f.sh.size(); ++i) f.sh[i] = scale * (float(i % 1000) - 300.f) / 100.f;
    f.bake.sh = f.sh.data();
    return f;
}

const float* denseAt(const Fixture& f, const openvdb::Coord& c, int k) {
    const openvdb::Coord d = c - f.bake.blockMin;
    const size_t i = size_t(d.x()) + size_t(f.bake.nx) * (size_t(d.y()) + size_t(f.bake.ny) * d.z());
    return &f.sh[(i * f.bake.coeffs + k) * 3];
}

/// The smallest valid metadata: every key a shader needs (bake_schema.h), with sh_order.
openvdb::MetaMap shaderMetadata(int shOrder) {
    openvdb::MetaMap meta;
    for (const MetaKey& k : bakeSchema()) {
        if (!k.required || !k.shader) continue;
        switch (k.type) {
            case MetaType::String:
                putString(meta, k, "");
                break;
            case MetaType::Double:
                putDouble(meta, k, 1.0);
                break;
            case MetaType::Int:
                putInt(meta, k, 0);
                break;
            case MetaType::Int64:
                putInt64(meta, k, 0);
                break;
            case MetaType::Bool:
                putBool(meta, k, false);
                break;
            case MetaType::Vec3d:
                putVec3(meta, k, 0.5, 0.5, 0.5);
                break;
            case MetaType::Vec3i:
                putVec3i(meta, k, 0, 0, 0);
                break;
        }
    }
    putInt(meta, bakekey::formatVersion, kBakeFormatVersion);
    putInt(meta, bakekey::shOrder, shOrder);
    return meta;
}

}  // namespace

TEST(BakeFile, LayoutTopologyAndValues) {
    const std::string dir = lpmtest::scratchDir();
    Fixture f = makeFixture(9);
    openvdb::MetaMap meta = shaderMetadata(2);
    putString(meta, bakekey::densityGrid, "density");
    BakeWriteOptions o;
    o.path = dir + "/bake.vdb";
    const BakeWriteReport rep = writeBake(*f.density, f.bake, meta, o);
    // The lighting grids: the density's voxels and the one-voxel shell around them (all
    // inside the 9x5x5 block, so none is dropped).
    EXPECT_EQ(rep.shellDropped, 0u);
    EXPECT_GT(rep.shellVoxels, 0u);
    EXPECT_EQ(rep.voxelsWritten, f.density->activeVoxelCount() + rep.shellVoxels);
    EXPECT_TRUE(rep.warnings.empty());

    const BakeFile b = readBakeFile(o.path);
    EXPECT_TRUE(validateBake(b).empty());
    ASSERT_EQ(b.sh.size(), 9u);
    ASSERT_TRUE(b.scatter && b.density);
    EXPECT_FALSE(b.emission);
    for (int k = 0; k < 9; ++k) {
        const auto& g = b.sh[k];
        EXPECT_EQ(g->getName(), "sh_" + std::to_string(k));
        EXPECT_EQ(g->getGridClass(), openvdb::GRID_UNKNOWN);
        EXPECT_EQ(g->getVectorType(), openvdb::VEC_INVARIANT);
        EXPECT_TRUE(g->transform() == f.density->transform());
        lpmtest::expectLightingTopology(*g, *f.density);
        for (auto it = g->cbeginValueOn(); it; ++it) {  // shell voxels hold the block's values too
            const openvdb::Vec3s v = *it;
            const float* e = denseAt(f, it.getCoord(), k);
            ASSERT_EQ(v, openvdb::Vec3s(e[0], e[1], e[2])) << "sh_" << k << " at " << it.getCoord();
        }
    }
    EXPECT_EQ(b.scatter->getGridClass(), openvdb::GRID_FOG_VOLUME);
    const openvdb::Coord c(6, 1, 1);
    const float* e0 = denseAt(f, c, 0);
    EXPECT_FLOAT_EQ(b.scatter->tree().getValue(c).x(), e0[0] * float(kY00));
    EXPECT_FLOAT_EQ(b.density->tree().getValue(c), 2.f);
    EXPECT_TRUE(b.density->tree().hasSameTopology(f.density->tree())) << "the density copy keeps its topology";
    lpmtest::expectLightingTopology(*b.scatter, *f.density);
    EXPECT_EQ(b.meta->metaValue<std::string>("lpm:density_grid"), "density");
    EXPECT_EQ(b.shOrder, 2);
}

// The writer reads SH through a row map (DenseBake::shRow: the solver's rows for the
// written voxels) and frees the rows it was handed (releaseSh) once its grids hold them:
// the file is the one written from the same values by voxel.
TEST(BakeFile, ShRowsWriteTheGridsOfTheValuesByVoxel) {
    const std::string dir = lpmtest::scratchDir();
    const int coeffs = 4;
    Fixture byVoxel = makeFixture(coeffs);
    const size_t voxels = byVoxel.sh.size() / (coeffs * 3), width = coeffs * 3;
    // Rows in reverse voxel order; every third voxel without one (S = 0 there).
    std::vector<std::uint32_t> rowOf(voxels, ShRows::kNone);
    std::vector<float> rows;
    for (size_t v = voxels; v-- > 0;) {
        if (v % 3 == 0) continue;
        rowOf[v] = std::uint32_t(rows.size() / width);
        rows.insert(rows.end(), byVoxel.sh.begin() + long(v * width), byVoxel.sh.begin() + long((v + 1) * width));
    }
    for (size_t v = 0; v < voxels; v += 3) std::fill_n(byVoxel.sh.begin() + long(v * width), width, 0.0f);
    Fixture byRow = makeFixture(coeffs);
    byRow.bake.sh = rows.data();
    byRow.bake.shRow = rowOf.data();
    byRow.bake.releaseSh = &rows;
    const openvdb::MetaMap meta = shaderMetadata(1);
    BakeWriteOptions o;
    o.path = dir + "/by_voxel.vdb";
    writeBake(*byVoxel.density, byVoxel.bake, meta, o);
    o.path = dir + "/by_row.vdb";
    writeBake(*byRow.density, byRow.bake, meta, o);
    EXPECT_TRUE(rows.empty() && rows.capacity() == 0) << "the rows are freed";

    const BakeFile a = readBakeFile(dir + "/by_voxel.vdb"), b = readBakeFile(dir + "/by_row.vdb");
    ASSERT_EQ(a.sh.size(), size_t(coeffs));
    ASSERT_EQ(b.sh.size(), size_t(coeffs));
    size_t zeros = 0;
    for (int k = 0; k < coeffs; ++k) {
        ASSERT_TRUE(a.sh[k]->tree().hasSameTopology(b.sh[k]->tree()));
        for (auto it = a.sh[k]->cbeginValueOn(); it; ++it) {
            ASSERT_EQ(*it, b.sh[k]->tree().getValue(it.getCoord())) << "sh_" << k << " at " << it.getCoord();
            zeros += *it == openvdb::Vec3s(0.0f);
        }
    }
    EXPECT_GT(zeros, 0u) << "voxels without a row are written as 0";
    ASSERT_TRUE(a.scatter && b.scatter);
    for (auto it = a.scatter->cbeginValueOn(); it; ++it)
        ASSERT_EQ(*it, b.scatter->tree().getValue(it.getCoord())) << "scatter at " << it.getCoord();
}

TEST(BakeFile, HalfStorageWarnsAboveHalfMax) {
    const std::string dir = lpmtest::scratchDir();
    Fixture f = makeFixture(1, 1e5f);  // values up to ~7e5
    openvdb::MetaMap meta;
    BakeWriteOptions o;
    o.path = dir + "/half.vdb";
    o.half = true;
    BakeWriteReport rep = writeBake(*f.density, f.bake, meta, o);
    ASSERT_EQ(rep.warnings.size(), 1u);
    EXPECT_NE(rep.warnings[0].find("65504"), std::string::npos);
    Fixture small = makeFixture(1, 1.f);
    o.path = dir + "/half_ok.vdb";
    rep = writeBake(*small.density, small.bake, meta, o);
    EXPECT_TRUE(rep.warnings.empty());
    // Same data as float32: the half file is smaller and reads back within half precision.
    o.half = false;
    o.path = dir + "/float.vdb";
    writeBake(*small.density, small.bake, meta, o);
    EXPECT_LT(std::filesystem::file_size(dir + "/half_ok.vdb"), std::filesystem::file_size(o.path));
    const BakeFile h = readBakeFile(dir + "/half_ok.vdb"), fl = readBakeFile(o.path);
    for (auto it = fl.sh[0]->cbeginValueOn(); it; ++it)
        for (int c = 0; c < 3; ++c)
            ASSERT_NEAR(h.sh[0]->tree().getValue(it.getCoord())[c], (*it)[c], 1e-3 * std::fabs((*it)[c]) + 1e-6);
}

TEST(BakeFile, EmptyBakeAndNoDensity) {
    const std::string dir = lpmtest::scratchDir();
    auto empty = openvdb::FloatGrid::create(0.f);
    DenseBake db;  // sh == nullptr: no result
    db.coeffs = 1;
    openvdb::MetaMap meta = shaderMetadata(0);
    BakeWriteOptions o;
    o.path = dir + "/empty.vdb";
    o.writeDensity = false;
    writeBake(*empty, db, meta, o);
    const BakeFile b = readBakeFile(o.path);
    EXPECT_TRUE(validateBake(b).empty());
    EXPECT_EQ(b.sh.size(), 1u);
    EXPECT_EQ(b.sh[0]->activeVoxelCount(), 0u);
    EXPECT_FALSE(b.density);
}

// The shell is written only where the solver computed S: a shell voxel in an unallocated
// 8^3 tile of the block (no solved value) is left inactive and reported, not extrapolated.
TEST(BakeFile, ShellOnlyWhereSolved) {
    const std::string dir = lpmtest::scratchDir();
    initOpenVdb();
    auto density = openvdb::FloatGrid::create(0.f);
    density->tree().setValue(openvdb::Coord(6, 2, 2), 1.f);  // block voxel (7, 3, 3): tile 0's last x
    Medium layout;
    const std::vector<std::uint8_t> tiles = {1, 0};  // 16x8x8 block: tile x = 1 not stored
    layout.allocate(16, 8, 8, &tiles);
    ASSERT_TRUE(layout.sparse());
    std::vector<float> sh(layout.voxelCount() * 3, 0.5f);
    DenseBake b;
    b.blockMin = openvdb::Coord(-1);
    b.nx = 16;
    b.ny = b.nz = 8;
    b.sh = sh.data();
    b.layout = &layout;
    BakeWriteOptions o;
    o.path = dir + "/b.vdb";
    const BakeWriteReport rep = writeBake(*density, b, openvdb::MetaMap(), o);
    EXPECT_EQ(rep.shellDropped, 9u) << "the 3x3 shell voxels at x = 7 lie in the missing tile";
    EXPECT_EQ(rep.shellVoxels, 26u - 9u);
    ASSERT_EQ(rep.warnings.size(), 1u);
    EXPECT_NE(rep.warnings[0].find("no solved S"), std::string::npos) << rep.warnings[0];
    const BakeFile f = readBakeFile(o.path);
    EXPECT_EQ(f.sh[0]->activeVoxelCount(), 18u);
    EXPECT_FALSE(f.sh[0]->tree().isValueOn(openvdb::Coord(7, 2, 2)));
    EXPECT_TRUE(f.sh[0]->tree().isValueOn(openvdb::Coord(5, 1, 1)));
    EXPECT_EQ(f.sh[0]->tree().getValue(openvdb::Coord(5, 1, 1)), openvdb::Vec3s(0.5f));
}

TEST(BakeFile, NeverOverwritesInputAndValidatesForeignFiles) {
    const std::string dir = lpmtest::scratchDir();
    Fixture f = makeFixture(1);
    const std::string in = dir + "/in.vdb";
    lpmtest::writeVdb(in, {f.density});
    const auto before = std::filesystem::file_size(in);
    BakeWriteOptions o;
    o.path = in;
    o.inputs = {in};
    EXPECT_THROW(writeBake(*f.density, f.bake, openvdb::MetaMap(), o), OutputError);
    EXPECT_EQ(std::filesystem::file_size(in), before);
    const BakeFile b = readBakeFile(in);  // a plain density file: readable, not a bake
    const auto why = validateBake(b);
    EXPECT_FALSE(why.empty());
    EXPECT_THROW(readBakeFile(dir + "/missing.vdb"), InputError);
}

// Content digest of a bake (vdb_io/bake_digest.h): sees every value, the transform and
// the settings; ignores timings and the command line.
#include <gtest/gtest.h>

#include "test_helpers.h"
#include "vdb_io/bake_digest.h"
#include "vdb_io/io_error.h"

using namespace lpm;

namespace {

BakeFile smallBake() {
    BakeFile f;
    f.path = "test.vdb";
    auto density = lpmtest::cubeGrid(4, 0.5f);
    auto sh = openvdb::Vec3SGrid::create(openvdb::Vec3s(0.f));
    sh->setName("sh_0");
    sh->tree().topologyUnion(density->tree());
    sh->tree().setValue(openvdb::Coord(1, 2, 3), openvdb::Vec3s(1.f, 2.f, 3.f));
    f.grids = {density, sh};
    f.meta = std::make_shared<openvdb::MetaMap>();
    f.meta->insertMeta("lpm:format_version", openvdb::Int32Metadata(3));
    f.meta->insertMeta("lpm:albedo", openvdb::Vec3DMetadata(openvdb::Vec3d(0.9)));
    f.meta->insertMeta("lpm:time_solve_s", openvdb::DoubleMetadata(1.5));
    f.meta->insertMeta("lpm:timings", openvdb::StringMetadata("solve 1.5 s"));
    f.meta->insertMeta("lpm:command_line", openvdb::StringMetadata("lpmbake a.vdb"));
    return f;
}

}  // namespace

TEST(BakeDigest, IgnoresTimingsAndCommandLine) {
    BakeFile a = smallBake(), b = smallBake();
    b.meta->removeMeta("lpm:time_solve_s");
    b.meta->insertMeta("lpm:time_solve_s", openvdb::DoubleMetadata(99.0));
    b.meta->removeMeta("lpm:command_line");
    b.meta->insertMeta("lpm:command_line", openvdb::StringMetadata("lpmbake a.####.vdb --frames 1-9"));
    b.meta->removeMeta("lpm:timings");
    EXPECT_EQ(bakeContentDigest(a), bakeContentDigest(b));
    EXPECT_EQ(hex64(bakeContentDigest(a)).size(), 16u);
}

TEST(BakeDigest, SeesValuesTopologyTransformAndSettings) {
    const std::uint64_t base = bakeContentDigest(smallBake());
    {
        BakeFile f = smallBake();  // one voxel's last bit
        auto sh = openvdb::gridPtrCast<openvdb::Vec3SGrid>(f.grids[1]);
        sh->tree().setValue(openvdb::Coord(1, 2, 3), openvdb::Vec3s(1.f, 2.f, std::nextafter(3.f, 4.f)));
        EXPECT_NE(bakeContentDigest(f), base);
    }
    {
        BakeFile f = smallBake();  // one more active voxel of value 0
        openvdb::gridPtrCast<openvdb::Vec3SGrid>(f.grids[1])->tree().setValueOn(openvdb::Coord(9, 9, 9));
        EXPECT_NE(bakeContentDigest(f), base);
    }
    {
        BakeFile f = smallBake();  // the grids placed elsewhere
        for (auto& g : f.grids) g->transform().postTranslate(openvdb::Vec3d(0.5, 0, 0));
        EXPECT_NE(bakeContentDigest(f), base);
    }
    {
        BakeFile f = smallBake();  // another setting
        f.meta->removeMeta("lpm:albedo");
        f.meta->insertMeta("lpm:albedo", openvdb::Vec3DMetadata(openvdb::Vec3d(0.8)));
        EXPECT_NE(bakeContentDigest(f), base);
    }
}

TEST(BakeDigest, ForeignGridTypeIsAnInputError) {
    BakeFile f = smallBake();
    auto ints = openvdb::Int32Grid::create(0);
    ints->setName("obstacles");
    f.grids.push_back(ints);
    EXPECT_THROW(bakeContentDigest(f), InputError);
}

// Constant-free renderer grids: extinction = density * scale and source = sigma_s * scatter +
// sigma_a * L_e on the density's active voxels (tiles voxelised), nothing elsewhere.
#include "vdb_io/renderer_grids.h"

#include <gtest/gtest.h>

using namespace lpm;

TEST(RendererGrids, ExtinctionAndSourceFromTheConstants) {
    openvdb::initialize();
    auto density = openvdb::FloatGrid::create(0.f);
    density->setTransform(openvdb::math::Transform::createLinearTransform(0.5));
    density->tree().setValue(openvdb::Coord(1, 2, 3), 2.f);
    density->tree().addTile(1, openvdb::Coord(16, 0, 0), 0.5f, true);  // an 8^3 tile
    auto scatter = openvdb::Vec3SGrid::create(openvdb::Vec3s(0.f));
    scatter->setTransform(density->transform().copy());
    scatter->tree().setValue(openvdb::Coord(1, 2, 3), openvdb::Vec3s(1, 2, 4));
    scatter->tree().setValue(openvdb::Coord(17, 1, 1), openvdb::Vec3s(8, 8, 8));
    scatter->tree().setValue(openvdb::Coord(40, 40, 40), openvdb::Vec3s(5, 5, 5));  // a shell voxel
    auto emission = scatter->deepCopy();
    emission->tree().setValue(openvdb::Coord(1, 2, 3), openvdb::Vec3s(10, 0, 0));
    const RGB albedo(0.5f, 0.75f, 1.0f);
    const RendererGrids r = makeRendererGrids(*density, *scatter, emission.get(), 3.0, albedo);
    EXPECT_EQ(r.extinction->activeVoxelCount(), 1 + 512);
    EXPECT_EQ(r.source->activeVoxelCount(), 1 + 512 + 1) << "and scatter's voxels";
    EXPECT_TRUE(r.source->tree().isValueOn(openvdb::Coord(40, 40, 40)));
    EXPECT_EQ(r.source->tree().getValue(openvdb::Coord(40, 40, 40)), openvdb::Vec3s(0.f)) << "no density: 0";
    EXPECT_EQ(r.extinction->transform(), density->transform());
    EXPECT_FLOAT_EQ(r.extinction->tree().getValue(openvdb::Coord(1, 2, 3)), 6.f);
    EXPECT_FLOAT_EQ(r.extinction->tree().getValue(openvdb::Coord(20, 5, 5)), 1.5f);
    const openvdb::Vec3s s = r.source->tree().getValue(openvdb::Coord(1, 2, 3));
    EXPECT_FLOAT_EQ(s[0], 6 * (0.5f * 1 + 0.5f * 10));  // sigma_s S + sigma_a L_e
    EXPECT_FLOAT_EQ(s[1], 6 * (0.75f * 2));
    EXPECT_FLOAT_EQ(s[2], 6 * (1.0f * 4));
    EXPECT_FLOAT_EQ(r.source->tree().getValue(openvdb::Coord(17, 1, 1))[1], 1.5f * 0.75f * 8 + 1.5f * 0.25f * 8);
    EXPECT_FALSE(r.source->tree().isValueOn(openvdb::Coord(0, 0, 0)));
    EXPECT_EQ(r.extinction->getName(), "extinction");
    EXPECT_EQ(r.source->getName(), "source");
}

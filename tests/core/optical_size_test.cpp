// The optical size of a medium's thickest region (core/optical_size.h): exact on uniform
// boxes (a cube gives its optical side, a box its three row depths combined), voxel edges
// per axis, the thickest region winning over a wide thin one, rows through the gaps of a
// sparse block, nothing for an empty medium, and the same bits for any thread count.
#include "core/optical_size.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "core/parallel.h"
#include "test_scenes.h"

using namespace lpm;

namespace {

Medium uniformBox(int nx, int ny, int nz, float sigma, Vec3 edge = {1, 1, 1}) {
    Medium m;
    m.voxelSize = edge;
    m.allocate(nx, ny, nz);
    for (float& s : m.sigmaT) s = sigma;
    return m;
}

double boxSize(double tx, double ty, double tz) {
    return std::sqrt(3.0 / (1 / (tx * tx) + 1 / (ty * ty) + 1 / (tz * tz)));
}

}  // namespace

TEST(OpticalSize, CubeGivesItsOpticalSide) { EXPECT_NEAR(opticalSize(uniformBox(24, 24, 24, 0.5f)), 12.0, 1e-5); }

TEST(OpticalSize, BoxCombinesItsThreeRowDepths) {
    EXPECT_NEAR(opticalSize(uniformBox(4, 8, 16, 0.5f)), boxSize(2, 4, 8), 1e-6);
    // Row depths count each axis's voxel edge: x rows twice as deep with edges of 2.
    EXPECT_NEAR(opticalSize(uniformBox(4, 8, 16, 0.5f, {2, 1, 1})), boxSize(4, 4, 8), 1e-6);
}

// A thin slab across the whole block and a small dense cube in one corner: the size is
// the cube's, where light stays longest, not the slab's area or the total extinction.
TEST(OpticalSize, ThickestRegionWins) {
    Medium m = uniformBox(64, 64, 64, 0.0f);
    for (int y = 0; y < 64; ++y)
        for (int x = 0; x < 64; ++x) m.sigmaT[m.index(x, y, 40)] = 0.25f;  // rows of depth 16 across, 0.25 through
    for (int z = 0; z < 8; ++z)
        for (int y = 0; y < 8; ++y)
            for (int x = 0; x < 8; ++x) m.sigmaT[m.index(x, y, z)] = 4.0f;  // a cube of optical side 32
    EXPECT_NEAR(opticalSize(m), boxSize(32, 32, 32.25), 1e-4);              // its z rows cross the slab too
}

// Sparse storage: tiles at opposite corners of a 32^3 block share no row, so each is a
// cube of optical side 8 sigma; two tiles on one x row add their depths along x.
TEST(OpticalSize, SparseRowsPassThroughGaps) {
    const int tiles = 4;
    std::vector<std::uint8_t> active(tiles * tiles * tiles, 0);
    active[0] = active[active.size() - 1] = 1;
    Medium corners;
    corners.allocate(32, 32, 32, &active);
    for (size_t v = 0; v < corners.voxelCount(); ++v) corners.sigmaT[v] = 1.0f;
    EXPECT_NEAR(opticalSize(corners), 8.0, 1e-5);

    std::fill(active.begin(), active.end(), 0);
    active[0] = active[3] = 1;  // tiles (0, 0, 0) and (3, 0, 0)
    Medium row;
    row.allocate(32, 32, 32, &active);
    for (size_t v = 0; v < row.voxelCount(); ++v) row.sigmaT[v] = 1.0f;
    EXPECT_NEAR(opticalSize(row), boxSize(16, 8, 8), 1e-5);
}

TEST(OpticalSize, EmptyMediumHasNoSize) { EXPECT_EQ(opticalSize(uniformBox(8, 8, 8, 0.0f)), 0.0); }

TEST(OpticalSize, SameForAnyThreadCount) {
    const Medium m = lpm::test::makeVolume(lpm::test::VolumeKind::Cloud, 40, 24.0);
    double one = 0;
    {
        ThreadLimit limit(1);
        one = opticalSize(m);
    }
    EXPECT_GT(one, 0.0);
    EXPECT_EQ(opticalSize(m), one);
}

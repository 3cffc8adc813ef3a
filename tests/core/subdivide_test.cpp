// Subdivided solves (core/subdivide.h): the refined medium is the same medium, and
// averaging back inverts the split for piecewise-constant values.
#include "core/subdivide.h"

#include <gtest/gtest.h>

#include "test_scenes.h"

using namespace lpm;
using namespace lpm::test;

namespace {

Medium sparseCloud() {
    Medium dense = makeVolume(VolumeKind::Cloud, 16, 3.0);
    Medium m;
    std::vector<std::uint8_t> active = {1, 0, 1, 1, 0, 1, 1, 0};  // 2x2x2 tiles, 3 empty
    m.allocate(16, 16, 16, &active);
    m.voxelSize = dense.voxelSize;
    for (int z = 0; z < 16; ++z)
        for (int y = 0; y < 16; ++y)
            for (int x = 0; x < 16; ++x) {
                const size_t v = m.index(x, y, z);
                if (v != Medium::npos) m.sigmaT[v] = dense.sigmaT[dense.index(x, y, z)];
            }
    return m;
}

}  // namespace

TEST(Subdivide, SameMediumOnFinerVoxels) {
    const Medium m = sparseCloud();
    const Medium f = subdivided(m, 2);
    EXPECT_EQ(f.nx, 32);
    EXPECT_EQ(f.voxelSize.x, 0.5);
    EXPECT_EQ(f.storedTiles, m.storedTiles * 8);
    double mass = 0, fineMass = 0;  // optical mass sigma_t V is kept
    for (float s : m.sigmaT) mass += s * m.voxelVolume();
    for (float s : f.sigmaT) fineMass += s * f.voxelVolume();
    EXPECT_NEAR(fineMass, mass, 1e-9 * mass);
    for (int z = 0; z < 32; ++z)
        for (int y = 0; y < 32; ++y)
            for (int x = 0; x < 32; ++x) {
                const size_t c = m.index(x / 2, y / 2, z / 2), v = f.index(x, y, z);
                ASSERT_EQ(c == Medium::npos, v == Medium::npos);
                if (v != Medium::npos) {
                    ASSERT_EQ(f.sigmaT[v], m.sigmaT[c]);
                }
            }
}

TEST(Subdivide, AverageBackInvertsTheSplit) {
    const Medium m = sparseCloud();
    const Medium f = subdivided(m, 3);
    std::vector<float> fine(f.voxelCount() * 2);
    for (size_t v = 0; v < f.voxelCount(); ++v) {
        fine[v * 2] = f.sigmaT[v];
        fine[v * 2 + 1] = 2 * f.sigmaT[v] + 1;
    }
    const std::vector<float> back = averageBack(m, f, 3, fine, 2);
    ASSERT_EQ(back.size(), m.voxelCount() * 2);
    for (size_t v = 0; v < m.voxelCount(); ++v) {
        EXPECT_NEAR(back[v * 2], m.sigmaT[v], 1e-6f * (1 + m.sigmaT[v]));
        EXPECT_NEAR(back[v * 2 + 1], 2 * m.sigmaT[v] + 1, 1e-6f * (1 + m.sigmaT[v]));
    }
}

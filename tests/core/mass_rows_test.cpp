// Rows of the voxels with mass (core/mass_rows.h), and a coarse continuation whose sources
// are held by them: the same solve as by voxel, where the voxels without mass carry no
// source power.
#include "core/mass_rows.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/lpm_solve.h"
#include "core/multires.h"
#include "core/parallel.h"
#include "core/rng.h"
#include "test_scenes.h"

using namespace lpm;
using namespace lpm::test;

TEST(MassRows, RowsAreTheVoxelsWithMassInStorageOrder) {
    const Medium m = sparseBlock(5);  // 30% of its voxels without extinction, and tile padding
    const MassRows rows(m);
    ASSERT_EQ(rows.rowOf.size(), m.voxelCount());
    size_t withMass = 0;
    for (size_t v = 0; v < m.voxelCount(); ++v) {
        const bool mass = m.sigmaT[v] > 0;
        withMass += mass;
        ASSERT_EQ(rows.rowOf[v] != MassRows::kNone, mass) << v;
        if (mass) {
            ASSERT_EQ(rows.voxel[rows.rowOf[v]], v);
        }
    }
    EXPECT_EQ(rows.size(), withMass);
    EXPECT_LT(rows.size(), m.voxelCount() * 8 / 10);
    for (size_t row = 1; row < rows.size(); ++row) ASSERT_LT(rows.voxel[row - 1], rows.voxel[row]);
    // expandRows puts each row at its voxel and 0 elsewhere; gatherRows takes them back.
    const size_t width = 5;
    std::vector<float> x(rows.size() * width);
    Pcg32 rng(3, 9);
    for (float& value : x) value = float(rng.uniform()) + 0.5f;
    const std::vector<float> full = expandRows(rows, x, width);
    ASSERT_EQ(full.size(), m.voxelCount() * width);
    for (size_t v = 0; v < m.voxelCount(); ++v)
        for (size_t i = 0; i < width; ++i) {
            const float want = rows.rowOf[v] == MassRows::kNone ? 0.0f : x[size_t(rows.rowOf[v]) * width + i];
            ASSERT_EQ(full[v * width + i], want) << v;
        }
    EXPECT_TRUE(gatherRows(rows, full, width) == x);
}

namespace {

/// The coarse continuation of a two-grid solve (core/two_grid.cpp): the orders of `initial`
/// on `mc`, source iteration only, by rows when `rows` is set.
LpmResult coarseSolve(const Medium& mc, std::vector<float> initial, const MassRows* rows) {
    LpmSettings cs;
    cs.multires = 0;
    cs.deltaM = 0;
    cs.binsPerFace = 2;
    cs.directionsPerFace = 2;
    cs.krylov = false;
    cs.linearSource = 0;  // rows hold voxel-constant sources (core/two_grid.cpp)
    cs.validate();
    const SolvePlan plan = planSolve(summarizeScene(mc, Lights{}, nullptr, true), cs, maxThreads());
    return LpmSolve(mc, Lights{}, cs, plan, std::make_shared<LpmCache>(), &initial, nullptr, rows).run();
}

}  // namespace

// The coarse grid of a plume (its tiles' fringes without mass): the source sum of a solve
// by rows is that of the solve by voxel at the rows, bit for bit, and so are its passes'
// tallies; the rows hold a fraction of the voxels.
TEST(MassRows, CoarseSolveByRowsEqualsTheSolveByVoxel) {
    Medium fine = makeVolume(VolumeKind::Plume, 24, 3.0);
    fine.g = 0.6f;
    fine.albedo = RGB(0.9f, 0.85f, 0.8f);
    const Medium mc = coarsen(fine);
    const MassRows rows(mc);
    ASSERT_LT(rows.size(), mc.voxelCount() * 9 / 10);
    const size_t width = 24 * 3;  // 2x2 bins per face, RGB
    std::vector<float> initial(rows.size() * width);
    Pcg32 rng(17, 2);
    for (float& x : initial) x = float(rng.uniform());
    const LpmResult byRows = coarseSolve(mc, initial, &rows);
    const LpmResult byVoxel = coarseSolve(mc, expandRows(rows, initial, width), nullptr);
    ASSERT_GT(byVoxel.passes.size(), size_t(3));
    ASSERT_EQ(byRows.passes.size(), byVoxel.passes.size());
    for (size_t p = 0; p < byRows.passes.size(); ++p) {
        EXPECT_EQ(byRows.passes[p].scattered, byVoxel.passes[p].scattered) << p;
        EXPECT_EQ(byRows.passes[p].absorbed, byVoxel.passes[p].absorbed) << p;
    }
    ASSERT_EQ(byRows.sourceSum.size(), rows.size() * width);
    EXPECT_TRUE(byRows.sourceSum == gatherRows(rows, byVoxel.sourceSum, width));
    EXPECT_EQ(byRows.residual, byVoxel.residual);
}

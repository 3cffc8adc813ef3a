#include "core/sh_rows.h"

#include <gtest/gtest.h>

#include "core/lpm_solver.h"
#include "core/rng.h"
#include "lpm_vs_mc.h"

using namespace lpm;
using namespace lpm::test;

namespace {

Medium smallBox(int n) {
    Medium m;
    m.allocate(n, n, n);
    for (float& s : m.sigmaT) s = 1.0f;
    return m;
}

/// About half the voxels wanted, in runs of irregular length.
std::vector<std::uint8_t> someVoxels(size_t count, std::uint64_t seed) {
    Pcg32 rng(seed, 1);
    std::vector<std::uint8_t> w(count);
    for (auto& f : w) f = rng.uniform() < 0.5 ? 1 : 0;
    return w;
}

}  // namespace

TEST(ShRows, IdentityWithoutWantedVoxelsOrAtOrderZero) {
    Medium m = smallBox(4);
    const ShRows none(m, 9);
    EXPECT_FALSE(none.compact());
    EXPECT_EQ(none.count(), m.voxelCount());
    m.wantedS = someVoxels(m.voxelCount(), 3);
    const ShRows orderZero(m, 1);
    EXPECT_FALSE(orderZero.compact());
    EXPECT_EQ(orderZero.count(), m.voxelCount());
    m.wantedS.assign(m.voxelCount(), 1);
    EXPECT_FALSE(ShRows(m, 9).compact()) << "every voxel wanted: nothing to leave out";
}

TEST(ShRows, ExpandPutsEachRowAtItsVoxelAndZerosElsewhere) {
    Medium m = smallBox(6);
    m.wantedS = someVoxels(m.voxelCount(), 5);
    const ShRows rows(m, 4);
    ASSERT_TRUE(rows.compact());
    size_t wanted = 0;
    for (auto f : m.wantedS) wanted += f;
    ASSERT_EQ(rows.count(), wanted);
    const size_t width = 4 * 3;
    std::vector<float> sh(rows.count() * width);
    for (size_t i = 0; i < sh.size(); ++i) sh[i] = float(i + 1);  // row r holds r * width + 1 ...
    rows.expand(sh, 4);
    ASSERT_EQ(sh.size(), m.voxelCount() * width);
    size_t r = 0;
    for (size_t v = 0; v < m.voxelCount(); ++v)
        for (size_t i = 0; i < width; ++i) {
            const float want = m.wantedS[v] ? float(r * width + i + 1) : 0.0f;
            ASSERT_EQ(sh[v * width + i], want) << "voxel " << v << " value " << i;
            if (i + 1 == width && m.wantedS[v]) ++r;
        }
    std::vector<float> wrongSize(3);
    EXPECT_THROW(rows.expand(wrongSize, 4), Error);
    // Handed-over maps: a row beyond the result is refused; no row held expands to zeros.
    std::vector<float> twoRows(2 * width, 1.0f), none;
    EXPECT_THROW(expandShRows(twoRows, {0, ShRows::kNone, 2}, 4), Error);
    expandShRows(none, std::vector<std::uint32_t>(5, ShRows::kNone), 4);
    EXPECT_EQ(none, std::vector<float>(5 * width, 0.0f));
}

// A solve that keeps SH rows only for the wanted voxels returns, there, exactly the full
// solve's values (and 0 elsewhere), on each fold that deposits SH: the separable fine
// passes of the two-grid solve (its 4x9 kernel and the general one), the full fold, and
// the linear source's (whose negative band-0 values are clamped on the held rows).
TEST(ShRows, SolveWithWantedVoxelsEqualsTheFullSolveThere) {
    Case cs{"plume g0.5 a0.95", VolumeKind::Plume, 0.5, 0.95, 8.0};
    Scene sc = makeScene(cs, 24);
    sc.lights.env = &sc.sky;
    LpmSettings separable, fullSources, linear;
    separable.multires = fullSources.multires = 1;
    fullSources.separableSource = 0;
    linear.multires = 0;
    linear.linearSource = 1;
    linear.directionsPerFace = 2;  // 24 directions: the linear source costs 4-5x the step scheme
    for (const LpmSettings& s : {separable, fullSources, linear}) {
        Medium all = sc.medium, some = sc.medium;
        some.wantedS = someVoxels(some.voxelCount(), 11);
        const LpmResult ra = solveLpm(all, sc.lights, s), rs = solveLpm(some, sc.lights, s);
        ASSERT_EQ(ra.coeffs, 9);
        ASSERT_EQ(saidDecision(rs, "separable fine sources"), s.multires == 1 && s.separableSource != 0);
        ASSERT_EQ(ra.sh.size(), rs.sh.size());
        size_t mismatched = 0, nonZeroUnwanted = 0;
        for (size_t v = 0; v < all.voxelCount(); ++v)
            for (size_t i = 0; i < 27; ++i) {
                const float got = rs.sh[v * 27 + i];
                if (some.wantedS[v]) mismatched += got != ra.sh[v * 27 + i];
                else nonZeroUnwanted += got != 0.0f;
            }
        EXPECT_EQ(mismatched, 0u) << (s.linearSource == 1      ? "linear source"
                                      : s.separableSource == 0 ? "full sources"
                                                               : "separable sources");
        EXPECT_EQ(nonZeroUnwanted, 0u);
        EXPECT_EQ(ra.absorbed, rs.absorbed);
        EXPECT_EQ(ra.passes.size(), rs.passes.size());
    }
}

// With keepShRows the solve hands back the held rows and their map: read through the map
// (coeff) and expanded (expandSh), they are the by-voxel result bit for bit.
TEST(ShRows, KeptRowsAreTheResultByVoxel) {
    Case cs{"plume g0.5 a0.95", VolumeKind::Plume, 0.5, 0.95, 8.0};
    Scene sc = makeScene(cs, 16);
    sc.lights.env = &sc.sky;
    sc.medium.wantedS = someVoxels(sc.medium.voxelCount(), 13);
    LpmSettings byVoxel, kept;
    kept.keepShRows = true;
    const LpmResult rv = solveLpm(sc.medium, sc.lights, byVoxel);
    LpmResult rk = solveLpm(sc.medium, sc.lights, kept);
    ASSERT_EQ(rv.coeffs, 9);
    EXPECT_TRUE(rv.shRow.empty());
    ASSERT_EQ(rk.shRow.size(), sc.medium.voxelCount());
    size_t wanted = 0;
    for (auto f : sc.medium.wantedS) wanted += f;
    ASSERT_EQ(rk.sh.size(), wanted * 27) << "rows for the wanted voxels only";
    size_t mismatched = 0;
    for (size_t v = 0; v < sc.medium.voxelCount(); ++v) {
        EXPECT_EQ(rk.shAt(v) == nullptr, sc.medium.wantedS[v] == 0) << "voxel " << v;
        for (int k = 0; k < 9; ++k) {
            const RGB a = rk.coeff(v, k), b = rv.coeff(v, k);
            mismatched += a.r != b.r || a.g != b.g || a.b != b.b;
        }
    }
    EXPECT_EQ(mismatched, 0u);
    rk.expandSh();
    EXPECT_TRUE(rk.shRow.empty());
    EXPECT_EQ(rk.sh, rv.sh);
    rk.expandSh();  // already by voxel: nothing
    EXPECT_EQ(rk.sh, rv.sh);
}

TEST(ShRows, WantedFlagsOfAnotherSizeAreRefused) {
    Medium m = smallBox(4);
    m.wantedS.assign(7, 1);
    EXPECT_THROW(m.validate(), Error);
    EXPECT_THROW(ShRows(m, 9), Error);
}

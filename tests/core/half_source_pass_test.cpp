// A pass of a half-precision source (core/half_source_pass.h) against run() of the
// decoded source: the same deposits and tallies, bit for bit.
#include "core/half_source_pass.h"

#include <gtest/gtest.h>

#include "core/lpm_cache.h"
#include "core/rng.h"
#include "test_scenes.h"

using namespace lpm;
using namespace lpm::test;

namespace {

/// A cloud, the jobs of 2x2 directions per face (24 bins at g = 0.6), and a random source
/// (residuals change sign) of bins x RGB per voxel, or per row with mass, with its
/// half-precision copy.
struct PassSetup {
    const Medium m = makeVolume(VolumeKind::Cloud, 12, 3.0);
    const MassRows rows{m};
    LpmCache cache;
    const CubeQuadrature quad{2};
    const std::shared_ptr<const FormFactors> ff = cache.formFactors(2, 2, 0.6);
    const int bins = ff->binCount();
    const size_t width = size_t(bins) * 3;
    const JobFactory factory{quad, *ff, m.localToWorld, m.voxelVolume(), 1, 0.6};
    const RGB albedo{0.9f, 0.8f, 0.7f};
    const std::vector<std::uint8_t> noSlopes;
    std::vector<float> sh, src, decoded;
    HalfBuffer half;
    PassSetup(bool byRows, std::uint64_t seed) {
        Pcg32 rng(seed, 7);
        src.resize((byRows ? rows.size() : m.voxelCount()) * width);
        for (float& x : src) x = float(rng.uniform()) - 0.2f;
        half = HalfBuffer::encode(src);
        for (size_t i = 0; i < src.size(); ++i) decoded.push_back(half.at(i));
    }
};

}  // namespace

TEST(HalfSourcePass, EqualsThePassOfTheDecodedSource) {
    PassSetup t(false, 31);
    ASSERT_EQ(t.bins, 24);
    const PassRunner runner(t.m, FoldShape{t.bins, 1, 1}, t.noSlopes, t.sh);
    std::vector<float> want(t.src.size(), 0.0f), got(t.src.size(), 0.0f);
    Tally wantTally, gotTally;
    runner.run(t.factory.sourceJobs(t.decoded, 1, t.albedo), 2, wantTally, false, want);
    for (size_t slots : {size_t(4), size_t(3)}) {  // 3: batches that cut faces apart
        SCOPED_TRACE(slots);
        std::vector<std::vector<float>> slotBuffers(slots);
        std::fill(got.begin(), got.end(), 0.0f);
        gotTally = Tally();
        propagateHalfSource(runner, t.factory, t.half, t.bins, t.albedo, 2, slotBuffers, gotTally, got);
        EXPECT_TRUE(got == want);
        for (int c = 0; c < 3; ++c) EXPECT_EQ(gotTally.scattered[c], wantTally.scattered[c]);
    }
    float peak = 0;
    for (float x : want) peak = std::max(peak, std::fabs(x));
    EXPECT_GT(peak, 0);
}

// A source held by the rows with mass (core/mass_rows.h), in float or half precision, and
// its deposits folded into rows: the pass of the source expanded to every voxel, at the
// rows, bit for bit. The runner refuses rows where the source is not voxel-constant bins.
TEST(HalfSourcePass, RowSourcesEqualThePassOfTheExpandedSource) {
    PassSetup t(true, 5);
    const MassRows& rows = t.rows;
    ASSERT_LT(rows.size(), t.m.voxelCount() * 9 / 10);
    const PassRunner byVoxel(t.m, FoldShape{t.bins, 1, 1}, t.noSlopes, t.sh);
    const PassRunner byRows(t.m, FoldShape{t.bins, 1, 1}, t.noSlopes, t.sh, nullptr, rows.rowOf.data());
    for (bool inHalf : {false, true}) {
        SCOPED_TRACE(inHalf);
        std::vector<float> want(t.m.voxelCount() * t.width, 0.0f), got(rows.size() * t.width, 0.0f);
        Tally wantTally, gotTally;
        const std::vector<float> expanded = expandRows(rows, inHalf ? t.decoded : t.src, t.width);
        byVoxel.run(t.factory.sourceJobs(expanded, 1, t.albedo), 2, wantTally, false, want);
        std::vector<std::vector<float>> slots(4);
        if (inHalf) propagateHalfSource(byRows, t.factory, t.half, t.bins, t.albedo, 2, slots, gotTally, got, &rows);
        else propagateRowSource(byRows, t.factory, t.src, t.bins, t.albedo, 2, slots, rows, gotTally, got);
        EXPECT_TRUE(got == gatherRows(rows, want, t.width));
        for (int c = 0; c < 3; ++c) EXPECT_EQ(gotTally.scattered[c], wantTally.scattered[c]);
    }
    EXPECT_THROW(PassRunner(t.m, FoldShape{1, 1, 1}, t.noSlopes, t.sh, nullptr, rows.rowOf.data()), Error);
    EXPECT_THROW(PassRunner(t.m, FoldShape{t.bins, 4, 1}, t.noSlopes, t.sh, nullptr, rows.rowOf.data()), Error);
}

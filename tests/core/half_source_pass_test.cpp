// A pass of a half-precision source (core/half_source_pass.h) against run() of the
// decoded source: the same deposits and tallies, bit for bit.
#include "core/half_source_pass.h"

#include <gtest/gtest.h>

#include "core/lpm_cache.h"
#include "core/rng.h"
#include "test_scenes.h"

using namespace lpm;
using namespace lpm::test;

TEST(HalfSourcePass, EqualsThePassOfTheDecodedSource) {
    const Medium m = makeVolume(VolumeKind::Cloud, 12, 3.0);
    LpmCache cache;
    const CubeQuadrature quad(2);
    const auto ff = cache.formFactors(2, 2, 0.6);
    const int bins = ff->binCount();
    ASSERT_EQ(bins, 24);
    const JobFactory factory(quad, *ff, m.localToWorld, m.voxelVolume(), 1, 0.6);
    Pcg32 rng(31, 7);
    std::vector<float> src(m.voxelCount() * size_t(bins) * 3);
    for (float& x : src) x = float(rng.uniform()) - 0.2f;  // residuals change sign
    const HalfBuffer half = HalfBuffer::encode(src);
    std::vector<float> decoded(src.size());
    for (size_t i = 0; i < src.size(); ++i) decoded[i] = half.at(i);
    const RGB albedo(0.9f, 0.8f, 0.7f);
    const std::vector<std::uint8_t> noSlopes;
    std::vector<float> sh;
    const PassRunner runner(m, FoldShape{bins, 1, 1}, noSlopes, sh);
    std::vector<float> want(src.size(), 0.0f), got(src.size(), 0.0f);
    Tally wantTally, gotTally;
    runner.run(factory.sourceJobs(decoded, 1, albedo), 2, wantTally, false, want);
    for (size_t slots : {size_t(4), size_t(3)}) {  // 3: batches that cut faces apart
        SCOPED_TRACE(slots);
        std::vector<std::vector<float>> slotBuffers(slots);
        std::fill(got.begin(), got.end(), 0.0f);
        gotTally = Tally();
        propagateHalfSource(runner, factory, half, bins, albedo, 2, slotBuffers, gotTally, got);
        EXPECT_TRUE(got == want);
        for (int c = 0; c < 3; ++c) EXPECT_EQ(gotTally.scattered[c], wantTally.scattered[c]);
    }
    float peak = 0;
    for (float x : want) peak = std::max(peak, std::fabs(x));
    EXPECT_GT(peak, 0);
}

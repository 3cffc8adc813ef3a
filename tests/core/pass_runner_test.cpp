// A propagation pass (core/pass_runner.h): the isotropic fold's fixed accumulators give the
// general fold's result, and the sweep batches partition the jobs by axis and source.
#include "core/pass_runner.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <set>

#include "core/job_factory.h"
#include "core/lpm_cache.h"
#include "test_scenes.h"

using namespace lpm;
using namespace lpm::test;

namespace {

struct PassOutput {
    std::vector<float> sh, out;
    Tally tally;
    size_t batches = 0;  ///< sweep batches of both passes (sweepBatches)
};

/// Pass 0 under a uniform sky, folded into `coeffs` SH coefficients and one isotropic bin,
/// with `moments` per bin; with the linear source's 4 also the pass its folded source feeds
/// (slopes and all; voxels with odd index keep no slopes), `out` holding both passes'.
/// exactFirstMoments: the isotropic linear fold keeps its first moments in float.
PassOutput runSkyPasses(const Medium& m, int coeffs, int moments = 1, bool exactFirstMoments = false) {
    LpmCache cache;
    const CubeQuadrature quad(4);
    const auto ff = cache.formFactors(4, 0, 0.0);
    const JobFactory factory(quad, *ff, m.localToWorld, m.voxelVolume(), coeffs, 0.0);
    const std::vector<RGB> sky(quad.count(), RGB(1.0f, 0.8f, 0.5f));
    const std::vector<Job> jobs = factory.lightJobs(m, sky, true, {});
    const size_t N = m.voxelCount();
    std::vector<std::uint8_t> slopes;
    for (size_t v = 0; v < N && moments == 4; ++v) slopes.push_back(v % 2 == 0);
    PassOutput o;
    o.sh.assign(N * coeffs * 3, 0.0f);
    o.out.assign(N * 3 * moments, 0.0f);
    const PassRunner runner(m, FoldShape{1, moments, coeffs}, slopes, o.sh);
    EXPECT_EQ(runner.isotropic(jobs), coeffs == 1);
    if (exactFirstMoments) runner.keepFirstMomentsInFloat();
    runner.run(jobs, 2, o.tally, true, o.out);
    o.batches = sweepBatches(jobs, 2).size();
    if (moments == 4) {
        std::vector<float> next(o.out.size(), 0.0f);
        const std::vector<Job> sourceJobs = factory.sourceJobs(o.out, 4, m.albedo);
        o.batches += sweepBatches(sourceJobs, 2).size();
        runner.run(sourceJobs, 1, o.tally, true, next);
        for (size_t i = 0; i < next.size(); ++i) o.out[i] += next[i];
    }
    return o;
}

}  // namespace

TEST(PassRunner, IsotropicFoldEqualsGeneralFold) {
    const Medium m = makeVolume(VolumeKind::Cloud, 12, 3.0);
    const PassOutput iso = runSkyPasses(m, 1), general = runSkyPasses(m, 4);
    float peak = 0;
    for (float v : general.out) peak = std::max(peak, v);
    ASSERT_GT(peak, 0);
    for (size_t v = 0; v < m.voxelCount(); ++v)
        for (int c = 0; c < 3; ++c) {
            EXPECT_NEAR(iso.out[v * 3 + c], general.out[v * 3 + c], 1e-5 * peak) << v;
            EXPECT_NEAR(iso.sh[v * 3 + c], general.sh[v * 12 + c], 1e-5 * peak) << v;
        }
    for (int c = 0; c < 3; ++c)
        EXPECT_NEAR(iso.tally.scattered[c], general.tally.scattered[c], 1e-5 * general.tally.scattered[c]);
}

// The linear source's isotropic fold (batched sweeps into fixed accumulators, in rounds)
// against its general fold (a deposit buffer per direction): the next source's means and
// slopes, band 0 and the tallies. With first moments in float (as under GMRES) everything
// agrees to float rounding; with them in bfloat16 the means and the tallies still do, band
// 0 within what the first pass's rounded slopes can move in the second, and the slopes
// within the rounding of each batch's first moments: 2^-8 of a stored value at most, so
// at most 2^-8 of the sum of the batches' magnitudes per value (bounded by G x 2^-8 of the
// largest slope, G the batches) and about 2^-10 of the slopes' L1 norm (errors of either
// sign, a quarter of an ulp on average; the test allows 2^-9).
TEST(PassRunner, IsotropicLinearFoldEqualsGeneralFold) {
    Medium m = makeVolume(VolumeKind::Cloud, 12, 3.0);
    const PassOutput general = runSkyPasses(m, 4, 4);
    float peak = 0, slopePeak = 0;
    double slopeL1 = 0;
    for (size_t i = 0; i < general.out.size(); ++i) {
        float& p = i % 12 < 3 ? peak : slopePeak;
        p = std::max(p, std::fabs(general.out[i]));
        if (i % 12 >= 3) slopeL1 += std::fabs(general.out[i]);
    }
    float shPeak = 0;
    for (float v : general.sh) shPeak = std::max(shPeak, std::fabs(v));
    ASSERT_GT(peak, 0);
    ASSERT_GT(slopePeak, 0);
    for (bool exact : {true, false}) {
        SCOPED_TRACE(exact ? "first moments in float" : "first moments in bfloat16");
        const PassOutput iso = runSkyPasses(m, 1, 4, exact);
        const float slopeTol = exact ? 1e-5f * peak : float(iso.batches) * 0x1p-8f * slopePeak;
        // Band 0 of the second pass sees the first's rounded slopes through its source: at
        // most 2^-8 of it if the slopes carried all of it.
        const float shTol = exact ? 1e-5f * peak : 0x1p-8f * shPeak;
        double slopeDiff = 0;
        for (size_t v = 0; v < m.voxelCount(); ++v) {
            for (int k = 0; k < 3; ++k) EXPECT_NEAR(iso.out[v * 12 + k], general.out[v * 12 + k], 1e-5 * peak) << v;
            for (int k = 3; k < 12; ++k) {
                EXPECT_NEAR(iso.out[v * 12 + k], general.out[v * 12 + k], slopeTol) << v;
                slopeDiff += std::fabs(iso.out[v * 12 + k] - general.out[v * 12 + k]);
            }
            for (int k = 3; k < 12 && v % 2 == 1; ++k) EXPECT_EQ(iso.out[v * 12 + k], 0.0f) << v;  // no slopes kept
            for (int c = 0; c < 3; ++c) EXPECT_NEAR(iso.sh[v * 3 + c], general.sh[v * 12 + c], shTol) << v;
        }
        EXPECT_LT(slopeDiff, (exact ? 1e-5 : 0x1p-9) * slopeL1);
        std::printf("%s: slopes' relative L1 difference %.3g\n", exact ? "float" : "bfloat16", slopeDiff / slopeL1);
        for (int c = 0; c < 3; ++c) {
            EXPECT_NEAR(iso.tally.scattered[c], general.tally.scattered[c], 1e-5 * general.tally.scattered[c]);
            EXPECT_NEAR(iso.tally.injected[c], general.tally.injected[c], 1e-5 * general.tally.injected[c]);
        }
    }
}

// The linear source's isotropic fold holds one accumulator per thread (up to the batch
// count): 30 B a voxel (mean in float, first moments in bfloat16); once GMRES asks for
// float first moments the bfloat16 buffers are freed, and then 48 B a voxel.
TEST(PassRunner, LinearFoldHoldsOnlyItsAccumulators) {
    const Medium m = makeVolume(VolumeKind::Cloud, 12, 3.0);
    LpmCache cache;
    const CubeQuadrature quad(4);
    const auto ff = cache.formFactors(4, 0, 0.0);
    const JobFactory factory(quad, *ff, m.localToWorld, m.voxelVolume(), 1, 0.0);
    const std::vector<RGB> sky(quad.count(), RGB(1.0f));
    const std::vector<Job> jobs = factory.lightJobs(m, sky, true, {});
    const size_t N = m.voxelCount();
    std::vector<float> sh(N * 3, 0.0f), out(N * 12, 0.0f);
    const PassRunner runner(m, FoldShape{1, 4, 1}, {}, sh);
    Tally tally;
    runner.run(jobs, 2, tally, true, out);
    const size_t rounded = runner.heldBufferBytes(), threads = rounded / (N * 30);
    ASSERT_GE(threads, 1u);
    EXPECT_EQ(rounded, threads * N * 30);
    runner.keepFirstMomentsInFloat();
    EXPECT_EQ(runner.heldBufferBytes(), threads * N * 12);  // only the means' buffers left
    runner.run(jobs, 2, tally, true, out);
    EXPECT_EQ(runner.heldBufferBytes(), threads * N * 48);
    runner.releaseBuffers();
    EXPECT_EQ(runner.heldBufferBytes(), 0u);
}

TEST(PassRunner, BatchesPartitionJobsByAxisAndSource) {
    const CubeQuadrature quad(4);
    LpmCache cache;
    const auto ff = cache.formFactors(4, 0, 0.0);
    const JobFactory factory(quad, *ff, Mat3{}, 1.0, 1, 0.0);
    std::vector<float> src(8 * 3, 1.0f);
    std::vector<Job> jobs = factory.sourceJobs(src, 1, RGB(0.9f));
    const std::vector<Job> more = factory.sourceJobs(src, 1, RGB(0.5f));  // another source scale
    jobs.insert(jobs.end(), more.begin(), more.end());
    // The factory's order (each face's directions together) and one with the signs
    // alternating job by job: batches hold one sign either way.
    std::vector<Job> alternating;
    std::vector<const Job*> plus, minus;
    for (const Job& j : jobs) (j.sign > 0 ? plus : minus).push_back(&j);
    ASSERT_EQ(plus.size(), minus.size());
    for (size_t i = 0; i < plus.size(); ++i) {
        alternating.push_back(*plus[i]);
        alternating.push_back(*minus[i]);
    }
    for (const std::vector<Job>* list : {&jobs, &alternating}) {
        const auto batches = sweepBatches(*list, 2);
        std::set<const Job*> seen;
        for (const auto& b : batches) {
            ASSERT_FALSE(b.empty());
            for (const Job* j : b) {
                EXPECT_TRUE(seen.insert(j).second) << "a job in two batches";
                EXPECT_EQ(j->axis, b[0]->axis);
                EXPECT_EQ(j->srcScale.r, b[0]->srcScale.r);
                EXPECT_EQ(j->sign, b[0]->sign) << "one sign a batch: each layer gathered once for all its jobs";
            }
            // Job order within a batch (thread-count independent sums).
            for (size_t i = 1; i < b.size(); ++i) EXPECT_LT(b[i - 1], b[i]);
        }
        EXPECT_EQ(seen.size(), list->size());
        EXPECT_EQ(batches.size(), 12u) << "3 axes x 2 sources x 2 halves";
    }
}

// The runner keeps its deposit buffers from pass to pass (they were faulted in again every
// pass): a pass run again on the same runner, and again after releaseBuffers, gives the
// same deposits, bit for bit, in both folds. A buffer not zeroed between passes fails it.
TEST(PassRunner, KeptBuffersStartEveryPassFromZero) {
    const Medium m = makeVolume(VolumeKind::Cloud, 12, 3.0);
    LpmCache cache;
    const CubeQuadrature quad(4);
    const auto ff = cache.formFactors(4, 0, 0.0);
    const std::vector<RGB> sky(quad.count(), RGB(1.0f, 0.8f, 0.5f));
    const std::vector<std::uint8_t> noSlopes;
    for (int coeffs : {1, 4}) {
        const JobFactory factory(quad, *ff, m.localToWorld, m.voxelVolume(), coeffs, 0.0);
        const std::vector<Job> jobs = factory.lightJobs(m, sky, true, {});
        std::vector<float> sh(m.voxelCount() * coeffs * 3, 0.0f);
        const PassRunner runner(m, FoldShape{1, 1, coeffs}, noSlopes, sh);
        std::vector<std::vector<float>> outs;
        for (int pass = 0; pass < 3; ++pass) {
            if (pass == 2) runner.releaseBuffers();
            outs.emplace_back(m.voxelCount() * 3, 0.0f);
            Tally t;
            runner.run(jobs, 2, t, false, outs.back());
        }
        EXPECT_GT(*std::max_element(outs[0].begin(), outs[0].end()), 0.0f);
        EXPECT_EQ(outs[1], outs[0]) << coeffs << " coefficients, second pass";
        EXPECT_EQ(outs[2], outs[0]) << coeffs << " coefficients, after releaseBuffers";
    }
}

// Sweep groups of a batch: contiguous runs of jobs with the same planes and sign, covering
// the batch in order; split until each thread has one where runs allow.
TEST(PassRunner, SweepGroupsCoverTheBatchInRunsOfOnePlaneSet) {
    const CubeQuadrature quad(4);
    LpmCache cache;
    const auto ff = cache.formFactors(4, 0, 0.0);
    const JobFactory factory(quad, *ff, Mat3{}, 1.0, 1, 0.0);
    std::vector<float> src(8 * 3, 1.0f);
    const std::vector<Job> jobs = factory.sourceJobs(src, 1, RGB(0.9f));
    for (int threads : {1, 2, 3, 16}) {
        const auto groups = sweepGroups(jobs.data(), jobs.size(), threads);
        size_t next = 0;
        int runs = 0;
        for (const auto& [b, e] : groups) {
            ASSERT_EQ(b, next) << "groups cover the batch in order";
            ASSERT_LT(b, e);
            for (size_t j = b; j < e; ++j) {
                EXPECT_TRUE(samePlanes(jobs[j], jobs[b]));
                EXPECT_EQ(jobs[j].sign, jobs[b].sign);
            }
            runs += b == 0 || !samePlanes(jobs[b], jobs[b - 1]) || jobs[b].sign != jobs[b - 1].sign;
            next = e;
        }
        EXPECT_EQ(next, jobs.size());
        EXPECT_EQ(runs, 6) << "one run per cube face";
        if (threads <= 6) EXPECT_EQ(groups.size(), 6u);
        else EXPECT_EQ(groups.size(), size_t(threads));
    }
    // One run of four jobs and two threads: two groups of two.
    const auto two = sweepGroups(jobs.data(), 4, 2);
    ASSERT_EQ(two.size(), 2u);
    EXPECT_EQ(two[0], std::make_pair(size_t(0), size_t(2)));
    EXPECT_EQ(two[1], std::make_pair(size_t(2), size_t(4)));
}

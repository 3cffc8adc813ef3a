// Sweep kernel throughput (Google Benchmark): ray-segment updates per second of one
// sweep, one thread, on a dense random block, by rays per voxel and with or without a
// volume source; and a batch of 16 directions sharing their planes (sweepStepBatch), on
// a block of 32^3 (its planes in L2) and 96^3 (in L3); and the separable fold of one
// batch at SH order 2 (BM_SeparableFold, bytes/s of its main streams).
//   lpm_bench_kernel [--benchmark_filter=...]
// The counter "segments/s" is the figure the roofline estimate in docs/performance.md is
// compared with.
#include <benchmark/benchmark.h>

#include <cmath>
#include <vector>

#include "core/multires.h"
#include "core/rng.h"
#include "core/separable_source.h"
#include "core/sweep.h"

using namespace lpm;

namespace {

Medium denseBlock(int n) {
    Medium m;
    m.albedo = RGB(0.9f);
    m.allocate(n, n, n);
    Pcg32 rng(7, 1);
    for (float& s : m.sigmaT) s = float(0.05 + 0.5 * rng.uniform());  // voxel optical depth 0.05 .. 0.55
    return m;
}

Job obliqueJob(int i, const std::vector<float>* src) {
    Job j;
    j.w = normalize(Vec3{0.3 + 0.02 * i, 1.0, 0.45 - 0.03 * i});
    j.axis = dominantAxis(j.w);
    j.sign = 1;
    j.boundary = RGB(1.0f);
    j.weight = 0.01;
    j.offsetU = std::fmod(0.5 + 0.754877666 * (i + 1), 1.0);
    j.offsetV = std::fmod(0.5 + 0.569840291 * (i + 1), 1.0);
    if (src) {
        j.src = src->data();
        j.srcScale = RGB(0.9f);
    }
    return j;
}

void BM_Sweep(benchmark::State& state) {
    const int r = int(state.range(0));
    const bool withSrc = state.range(1) != 0;
    const Medium m = denseBlock(96);
    const std::vector<float> src(m.voxelCount() * 3, 1.0f);
    const Job job = obliqueJob(0, withSrc ? &src : nullptr);
    std::vector<float> phi(m.voxelCount() * 3, 0.0f);
    std::uint64_t segments = 0;
    for (auto _ : state) {
        Tally t;
        sweepStep(m, job, r, phi.data(), t);
        segments += t.segments;
        benchmark::DoNotOptimize(phi.data());
    }
    state.counters["segments/s"] = benchmark::Counter(double(segments), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_Sweep)->ArgsProduct({{1, 2}, {0, 1}})->Unit(benchmark::kMillisecond);

void BM_SweepBatch16(benchmark::State& state) {
    const int r = int(state.range(0));
    const Medium m = denseBlock(int(state.range(1)));
    const std::vector<float> src(m.voxelCount() * 3, 1.0f);
    std::vector<Job> jobs;
    for (int i = 0; i < 16; ++i) jobs.push_back(obliqueJob(i, &src));
    std::vector<const Job*> ptrs;
    for (const Job& j : jobs) ptrs.push_back(&j);
    std::vector<float> phi(m.voxelCount() * 3, 0.0f);
    std::uint64_t segments = 0;
    for (auto _ : state) {
        Tally t;
        sweepStepBatch(m, ptrs, r, phi.data(), t, 1.0f);
        segments += t.segments;
        benchmark::DoNotOptimize(phi.data());
    }
    state.counters["segments/s"] = benchmark::Counter(double(segments), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_SweepBatch16)->ArgsProduct({{1, 2}, {32, 96}})->Unit(benchmark::kMillisecond);

// The separable fold of one batch (4 jobs of one bin, core/separable_source.h) on a dense
// block of n^3 fine voxels: each voxel's SH row (9 coefficients x RGB) read and written,
// 4 deposits read, its angular integral and its parent's psi updated. The counter
// "bytes/s" counts the fine voxel's main streams (SH read + write 216 B, deposits 48 B,
// integral 24 B, sigma and parent 8 B: 296 B), the figure to compare with the machine's
// streaming bandwidth (docs/performance.md).
void BM_SeparableFold(benchmark::State& state) {
    const int n = int(state.range(0));
    const Medium fine = denseBlock(n);
    const Medium coarse = coarsen(fine);  // every coarse voxel with mass: a row each
    const FineCoarseMap map(fine, coarse);
    constexpr int kBins = 24, kCoeffs = 9;
    const std::vector<double> binWeight(kBins, 4 * 3.14159265358979 / kBins);
    std::vector<Job> jobs(4);
    Pcg32 rng(11, 3);
    for (Job& j : jobs) {
        j.shCoef.resize(kCoeffs);
        j.binCoef.resize(kBins);
        for (double& c : j.shCoef) c = rng.uniform() - 0.5;
        for (double& c : j.binCoef) c = rng.uniform() / kBins;
    }
    std::vector<std::vector<float>> phi(4, std::vector<float>(fine.voxelCount() * 3));
    for (auto& p : phi)
        for (float& v : p) v = float(rng.uniform());
    std::vector<float> sh(fine.voxelCount() * kCoeffs * 3, 0.0f);
    SeparableFold fold(map, fine.sigmaT, binWeight, kCoeffs);
    for (auto _ : state) {
        fold.fold(true, jobs.data(), jobs.size(), phi, sh);
        benchmark::DoNotOptimize(sh.data());
    }
    state.counters["bytes/s"] =
        benchmark::Counter(296.0 * double(fine.voxelCount()) * double(state.iterations()), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_SeparableFold)->Arg(32)->Arg(128)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();

// The fast sweep kernel (core/sweep.cpp) against the reference DDA sweep, and its
// exponential against std::exp.
#include "core/sweep.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <initializer_list>
#include <string>
#include <vector>

#include "core/rng.h"

using namespace lpm;

namespace {

// A random heterogeneous block, optionally sparse (unallocated tiles inside tile rows, or
// whole empty tile rows), with
// optically thin and thick voxels and empty voxels inside allocated tiles.
Medium randomMedium(int nx, int ny, int nz, Vec3 h, bool sparse, std::uint64_t seed, bool emptyRows = false) {
    Medium m;
    m.voxelSize = h;
    m.albedo = RGB(0.8f, 0.7f, 0.6f);
    std::vector<std::uint8_t> active;
    Medium probe;
    probe.nx = nx;
    probe.ny = ny;
    probe.nz = nz;
    if (sparse) {
        active.assign(size_t(probe.tilesX()) * probe.tilesY() * probe.tilesZ(), 0);
        // Gaps inside tile rows (tx == 1 unallocated), or whole empty tile rows along x.
        for (size_t t = 0; t < active.size(); ++t)
            active[t] = emptyRows ? (t / probe.tilesX()) % 2 == 0 : (t % probe.tilesX()) != 1;
    }
    m.allocate(nx, ny, nz, sparse ? &active : nullptr);
    Pcg32 rng(seed, 5);
    for (float& s : m.sigmaT) {
        const double u = rng.uniform();
        s = u < 0.2 ? 0.0f : float(std::pow(10.0, 4 * rng.uniform() - 2.5));  // 0, or 3e-3 .. 30
    }
    return m;
}

// Per stored voxel: whether it lies in the block (the others are edge tiles' padding).
std::vector<char> blockVoxels(const Medium& m) {
    std::vector<char> inBlock(m.voxelCount(), 0);
    for (int z = 0; z < m.nz; ++z)
        for (int y = 0; y < m.ny; ++y)
            for (int x = 0; x < m.nx; ++x)
                if (m.index(x, y, z) != Medium::npos) inBlock[m.index(x, y, z)] = 1;
    return inBlock;
}

// Largest difference of two sweeps' tallies (injected, escaped, absorbed, scattered),
// relative to the reference's injected power, over the channels.
double tallyDifference(const Tally& tr, const Tally& tf) {
    double worst = 0;
    for (int ch = 0; ch < 3; ++ch) {
        const double inj = std::max(tr.injected[ch], 1e-30);
        for (double d : {tf.injected[ch] - tr.injected[ch], tf.escaped[ch] - tr.escaped[ch],
                         tf.absorbed[ch] - tr.absorbed[ch], tf.scattered[ch] - tr.scattered[ch]})
            worst = std::max(worst, std::fabs(d) / inj);
    }
    return worst;
}

struct Compare {
    double maxRel = 0;  // largest |fast - ref| / (max |ref|) over voxels and channels
    double tallyRel = 0;
};

Compare compareKernels(const Medium& m, const Job& job, int r) {
    const size_t N = m.voxelCount();
    std::vector<float> ref(N * 3, 0.0f), fast(N * 3, 0.0f);
    Tally tr, tf;
    sweepReference<false>(m, job, r, ref.data(), tr);
    sweepStep(m, job, r, fast.data(), tf);
    double scale = 0;
    for (float x : ref) scale = std::max(scale, double(std::fabs(x)));
    Compare c;
    for (size_t i = 0; i < ref.size(); ++i)
        c.maxRel = std::max(c.maxRel, std::fabs(double(fast[i]) - ref[i]) / std::max(scale, 1e-30));
    c.tallyRel = tallyDifference(tr, tf);
    return c;
}

Job makeJob(const Vec3& w, const std::vector<float>* src, double o) {
    Job j;
    j.w = normalize(w);
    j.axis = dominantAxis(j.w);
    j.sign = j.w[j.axis] > 0 ? 1 : -1;
    j.boundary = RGB(1.0f, 0.5f, 2.0f);
    j.weight = 0.1;
    j.offsetU = o;
    j.offsetV = std::fmod(o * 1.7 + 0.13, 1.0);
    if (src) {
        j.src = src->data();
        j.srcScale = RGB(0.8f, 0.7f, 0.6f);
    }
    return j;
}

/// check(r, w, kind, offset) for every ray density of `rs`, direction of `dirs` and source
/// kind 0..kinds-1, case k at lattice offset offset0 + k step (mod 1). Returns the number
/// of cases.
template <class Check>
int forEachCase(std::initializer_list<int> rs, const std::vector<Vec3>& dirs, int kinds, double offset0, double step,
                Check&& check) {
    int cases = 0;
    for (int r : rs)
        for (const Vec3& w : dirs)
            for (int kind = 0; kind < kinds; ++kind) check(r, w, kind, std::fmod(offset0 + step * cases++, 1.0));
    return cases;
}

/// Every direction of `dirs` at each ray density of `rs`, without and with the source
/// `src`: the kernel against the reference. Returns the number of cases.
int expectMatchesReference(const Medium& m, const std::vector<Vec3>& dirs, std::initializer_list<int> rs,
                           const std::vector<float>& src, double offset0, double step) {
    return forEachCase(rs, dirs, 2, offset0, step, [&](int r, const Vec3& w, int withSrc, double offset) {
        const Compare c = compareKernels(m, makeJob(w, withSrc ? &src : nullptr, offset), r);
        EXPECT_LT(c.maxRel, 2e-5) << "w = " << w.x << "," << w.y << "," << w.z << " r = " << r << " src " << withSrc;
        EXPECT_LT(c.tallyRel, 2e-5) << "w = " << w.x << "," << w.y << "," << w.z << " r = " << r;
    });
}

}  // namespace

TEST(SweepKernel, ExpNegMatchesStdExp) {
    double worst = 0;
    for (int i = 0; i < 870000; ++i) {  // [0, 87): e^-x normal in float
        const float x = float(i) * 1e-4f;
        const double ref = std::exp(-double(x));
        worst = std::max(worst, std::fabs(double(expNeg(x)) - ref) / ref);
    }
    EXPECT_LT(worst, 3e-7);
    EXPECT_EQ(expNeg(87.5f), 0.0f);
    EXPECT_EQ(expNeg(1e30f), 0.0f);
    EXPECT_EQ(expNeg(0.0f), 1.0f);
}

// Every direction family, oblique and axis-aligned directions, r = 1..3, boundary light
// with and without a volume source, dense and sparse storage, non-cubic voxels.
TEST(SweepKernel, MatchesReferenceSweep) {
    const Vec3 dirs[] = {{1, 0, 0},       {0, -1, 0},      {0, 0, 1},     {0.9, 0.3, -0.2},   {-0.4, 1, 0.7},
                         {0.5, -0.5, -1}, {1, 0.999, 0.2}, {-1, -1, 1.0}, {0.05, 0.02, -1.0}, {1, 1e-9, 0}};
    int cases = 0;
    for (bool sparse : {false, true})
        for (int r : {1, 2, 3}) {
            const Medium m = randomMedium(19, 13, 17, sparse ? Vec3{1, 1, 1} : Vec3{0.7, 1.1, 0.9}, sparse, 11 + r);
            std::vector<float> src(m.voxelCount() * 3);
            Pcg32 rng(3, 7);
            for (float& x : src) x = float(rng.uniform());
            for (const Vec3& w : dirs)
                for (bool withSrc : {false, true}) {
                    const Job job = makeJob(w, withSrc ? &src : nullptr, std::fmod(0.37 + 0.05 * cases, 1.0));
                    const Compare c = compareKernels(m, job, r);
                    EXPECT_LT(c.maxRel, 2e-5) << "w = " << w.x << "," << w.y << "," << w.z << " r = " << r << " sparse "
                                              << sparse << " src " << withSrc;
                    EXPECT_LT(c.tallyRel, 2e-5) << "w = " << w.x << "," << w.y << "," << w.z << " r = " << r;
                    ++cases;
                }
        }
    EXPECT_EQ(cases, 120);
}

// The kernel picks its formulas per chunk of 8 voxels by their optical depths (series
// only below 1/4, exp only from 1/4, both where a chunk straddles it): a medium thin
// enough that no segment reaches 1/4, one thick enough that nearly every segment is past
// it, and one with every chunk straddling it, each against the reference DDA.
TEST(SweepKernel, ThinThickAndMixedChunksMatchReference) {
    const std::vector<Vec3> dirs = {{1, 0.7, -0.4}, {-0.3, -1, 0.9}, {0.6, 0.2, 1}, {0, 0, -1}};
    struct Range {
        double lo, hi;   // sigma per voxel length
        bool alternate;  // alternate lanes between lo and hi instead of a uniform draw
    };
    int cases = 0;
    for (const Range& range : {Range{1e-4, 0.14, false}, Range{2.0, 30.0, false}, Range{0.01, 5.0, true}}) {
        Medium m;
        m.albedo = RGB(0.8f, 0.7f, 0.6f);
        m.allocate(16, 24, 16);
        Pcg32 rng(17, 9);
        for (size_t x = 0; x < m.sigmaT.size(); ++x)
            m.sigmaT[x] = float(range.alternate ? (x % 2 ? range.hi : range.lo)
                                                : range.lo + (range.hi - range.lo) * rng.uniform());
        std::vector<float> src(m.voxelCount() * 3);
        for (float& x : src) x = float(rng.uniform());
        cases += expectMatchesReference(m, dirs, {1, 2}, src, 0.21, 0.09);
    }
    EXPECT_EQ(cases, 48);
}

// Whole empty tile layers (tile index 1 unallocated along every axis, so every sweep
// crosses one) are crossed by bookkeeping alone: the same deposits and tallies as the
// reference DDA, for oblique directions of every axis that also leave through the
// lateral faces inside the empty layer.
TEST(SweepKernel, EmptyTileLayersMatchReference) {
    Medium probe;
    probe.nx = 26, probe.ny = 21, probe.nz = 30;
    std::vector<std::uint8_t> active(size_t(probe.tilesX()) * probe.tilesY() * probe.tilesZ(), 0);
    for (int tz = 0; tz < probe.tilesZ(); ++tz)
        for (int ty = 0; ty < probe.tilesY(); ++ty)
            for (int tx = 0; tx < probe.tilesX(); ++tx)
                active[size_t(tx) + size_t(probe.tilesX()) * (size_t(ty) + size_t(probe.tilesY()) * tz)] =
                    tx != 1 && ty != 1 && tz != 1;
    Medium m;
    m.voxelSize = {1, 0.9, 1.1};
    m.albedo = RGB(0.8f, 0.7f, 0.6f);
    m.allocate(probe.nx, probe.ny, probe.nz, &active);
    Pcg32 rng(21, 4);
    for (float& x : m.sigmaT) x = float(2 * rng.uniform());
    std::vector<float> src(m.voxelCount() * 3);
    for (float& x : src) x = float(rng.uniform());
    const std::vector<Vec3> dirs = {{1, 0.7, -0.4},    {-1, -0.3, 0.9}, {0.6, 1, 0.8},
                                    {-0.2, -1, -0.95}, {0.9, -0.8, 1},  {0.3, 0.4, -1}};
    // Offsets 0.11 + 0.0707 k: none lands on 0, where a ray starts exactly on a lateral face
    // and the two kernels count its exit and re-entry by different conventions (an
    // injected-minus-escaped neutral difference of the tallies; the deposits agree).
    EXPECT_EQ(expectMatchesReference(m, dirs, {1, 2, 3}, src, 0.11, 0.0707), 36);
}

// Empty tiles are skipped, not mis-swept: a sparse block and the same block stored densely
// give the same deposits in the stored voxels.
// Two blobs of density at opposite corners of a wide sparse block (the puffs-in-a-box
// case): ray rows meet density, cross long empty stretches with their column shifts
// pending, and meet density again far from where their kept columns lie, so their
// windows move and grow; rows that only ever cross empty space stay unwritten.
TEST(SweepKernel, DistantBlobsMatchReference) {
    Medium probe;
    probe.nx = 75, probe.ny = 70, probe.nz = 66;
    std::vector<std::uint8_t> active(size_t(probe.tilesX()) * probe.tilesY() * probe.tilesZ(), 0);
    auto tile = [&](int tx, int ty, int tz) -> std::uint8_t& {
        return active[size_t(tx) + size_t(probe.tilesX()) * (size_t(ty) + size_t(probe.tilesY()) * tz)];
    };
    tile(0, 0, 0) = tile(1, 0, 0) = tile(0, 1, 0) = 1;                     // near corner
    tile(probe.tilesX() - 1, probe.tilesY() - 1, probe.tilesZ() - 1) = 1;  // far corner
    tile(probe.tilesX() - 2, probe.tilesY() - 1, probe.tilesZ() - 1) = 1;
    tile(probe.tilesX() - 1, 0, probe.tilesZ() / 2) = 1;  // a third, off the diagonal
    Medium m;
    m.voxelSize = {1, 1.1, 0.9};
    m.albedo = RGB(0.9f, 0.8f, 0.7f);
    m.allocate(probe.nx, probe.ny, probe.nz, &active);
    Pcg32 rng(33, 5);
    for (float& x : m.sigmaT) x = float(0.5 * rng.uniform());
    std::vector<float> src(m.voxelCount() * 3);
    for (float& x : src) x = float(rng.uniform());
    const std::vector<Vec3> dirs = {{1, 0.95, 0.9}, {-1, -0.9, -0.97}, {0.9, 1, 0.3},
                                    {0.2, -0.6, 1}, {1, -0.99, 0.05},  {-0.7, 0.8, -1}};
    EXPECT_EQ(expectMatchesReference(m, dirs, {1, 2}, src, 0.23, 0.13), 24);
}

// A long dense block crossed at a steep lateral slope: every ray row's window drifts with
// its rays through far more column shifts than its slack, so it is re-centred many times.
TEST(SweepKernel, LongDenseBlockMatchesReference) {
    const Medium m = randomMedium(14, 10, 150, {1, 1, 0.8}, false, 41);
    Pcg32 rng(7, 9);
    std::vector<float> src(m.voxelCount() * 3);
    for (float& x : src) x = float(rng.uniform());
    const std::vector<Vec3> dirs = {{0.9, 0.02, 1}, {-0.85, -0.03, -1}, {0.6, 0.01, -1}, {-0.7, 0.0, 1}};
    EXPECT_EQ(expectMatchesReference(m, dirs, {1, 2}, src, 0.31, 0.17), 16);
}

TEST(SweepKernel, SparseStorageEqualsDense) {
    const Medium sp = randomMedium(24, 16, 20, {1, 1, 1}, true, 5, true);
    Medium dn;
    dn.voxelSize = sp.voxelSize;
    dn.albedo = sp.albedo;
    dn.allocate(sp.nx, sp.ny, sp.nz);
    for (int z = 0; z < sp.nz; ++z)
        for (int y = 0; y < sp.ny; ++y)
            for (int x = 0; x < sp.nx; ++x) {
                const size_t i = sp.index(x, y, z);
                dn.sigmaT[dn.index(x, y, z)] = i == Medium::npos ? 0.0f : sp.sigmaT[i];
            }
    const Job job = makeJob({0.6, -0.45, 1.0}, nullptr, 0.21);
    std::vector<float> a(sp.voxelCount() * 3, 0.0f), b(dn.voxelCount() * 3, 0.0f);
    Tally ta, tb;
    sweepStep(sp, job, 2, a.data(), ta);
    sweepStep(dn, job, 2, b.data(), tb);
    for (int z = 0; z < sp.nz; ++z)
        for (int y = 0; y < sp.ny; ++y)
            for (int x = 0; x < sp.nx; ++x) {
                const size_t i = sp.index(x, y, z);
                if (i == Medium::npos) continue;
                for (int c = 0; c < 3; ++c)
                    ASSERT_NEAR(a[i * 3 + c], b[dn.index(x, y, z) * 3 + c],
                                1e-5 * (1 + std::fabs(b[dn.index(x, y, z) * 3 + c])));
            }
    for (int c = 0; c < 3; ++c) {
        EXPECT_NEAR(ta.escaped[c], tb.escaped[c], 1e-6 * tb.injected[c]);
        EXPECT_NEAR(ta.scattered[c], tb.scattered[c], 1e-6 * tb.injected[c]);
    }
    EXPECT_LT(ta.segments, tb.segments);  // the empty tiles were skipped
}

// A batch of jobs sharing an axis and a source (shared planes for every layer, deposits
// accumulated in place) equals the sum of their separate sweeps, on dense storage, on
// sparse storage with gaps inside tile rows and with empty tile rows (per-layer spans),
// with and without a source, in a buffer holding other values (assigned: every stored
// voxel of the block overwritten, the padding of edge tiles left alone); its tally is the
// sum of theirs.
TEST(SweepKernel, BatchEqualsSumOfSweeps) {
    const Vec3 dirs[3][3] = {{{1, 0.3, -0.2}, {-0.8, -0.5, 0.4}, {0.9, 0.05, 0.6}},
                             {{0.2, 1, 0.1}, {-0.4, -0.9, 0.7}, {0.6, 0.8, -0.3}},
                             {{0.3, -0.2, 1}, {0.1, 0.5, -0.9}, {-0.7, 0.6, -0.8}}};
    int cases = 0;
    for (int layout = 0; layout < 3; ++layout) {
        const Medium m = randomMedium(21, 18, 26, {1, 0.8, 1.2}, layout > 0, 31 + layout, layout == 2);
        const std::vector<char> inBlock = blockVoxels(m);
        std::vector<float> src(m.voxelCount() * 3);
        Pcg32 rng(8, 3);
        for (float& x : src) x = float(rng.uniform());
        for (int axis = 0; axis < 3; ++axis)
            for (bool withSrc : {false, true}) {
                std::vector<Job> jobs;
                for (int i = 0; i < 3; ++i) {
                    jobs.push_back(makeJob(dirs[axis][i], withSrc ? &src : nullptr, 0.13 + 0.29 * i));
                    jobs.back().weight = 0.05 + 0.1 * i;
                }
                const float perWeight = 0.7f;
                const size_t N = m.voxelCount();
                constexpr float kStale = 7.0f;  // what the buffer held before
                std::vector<float> sum(N * 3, 0.0f), batch(N * 3, kStale);
                Tally ts, tb;
                std::vector<const Job*> ptrs;
                for (const Job& j : jobs) {
                    ASSERT_EQ(j.axis, axis);
                    sweepStep(m, j, 2, sum.data(), ts, float(perWeight * j.weight));
                    ptrs.push_back(&j);
                }
                sweepStepBatch(m, ptrs, 2, batch.data(), tb, perWeight);
                double scale = 0, worst = 0;
                for (float x : sum) scale = std::max(scale, double(std::fabs(x)));
                for (size_t i = 0; i < N * 3; ++i) {
                    const float want = inBlock[i / 3] ? sum[i] : kStale;
                    worst = std::max(worst, std::fabs(double(batch[i]) - want) / scale);
                }
                EXPECT_LT(worst, 1e-5) << "layout " << layout << " axis " << axis << " src " << withSrc;
                for (int c = 0; c < 3; ++c) {
                    const double inj = ts.injected[c];
                    EXPECT_NEAR(tb.injected[c], ts.injected[c], 1e-6 * inj);
                    EXPECT_NEAR(tb.escaped[c], ts.escaped[c], 1e-6 * inj);
                    EXPECT_NEAR(tb.scattered[c], ts.scattered[c], 1e-5 * inj);
                    EXPECT_NEAR(tb.absorbed[c], ts.absorbed[c], 1e-5 * inj);
                }
                EXPECT_EQ(tb.segments, ts.segments);
                ++cases;
            }
    }
    EXPECT_EQ(cases, 18);
}

TEST(SweepKernel, BatchRefusesMixedAxesOrSources) {
    const Medium m = randomMedium(9, 9, 9, {1, 1, 1}, false, 2);
    std::vector<float> src(m.voxelCount() * 3, 1.0f);
    const Job a = makeJob({1, 0.2, 0.1}, nullptr, 0.3), b = makeJob({0.1, 1, 0.2}, nullptr, 0.3),
              c = makeJob({1, 0.1, 0.3}, &src, 0.3);
    std::vector<float> phi(m.voxelCount() * 3, 0.0f);
    Tally t;
    EXPECT_THROW(sweepStepBatch(m, {&a, &b}, 2, phi.data(), t, 1.0f), Error);
    EXPECT_THROW(sweepStepBatch(m, {&a, &c}, 2, phi.data(), t, 1.0f), Error);
}

// A group of jobs of one axis, one sign and one source (planes gathered once per layer,
// each job's deposits scattered and cleared before the next job sweeps the layer) gives
// every job bit for bit the deposits and tally of its own sweep: dense, sparse with gaps
// inside tile rows and empty tile rows, with and without a source, r = 1 and 2. The group
// assigns its deposits: buffers holding other values get every stored voxel of the block
// overwritten and the padding of edge tiles left alone. The group into bfloat16 buffers
// stores each of those deposits rounded (core/bf16.h), with the same tallies.
TEST(SweepKernel, GroupEqualsOwnSweepsBitForBit) {
    const Vec3 dirs[3][3] = {{{1, 0.3, -0.2}, {0.8, -0.5, 0.4}, {0.9, 0.05, 0.6}},
                             {{0.2, 1, 0.1}, {-0.4, 0.9, 0.7}, {0.6, 0.8, -0.3}},
                             {{0.3, -0.2, 1}, {0.1, 0.5, 0.9}, {-0.7, 0.6, 0.8}}};
    int cases = 0;
    for (int layout = 0; layout < 3; ++layout) {
        const Medium m = randomMedium(21, 18, 26, {1, 0.8, 1.2}, layout > 0, 41 + layout, layout == 2);
        const std::vector<char> inBlock = blockVoxels(m);
        if (layout > 0) {
            ASSERT_LT(std::count(inBlock.begin(), inBlock.end(), 1), long(m.voxelCount()));  // padding
        }
        constexpr float kStale = 7.0f;  // what a buffer held before
        std::vector<float> src(m.voxelCount() * 3);
        Pcg32 rng(9, 4);
        for (float& x : src) x = float(rng.uniform());
        for (int axis = 0; axis < 3; ++axis)
            for (bool withSrc : {false, true})
                for (int r : {1, 2}) {
                    std::vector<Job> jobs;
                    for (int i = 0; i < 3; ++i) {
                        jobs.push_back(makeJob(dirs[axis][i], withSrc ? &src : nullptr, 0.17 + 0.23 * i));
                        jobs.back().weight = 0.05 + 0.1 * i;
                    }
                    const size_t N = m.voxelCount();
                    std::vector<std::vector<float>> own(3, std::vector<float>(N * 3, 0.0f));
                    std::vector<std::vector<float>> grouped(3, std::vector<float>(N * 3, kStale));
                    std::vector<Tally> ownT(3), groupT(3);
                    std::vector<const Job*> ptrs;
                    std::vector<float*> phi;
                    for (int i = 0; i < 3; ++i) {
                        ASSERT_EQ(jobs[size_t(i)].axis, axis);
                        ASSERT_EQ(jobs[size_t(i)].sign, 1);
                        sweepStep(m, jobs[size_t(i)], r, own[size_t(i)].data(), ownT[size_t(i)]);
                        ptrs.push_back(&jobs[size_t(i)]);
                        phi.push_back(grouped[size_t(i)].data());
                    }
                    sweepStepGroup(m, ptrs, r, phi, groupT);
                    const Bf16 stale16 = bf16FromFloat(kStale);
                    std::vector<std::vector<Bf16>> grouped16(3, std::vector<Bf16>(N * 3, stale16));
                    std::vector<Bf16*> phi16;
                    for (auto& g : grouped16) phi16.push_back(g.data());
                    std::vector<Tally> group16T(3);
                    sweepStepGroup(m, ptrs, r, phi16, group16T);
                    for (int i = 0; i < 3; ++i) {
                        std::vector<float> want = own[size_t(i)];
                        for (size_t v = 0; v < N; ++v)
                            if (!inBlock[v]) std::fill_n(&want[v * 3], 3, kStale);
                        EXPECT_EQ(want, grouped[size_t(i)])
                            << "layout " << layout << " axis " << axis << " src " << withSrc << " r " << r;
                        size_t rounded = 0;
                        for (size_t k = 0; k < N * 3; ++k) {
                            const std::uint16_t want16 = inBlock[k / 3] ? bf16FromFloat(want[k]).bits : stale16.bits;
                            rounded += grouped16[size_t(i)][k].bits == want16;
                        }
                        EXPECT_EQ(rounded, N * 3) << "bfloat16 layout " << layout << " axis " << axis;
                        EXPECT_EQ(groupT[size_t(i)].scattered[0], group16T[size_t(i)].scattered[0]);
                        EXPECT_EQ(groupT[size_t(i)].escaped[1], group16T[size_t(i)].escaped[1]);
                        for (int c = 0; c < 3; ++c) {
                            EXPECT_EQ(ownT[size_t(i)].injected[c], groupT[size_t(i)].injected[c]);
                            EXPECT_EQ(ownT[size_t(i)].escaped[c], groupT[size_t(i)].escaped[c]);
                            EXPECT_EQ(ownT[size_t(i)].scattered[c], groupT[size_t(i)].scattered[c]);
                        }
                        EXPECT_EQ(ownT[size_t(i)].segments, groupT[size_t(i)].segments);
                    }
                    ++cases;
                }
    }
    EXPECT_EQ(cases, 36);
}

TEST(SweepKernel, GroupRefusesMixedSignsAxesOrSources) {
    const Medium m = randomMedium(9, 9, 9, {1, 1, 1}, false, 2);
    std::vector<float> src(m.voxelCount() * 3, 1.0f);
    const Job a = makeJob({1, 0.2, 0.1}, nullptr, 0.3), b = makeJob({-1, 0.2, 0.1}, nullptr, 0.3),
              c = makeJob({1, 0.1, 0.3}, &src, 0.3), d = makeJob({0.1, 1, 0.2}, nullptr, 0.3);
    std::vector<float> p0(m.voxelCount() * 3, 0.0f), p1 = p0;
    std::vector<Tally> t(2);
    for (const Job* other : {&b, &c, &d})
        EXPECT_THROW(sweepStepGroup(m, {&a, other}, 2, std::vector<float*>{p0.data(), p1.data()}, t), Error);
    EXPECT_THROW(sweepStepGroup(m, {&a, &a}, 2, std::vector<float*>{p0.data()}, t), Error);
}

namespace {

// Two balls of density in a sparse block, their allocated tiles wider than they are, and
// Medium::wantedS on every voxel within one voxel of the density (a bake's shell): many
// chunks of allocated tiles are empty and unread (dead).
Medium ballsWithShell() {
    Medium probe;
    probe.nx = 45, probe.ny = 41, probe.nz = 38;
    std::vector<std::uint8_t> active(size_t(probe.tilesX()) * probe.tilesY() * probe.tilesZ(), 0);
    const double centres[2][3] = {{9.3, 10.1, 8.7}, {35.2, 30.6, 28.9}};
    const double radius = 7.4;
    for (int tz = 0; tz < probe.tilesZ(); ++tz)
        for (int ty = 0; ty < probe.tilesY(); ++ty)
            for (int tx = 0; tx < probe.tilesX(); ++tx)
                for (const auto& c : centres) {
                    const int t[3] = {tx, ty, tz};
                    bool near = true;
                    for (int a = 0; a < 3; ++a)
                        near = near && c[a] + radius + 2 > t[a] * 8.0 && c[a] - radius - 2 < t[a] * 8.0 + 8;
                    if (near)
                        active[size_t(tx) + size_t(probe.tilesX()) * (size_t(ty) + size_t(probe.tilesY()) * tz)] = 1;
                }
    Medium m;
    m.voxelSize = {1, 0.9, 1.1};
    m.albedo = RGB(0.9f, 0.8f, 0.7f);
    m.allocate(probe.nx, probe.ny, probe.nz, &active);
    auto inBall = [&](int x, int y, int z, double grow) {
        for (const auto& c : centres) {
            const double dx = x + 0.5 - c[0], dy = y + 0.5 - c[1], dz = z + 0.5 - c[2];
            if (dx * dx + dy * dy + dz * dz < (radius + grow) * (radius + grow)) return true;
        }
        return false;
    };
    m.wantedS.assign(m.voxelCount(), 0);
    for (int z = 0; z < m.nz; ++z)
        for (int y = 0; y < m.ny; ++y)
            for (int x = 0; x < m.nx; ++x) {
                const size_t v = m.index(x, y, z);
                if (v == Medium::npos) continue;
                if (inBall(x, y, z, 0)) m.sigmaT[v] = float(0.2 + 0.1 * ((x * 7 + y * 3 + z) % 5));
                m.wantedS[v] = inBall(x, y, z, 1.8);  // the density's voxels and a shell around them
            }
    return m;
}

// Deposits of a sweep with wantedS against one without, voxel by voxel: equal where a
// voxel holds extinction or is wanted; elsewhere equal or 0 (a skipped chunk). Returns how
// many deposits were skipped (0 with wantedS, non-zero without).
size_t expectLiveDepositsEqual(const Medium& m, const std::vector<float>& withWanted, const std::vector<float>& without,
                               const std::string& what) {
    size_t skipped = 0, differ = 0, deadDiffer = 0;
    for (size_t v = 0; v < m.voxelCount(); ++v)
        for (int c = 0; c < 3; ++c) {
            const float a = withWanted[v * 3 + c], b = without[v * 3 + c];
            if (m.sigmaT[v] > 0 || m.wantedS[v]) differ += a != b;
            else if (a == 0 && b != 0) ++skipped;
            else deadDiffer += a != b;
        }
    EXPECT_EQ(differ, 0u) << what;
    EXPECT_EQ(deadDiffer, 0u) << what;
    return skipped;
}

}  // namespace

// The sweep skips chunks that hold no extinction and no wanted voxel (docs/performance.md,
// "Dead chunks"): rays cross them unchanged, so every deposit that is read (a voxel with
// extinction, or a wanted one) is bit for bit what the sweep of every chunk gives, and the
// power tallies agree; fewer segments are swept.
TEST(SweepKernel, DeadChunksSkippedWhatIsReadUnchanged) {
    const Medium m = ballsWithShell();
    Medium all = m;
    all.wantedS.clear();
    std::vector<float> src(m.voxelCount() * 3);
    Pcg32 rng(12, 7);
    for (float& x : src) x = float(rng.uniform());
    const std::vector<Vec3> dirs = {{1, 0.8, 0.9}, {-1, -0.7, -0.95}, {0.3, 1, -0.6}, {-0.4, 0.2, 1}};
    const size_t N = m.voxelCount();
    int cases = 0;
    for (int r : {1, 2})
        for (const Vec3& w : dirs)
            for (bool withSrc : {false, true}) {
                const Job job = makeJob(w, withSrc ? &src : nullptr, 0.19 + 0.07 * cases);
                std::vector<float> a(N * 3, 0.0f), b(N * 3, 0.0f);
                Tally ta, tb;
                sweepStep(m, job, r, a.data(), ta);
                sweepStep(all, job, r, b.data(), tb);
                const std::string what = "r " + std::to_string(r) + " case " + std::to_string(cases);
                EXPECT_GT(expectLiveDepositsEqual(m, a, b, what), 0u) << what;
                EXPECT_LT(ta.segments, tb.segments) << what;
                for (int c = 0; c < 3; ++c) {
                    EXPECT_EQ(ta.scattered[c], tb.scattered[c]) << what;
                    EXPECT_EQ(ta.absorbed[c], tb.absorbed[c]) << what;
                    EXPECT_NEAR(ta.injected[c], tb.injected[c], 1e-9 * tb.injected[c]) << what;
                    EXPECT_NEAR(ta.escaped[c], tb.escaped[c], 1e-9 * tb.injected[c]) << what;
                }
                ++cases;
            }
    EXPECT_EQ(cases, 16);
    // A batch (shared planes, jobs of both signs) likewise.
    std::vector<Job> jobs = {makeJob({1, 0.6, 0.3}, &src, 0.21), makeJob({-1, 0.2, -0.5}, &src, 0.47),
                             makeJob({0.9, -0.7, 0.8}, &src, 0.73)};
    std::vector<const Job*> ptrs;
    for (const Job& j : jobs) ptrs.push_back(&j);
    std::vector<float> a(N * 3, 0.0f), b(N * 3, 0.0f);
    Tally ta, tb;
    sweepStepBatch(m, ptrs, 2, a.data(), ta, 0.8f);
    sweepStepBatch(all, ptrs, 2, b.data(), tb, 0.8f);
    EXPECT_GT(expectLiveDepositsEqual(m, a, b, "batch"), 0u);
    EXPECT_LT(ta.segments, tb.segments);
    for (int c = 0; c < 3; ++c) EXPECT_EQ(ta.scattered[c], tb.scattered[c]);
}

// ---- The linear source's fast kernel (sweepStepLinear) against sweepReference<true>.

namespace {

// A linear source of stride 12 (mean, then x, y, z slopes, RGB each): means in [0, 1],
// slopes in [-1/2, 1/2] (the sweep takes any sign; the solver clamps negative ones).
std::vector<float> randomLinearSource(size_t voxels, std::uint64_t seed) {
    std::vector<float> src(voxels * 12);
    Pcg32 rng(seed, 3);
    for (size_t i = 0; i < src.size(); ++i) src[i] = float(i % 12 < 3 ? rng.uniform() : rng.uniform() - 0.5);
    return src;
}

// Largest |fast - ref| per moment (mean, x, y, z), relative to the largest |ref| of the
// mean (a slope moment is a difference of track-length integrals of the mean's size:
// zero slopes, as along an axis, come out as rounding noise in the reference); the
// tallies as compareKernels.
struct LinearCompare {
    double maxRel[4] = {0, 0, 0, 0};
    double tallyRel = 0;
};

LinearCompare compareLinearKernels(const Medium& m, const Job& job, int r) {
    const size_t N = m.voxelCount();
    std::vector<float> ref(N * 12, 0.0f), fast(N * 12, 0.0f);
    Tally tr, tf;
    sweepReference<true>(m, job, r, ref.data(), tr);
    sweepStepLinear(m, job, r, fast.data(), tf);
    LinearCompare c;
    double scale = 1e-30;
    for (size_t v = 0; v < N; ++v)
        for (int ch = 0; ch < 3; ++ch) scale = std::max(scale, double(std::fabs(ref[v * 12 + size_t(ch)])));
    for (int k = 0; k < 4; ++k) {
        double worst = 0;
        for (size_t v = 0; v < N; ++v)
            for (int ch = 0; ch < 3; ++ch) {
                const size_t i = v * 12 + size_t(3 * k + ch);
                worst = std::max(worst, std::fabs(double(fast[i]) - ref[i]));
            }
        c.maxRel[k] = worst / scale;
    }
    c.tallyRel = tallyDifference(tr, tf);
    return c;
}

/// expectMatchesReference for the linear kernel: without a source, with a linear source
/// (slopes), and with the same source read as voxel-constant (no slopes). Returns the
/// number of cases.
int expectLinearMatchesReference(const Medium& m, const std::vector<Vec3>& dirs, std::initializer_list<int> rs,
                                 const std::vector<float>& src12, double offset0, double step) {
    // kinds: no source, linear, constant
    return forEachCase(rs, dirs, 3, offset0, step, [&](int r, const Vec3& w, int kind, double offset) {
        Job job = makeJob(w, nullptr, offset);
        if (kind > 0) {
            job.src = src12.data();
            job.srcStride = 12;
            job.srcScale = RGB(0.8f, 0.7f, 0.6f);
            job.srcLinear = kind == 1;
        }
        const LinearCompare c = compareLinearKernels(m, job, r);
        for (int k = 0; k < 4; ++k)  // measured at most 5e-7 (mean), 7e-6 (slopes)
            EXPECT_LT(c.maxRel[k], k == 0 ? 2e-5 : 5e-5)
                << "moment " << k << " w = " << w.x << "," << w.y << "," << w.z << " r = " << r << " source " << kind;
        EXPECT_LT(c.tallyRel, 2e-5) << "w = " << w.x << "," << w.y << "," << w.z << " r = " << r;
    });
}

}  // namespace

// Every direction family, r = 1..3, dense and sparse storage, non-cubic voxels, optical
// depths from 3e-3 to 30 a voxel (the series, the recurrence and chunks needing both).
TEST(SweepKernelLinear, MatchesReferenceSweep) {
    const std::vector<Vec3> dirs = {{1, 0, 0},       {0, -1, 0},      {0, 0, 1},     {0.9, 0.3, -0.2},   {-0.4, 1, 0.7},
                                    {0.5, -0.5, -1}, {1, 0.999, 0.2}, {-1, -1, 1.0}, {0.05, 0.02, -1.0}, {1, 1e-9, 0}};
    int cases = 0;
    for (bool sparse : {false, true})
        for (int r : {1, 2, 3}) {
            const Medium m = randomMedium(19, 13, 17, sparse ? Vec3{1, 1, 1} : Vec3{0.7, 1.1, 0.9}, sparse, 11 + r);
            const std::vector<float> src = randomLinearSource(m.voxelCount(), 5 + r);
            cases += expectLinearMatchesReference(m, dirs, {r}, src, 0.37 + 0.05 * cases, 0.05);
        }
    EXPECT_EQ(cases, 180);
}

// Media whose chunks all take the series (thin), all the recurrence (thick), or straddle
// tau = 1 lane by lane.
TEST(SweepKernelLinear, ThinThickAndMixedChunksMatchReference) {
    const std::vector<Vec3> dirs = {{1, 0.7, -0.4}, {-0.3, -1, 0.9}, {0.6, 0.2, 1}, {0, 0, -1}};
    int cases = 0;
    struct Range {
        double lo, hi;
        bool alternate;
    };
    for (const Range& range : {Range{1e-4, 0.5, false}, Range{3.0, 8.0, false}, Range{0.05, 4.0, true}}) {
        Medium m;
        m.albedo = RGB(0.8f, 0.7f, 0.6f);
        m.allocate(16, 24, 16);
        Pcg32 rng(17, 9);
        for (size_t x = 0; x < m.sigmaT.size(); ++x)
            m.sigmaT[x] = float(range.alternate ? (x % 2 ? range.hi : range.lo)
                                                : range.lo + (range.hi - range.lo) * rng.uniform());
        cases += expectLinearMatchesReference(m, dirs, {1, 2}, randomLinearSource(m.voxelCount(), 19), 0.21, 0.09);
    }
    EXPECT_EQ(cases, 72);
}

// Empty tile layers and distant blobs in a sparse block: rows crossing empty space with
// their shifts pending, windows moving and growing, as the constant kernel's tests.
TEST(SweepKernelLinear, SparseBlobsMatchReference) {
    Medium probe;
    probe.nx = 45, probe.ny = 40, probe.nz = 36;
    std::vector<std::uint8_t> active(size_t(probe.tilesX()) * probe.tilesY() * probe.tilesZ(), 0);
    auto tile = [&](int tx, int ty, int tz) -> std::uint8_t& {
        return active[size_t(tx) + size_t(probe.tilesX()) * (size_t(ty) + size_t(probe.tilesY()) * tz)];
    };
    tile(0, 0, 0) = tile(1, 0, 0) = tile(0, 1, 0) = 1;
    tile(probe.tilesX() - 1, probe.tilesY() - 1, probe.tilesZ() - 1) = 1;
    tile(probe.tilesX() - 1, 0, probe.tilesZ() / 2) = 1;
    Medium m;
    m.voxelSize = {1, 1.1, 0.9};
    m.albedo = RGB(0.9f, 0.8f, 0.7f);
    m.allocate(probe.nx, probe.ny, probe.nz, &active);
    Pcg32 rng(33, 5);
    for (float& x : m.sigmaT) x = float(3 * rng.uniform());
    const std::vector<Vec3> dirs = {{1, 0.95, 0.9}, {-1, -0.9, -0.97}, {0.2, -0.6, 1}, {-0.7, 0.8, -1}};
    EXPECT_EQ(expectLinearMatchesReference(m, dirs, {1, 2}, randomLinearSource(m.voxelCount(), 23), 0.23, 0.13), 24);
}

// A linear-source group gathers each layer once for its jobs: each job's deposits and
// tally are those of its own sweepStepLinear, bit for bit, assigned over a buffer's stale
// values in the block (the padding keeps them); jobs of another source are refused.
TEST(SweepKernelLinear, GroupEqualsOwnSweepsBitForBit) {
    const Vec3 dirs[3] = {{0.3, -0.2, 1}, {0.1, 0.5, 0.9}, {-0.7, 0.6, 0.8}};
    int cases = 0;
    for (int layout = 0; layout < 3; ++layout) {
        const Medium m = randomMedium(21, 18, 26, {1, 0.8, 1.2}, layout > 0, 41 + layout, layout == 2);
        const std::vector<char> inBlock = blockVoxels(m);
        const size_t N = m.voxelCount();
        const std::vector<float> src = randomLinearSource(N, 31 + layout);
        constexpr float kStale = 7.0f;
        for (int kind : {0, 1, 2})  // no source, linear, constant
            for (int r : {1, 2}) {
                std::vector<Job> jobs;
                for (int i = 0; i < 3; ++i) {
                    jobs.push_back(makeJob(dirs[i], nullptr, 0.17 + 0.23 * i));
                    if (kind > 0) {
                        jobs.back().src = src.data();
                        jobs.back().srcStride = 12;
                        jobs.back().srcLinear = kind == 1;
                    }
                }
                std::vector<std::vector<float>> own(3, std::vector<float>(N * 12, 0.0f));
                std::vector<std::vector<float>> grouped(3, std::vector<float>(N * 12, kStale));
                std::vector<Tally> ownT(3), groupT(3);
                std::vector<const Job*> ptrs;
                std::vector<float*> phi;
                for (size_t i = 0; i < 3; ++i) {
                    sweepStepLinear(m, jobs[i], r, own[i].data(), ownT[i]);
                    ptrs.push_back(&jobs[i]);
                    phi.push_back(grouped[i].data());
                }
                sweepStepLinearGroup(m, ptrs, r, phi, groupT);
                for (size_t i = 0; i < 3; ++i) {
                    std::vector<float> want = own[i];
                    for (size_t v = 0; v < N; ++v)
                        if (!inBlock[v]) std::fill_n(&want[v * 12], 12, kStale);
                    EXPECT_EQ(want, grouped[i]) << "layout " << layout << " source " << kind << " r " << r;
                    for (int c = 0; c < 3; ++c) {
                        EXPECT_EQ(ownT[i].injected[c], groupT[i].injected[c]);
                        EXPECT_EQ(ownT[i].escaped[c], groupT[i].escaped[c]);
                        EXPECT_EQ(ownT[i].scattered[c], groupT[i].scattered[c]);
                    }
                }
                ++cases;
            }
    }
    EXPECT_EQ(cases, 18);
    const Medium m = randomMedium(9, 9, 9, {1, 1, 1}, false, 3);
    const std::vector<float> src = randomLinearSource(m.voxelCount(), 3);
    Job a = makeJob({0.2, 0.1, 1}, nullptr, 0.3), b = a;
    b.src = src.data();
    b.srcStride = 12;
    std::vector<float> pa(m.voxelCount() * 12), pb(pa);
    std::vector<Tally> t(2);
    EXPECT_THROW(sweepStepLinearGroup(m, {&a, &b}, 1, {pa.data(), pb.data()}, t), Error);
}

// A linear-source batch (shared planes, deposits accumulated in place; with 1 ray per
// voxel its sweeps take each layer slice by slice) equals the weighted sum of its jobs' own
// sweeps, both signs of an axis in one batch, with and without a source; its tally and
// segments are theirs.
TEST(SweepKernelLinear, BatchEqualsSumOfSweeps) {
    const Vec3 dirs[4] = {{0.3, -0.2, 1}, {0.1, 0.5, -0.9}, {-0.7, 0.6, 0.8}, {0.4, 0.4, -1}};
    int cases = 0;
    for (int layout = 0; layout < 3; ++layout) {
        const Medium m = randomMedium(21, 18, 26, {1, 0.8, 1.2}, layout > 0, 51 + layout, layout == 2);
        const std::vector<char> inBlock = blockVoxels(m);
        const size_t N = m.voxelCount();
        const std::vector<float> src = randomLinearSource(N, 61 + layout);
        for (int kind : {0, 1})  // no source, linear
            for (int r : {1, 2}) {
                std::vector<Job> jobs;
                for (int i = 0; i < 4; ++i) {
                    jobs.push_back(makeJob(dirs[i], nullptr, 0.19 + 0.21 * i));
                    jobs.back().weight = 0.05 + 0.1 * i;
                    if (kind > 0) {
                        jobs.back().src = src.data();
                        jobs.back().srcStride = 12;
                        jobs.back().srcLinear = true;
                    }
                }
                const float perWeight = 0.7f;
                std::vector<double> sum(N * 12, 0.0);
                Tally ts, tb;
                std::vector<const Job*> ptrs;
                for (const Job& j : jobs) {
                    std::vector<float> own(N * 12, 0.0f);
                    sweepStepLinear(m, j, r, own.data(), ts);
                    for (size_t i = 0; i < own.size(); ++i) sum[i] += double(perWeight) * j.weight * own[i];
                    ptrs.push_back(&j);
                }
                std::vector<float> batch(N * 12, 7.0f);
                LinearBatchDeposits out;
                out.whole = batch.data();
                sweepStepLinearBatch(m, ptrs, r, out, tb, perWeight);
                double scale = 0, worst = 0;
                for (double x : sum) scale = std::max(scale, std::fabs(x));
                for (size_t i = 0; i < N * 12; ++i)
                    if (inBlock[i / 12]) worst = std::max(worst, std::fabs(double(batch[i]) - sum[i]) / scale);
                EXPECT_LT(worst, 1e-5) << "layout " << layout << " source " << kind << " r " << r;
                for (int c = 0; c < 3; ++c) {
                    const double inj = ts.injected[c];
                    EXPECT_NEAR(tb.injected[c], ts.injected[c], 1e-6 * inj);
                    EXPECT_NEAR(tb.escaped[c], ts.escaped[c], 1e-6 * inj);
                }
                EXPECT_EQ(tb.segments, ts.segments);
                ++cases;
            }
    }
    EXPECT_EQ(cases, 12);
}

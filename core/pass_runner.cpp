// A propagation pass: sweeps in batches, deposits folded in job order (core/pass_runner.h).
#include "core/pass_runner.h"

#include <algorithm>
#include <cmath>
#include <type_traits>

#include "core/fold_kernel.h"
#include "core/malloc_policy.h"
#include "core/mass_rows.h"
#include "core/parallel.h"
#include "core/sh_rows.h"
#include "core/simd_clones.h"

namespace lpm {

std::vector<std::vector<const Job*>> sweepBatches(const std::vector<Job>& jobs, int split) {
    auto sameKey = [](const Job& a, const Job& b) {
        return a.axis == b.axis && a.src == b.src && a.srcBf16 == b.srcBf16 && a.srcStride == b.srcStride &&
               a.srcScale.r == b.srcScale.r && a.srcScale.g == b.srcScale.g && a.srcScale.b == b.srcScale.b;
    };
    std::vector<std::vector<const Job*>> keys;
    for (const Job& j : jobs) {
        auto it = std::find_if(keys.begin(), keys.end(), [&](const auto& k) { return sameKey(*k[0], j); });
        if (it == keys.end()) keys.push_back({&j});
        else it->push_back(&j);
    }
    // Within a key, the jobs of sign +1 before those of -1 (each in job order), cut into
    // `split` contiguous parts: with two parts and as many jobs of each sign, a batch holds
    // one sign, so each tile layer is gathered and scattered once for all its jobs (dealt
    // alternately, both signs, every layer twice for half as many).
    for (auto& k : keys) std::stable_partition(k.begin(), k.end(), [](const Job* j) { return j->sign > 0; });
    // Batch s of every key before batch s + 1 of any: the halves of the list that two
    // threads take first then hold one batch of each axis (the axes' costs differ).
    std::vector<std::vector<const Job*>> batches;
    for (int part = 0; part < split; ++part)
        for (const auto& k : keys) {
            const size_t lo = k.size() * size_t(part) / size_t(split), hi = k.size() * size_t(part + 1) / size_t(split);
            if (lo < hi) batches.emplace_back(k.begin() + long(lo), k.begin() + long(hi));
        }
    return batches;
}

namespace {

/// The per-direction coefficients of a batch, each repeated for the 3 channels.
struct FoldCoefs {
    std::vector<float> binC, shC;  ///< [job][bin][rgb], [job][coeff][rgb]
};

/// Voxels [vb, ve) of foldDeposits.
LPM_SIMD_CLONES
void foldDepositRange(size_t vb, size_t ve, const FoldShape& f, bool depositSh, size_t n, const FoldCoefs& k,
                      const std::vector<std::vector<float>>& phi, const std::vector<std::uint8_t>& slopeVoxel,
                      const std::uint32_t* shRow, const std::uint32_t* outRow, float* sh, float* out) {
    const int nb = f.bins, M = f.moments, nc = f.coeffs;
    const size_t perVoxel = size_t(nb) * M * 3;
    for (size_t x = vb; x < ve; ++x) {
        const size_t unRow = outRow ? outRow[x] : x;
        float* un = unRow == MassRows::kNone ? nullptr : &out[unRow * perVoxel];
        const int mx = slopeVoxel.empty() || slopeVoxel[x] ? M : 1;
        const size_t row = shRow ? shRow[x] : x;
        const bool toSh = depositSh && row != ShRows::kNone;
        if (!un && !toSh) continue;
        for (size_t j = 0; j < n; ++j) {
            const float* p = &phi[j][x * 3 * M];  // [moment][rgb]; moment 0 is the mean
            if (p[0] == 0 && p[1] == 0 && p[2] == 0) continue;
            const RgbRepeat rep(p);
            if (toSh) addTimesRgb(&sh[row * nc * 3], &k.shC[j * nc * 3], rep, nc);
            if (!un) continue;  // no mass: the source has no power there
            const float* cj = &k.binC[j * nb * 3];
            if (M == 1) {
                addTimesRgb(un, cj, rep, nb);
                continue;
            }
            for (int d = 0; d < nb; ++d) {
                const float bc = cj[d * 3];
                for (int c = 0; c < 3; ++c) un[d * M * 3 + c] += bc * p[c];
                // Least-squares slope from the first moment: Int xi_k^2 = 1/12.
                for (int k1 = 1; k1 < mx; ++k1)
                    for (int c = 0; c < 3; ++c) un[(d * M + k1) * 3 + c] += 12.0f * bc * p[k1 * 3 + c];
            }
        }
    }
}

/// Folds the deposits phi[j] ([voxel][moment][rgb]) of jobs[0..n) into the SH result
/// ([voxel][coeff][rgb], when depositSh) and the next unshot source `out`
/// ([voxel][bin][moment][rgb]). Voxels outer, jobs inner (in job order, so the sums do not
/// depend on the thread count): a voxel's unshot row stays in L1 across the jobs instead
/// of streaming through memory once per job.
void foldDeposits(const FoldShape& f, bool depositSh, const Job* jobs, size_t n,
                  const std::vector<std::vector<float>>& phi, const std::vector<std::uint8_t>& slopeVoxel,
                  const std::uint32_t* shRow, const std::uint32_t* outRow, std::vector<float>& sh,
                  std::vector<float>& out) {
    const int nb = f.bins, M = f.moments, nc = f.coeffs;
    const size_t N = phi.empty() ? 0 : phi[0].size() / (3 * size_t(M));
    FoldCoefs k;
    k.binC.resize(n * nb * 3);
    k.shC.resize(n * nc * 3);
    for (size_t j = 0; j < n; ++j)
        for (int c = 0; c < 3; ++c) {
            for (int d = 0; d < nb; ++d) k.binC[(j * nb + d) * 3 + c] = float(jobs[j].binCoef[d]);
            for (int s = 0; s < nc; ++s) k.shC[(j * nc + s) * 3 + c] = float(jobs[j].shCoef[s]);
        }
    parallelForChunks(N, 1024, [&](size_t vb, size_t ve) {
        foldDepositRange(vb, ve, f, depositSh, n, k, phi, slopeVoxel, shRow, outRow, sh.data(), out.data());
    });
}

}  // namespace

PassRunner::PassRunner(const Medium& m, FoldShape shape, const std::vector<std::uint8_t>& slopeVoxel,
                       std::vector<float>& sh, const std::uint32_t* shRow, const std::uint32_t* outRow)
    : m_(m), shape_(shape), slopeVoxel_(slopeVoxel), sh_(sh), shRow_(shRow), outRow_(outRow) {
    if (shRow_ && shape_.coeffs == 1) throw Error("PassRunner", "the isotropic fold takes no SH row map");
    if (outRow_ && (shape_.bins == 1 || shape_.moments != 1))
        throw Error("PassRunner", "rows of the next source are for voxel-constant sources of several bins");
}

void PassRunner::releaseBuffers() const {
    buffers_ = std::vector<std::vector<float>>();
    bf16Buffers_ = std::vector<std::vector<Bf16>>();
}

void PassRunner::keepFirstMomentsInFloat() const {
    exactFirstMoments_ = true;
    bf16Buffers_ = std::vector<std::vector<Bf16>>();
}

size_t PassRunner::heldBufferBytes() const {
    size_t bytes = 0;
    for (const auto& b : buffers_) bytes += b.capacity() * sizeof(float);
    for (const auto& b : bf16Buffers_) bytes += b.capacity() * sizeof(Bf16);
    return bytes;
}

template <class T>
std::vector<std::vector<T>>& PassRunner::buffersOf() const {
    if constexpr (std::is_same_v<T, float>) return buffers_;
    else return bf16Buffers_;
}

template <class T>
std::vector<T>& PassRunner::depositBuffer(size_t i, size_t len) const {
    std::vector<T>& b = buffersOf<T>()[i];
    return b.size() == len ? b : assignZeroed(b, len);
}

template <class T>
void PassRunner::reserveBuffers(size_t count, size_t len) const {
    std::vector<std::vector<T>>& buffers = buffersOf<T>();
    if (buffers.size() < count) buffers.resize(count);
    for (size_t i = 0; i < count; ++i) reserveOnHugePages(buffers[i], len);
}

void PassRunner::run(const std::vector<Job>& jobs, int r, Tally& total, bool depositSh, std::vector<float>& out) const {
    if (isotropic(jobs) && shape_.moments == 4) runIsotropicLinear(jobs, r, total, depositSh, out);
    else if (isotropic(jobs)) runIsotropic(jobs, r, total, depositSh, out);
    else runGeneral(jobs, r, total, depositSh, out);
}

// Every job of the isotropic fold must share the SH-per-bin and bin-per-weight ratios.
bool PassRunner::isotropic(const std::vector<Job>& jobs) const {
    if (!((shape_.moments == 1 || shape_.moments == 4) && shape_.bins == 1 && shape_.coeffs == 1)) return false;
    if (jobs.empty()) return true;
    const double ratio = jobs[0].shCoef[0] / jobs[0].binCoef[0], perWeight = jobs[0].binCoef[0] / jobs[0].weight;
    auto near = [](double a, double b) { return std::fabs(a - b) <= 1e-9 * std::fabs(b); };
    for (const Job& j : jobs)
        if (!near(j.shCoef[0] / j.binCoef[0], ratio) || !near(j.binCoef[0] / j.weight, perWeight)) return false;
    return true;
}

std::vector<std::pair<size_t, size_t>> sweepGroups(const Job* jobs, size_t n, int threads, bool linear) {
    std::vector<std::pair<size_t, size_t>> groups;  // [begin, end)
    const auto same = linear ? sameLinearPlanes : samePlanes;
    for (size_t j = 0; j < n; ++j)
        if (groups.empty() || !same(jobs[j], jobs[groups.back().first]) ||
            jobs[j].sign != jobs[groups.back().first].sign)
            groups.push_back({j, j + 1});
        else groups.back().second = j + 1;
    while (groups.size() < size_t(std::max(1, threads))) {
        auto largest = std::max_element(groups.begin(), groups.end(), [](const auto& a, const auto& b) {
            return a.second - a.first < b.second - b.first;
        });
        if (largest == groups.end() || largest->second - largest->first < 2) break;
        const size_t mid = largest->first + (largest->second - largest->first + 1) / 2;
        const size_t end = largest->second;
        largest->second = mid;
        groups.insert(largest + 1, {mid, end});
    }
    return groups;
}

void PassRunner::sweepInBatches(const std::vector<Job>& jobs, const std::vector<size_t>& starts, int r, Tally& total,
                                const std::function<void(size_t)>& before, const BatchFold& fold) const {
    sweepBatchesInto(jobs, starts, r, total, before, fold);
}

void PassRunner::sweepInBatchesBf16(const std::vector<Job>& jobs, const std::vector<size_t>& starts, int r,
                                    Tally& total, const std::function<void(size_t)>& before,
                                    const BatchFoldOf<Bf16>& fold) const {
    if (shape_.moments != 1) throw Error("PassRunner", "bfloat16 deposits are for voxel-constant sources");
    sweepBatchesInto(jobs, starts, r, total, before, fold);
}

template <class T>
void PassRunner::sweepBatchesInto(const std::vector<Job>& jobs, const std::vector<size_t>& starts, int r, Tally& total,
                                  const std::function<void(size_t)>& before, const BatchFoldOf<T>& fold) const {
    const size_t N = m_.voxelCount();
    const int M = shape_.moments;
    for (size_t b = 0; b < starts.size(); ++b) {
        const size_t b0 = starts[b], nbatch = (b + 1 < starts.size() ? starts[b + 1] : jobs.size()) - b0;
        reserveBuffers<T>(nbatch, N * 3 * size_t(M));
        if (before) before(b);
        std::vector<Tally> tallies(nbatch);
        // Jobs that sweep the same planes go as groups (sweepStepGroup), each job's deposits
        // and tally bit-identical to its own sweep, so any grouping gives the same sums (the
        // linear source's: sweepStepLinearGroup).
        const std::vector<std::pair<size_t, size_t>> groups = sweepGroups(&jobs[b0], nbatch, maxThreads(), M == 4);
        parallelForChunks(groups.size(), 1, [&](size_t gb, size_t ge) {
            for (size_t g = gb; g < ge; ++g) {
                const auto [j0, j1] = groups[g];
                std::vector<const Job*> group;
                std::vector<T*> phi;
                for (size_t j = j0; j < j1; ++j) {
                    group.push_back(&jobs[b0 + j]);
                    phi.push_back(depositBuffer<T>(j, N * 3 * size_t(M)).data());
                }
                std::vector<Tally> groupTallies(group.size());
                if constexpr (std::is_same_v<T, float>)
                    if (M == 4) sweepStepLinearGroup(m_, group, r, phi, groupTallies);
                if (M == 1) sweepStepGroup(m_, group, r, phi, groupTallies);
                std::copy(groupTallies.begin(), groupTallies.end(), tallies.begin() + std::ptrdiff_t(j0));
            }
        });
        for (size_t j = 0; j < nbatch; ++j) total.add(tallies[j]);
        fold(&jobs[b0], nbatch, buffersOf<T>());
    }
}

// Sweeps in parallel (one buffer per job), then folds the batch in job order, in parallel
// over voxels. Thread-count independent by construction (and batch-size independent: each
// voxel's sums take the jobs in job order either way). Batches of 8: plume-1M at g = 0.6
// peaked at 1663 MiB with 16, 1522 MiB with 8 or 4, in the same time within this
// machine's noise (docs/performance.md).
void PassRunner::runGeneral(const std::vector<Job>& jobs, int r, Tally& total, bool depositSh,
                            std::vector<float>& out) const {
    const size_t N = m_.voxelCount();
    const size_t batchMem = size_t(512) << 20;
    const size_t maxBatch = std::max<size_t>(1, batchMem / std::max<size_t>(1, N * 3 * shape_.moments * sizeof(float)));
    // The linear source's jobs each deposit into a whole-grid buffer (48 B a voxel): two
    // jobs a thread keep the threads busy with fewer of them (session 41: the 1M smoke at
    // density scale 150 held 6 of 74 MB, peak 843 -> 587 MiB).
    const size_t threadBatch = shape_.moments == 4 ? size_t(2 * maxThreads()) : size_t(8);
    runFilled(jobs, std::min({maxBatch, size_t(8), threadBatch}), r, total, {}, depositSh, out);
}

void PassRunner::runFilled(const std::vector<Job>& jobs, size_t batch, int r, Tally& total,
                           const std::function<void(size_t)>& before, bool depositSh, std::vector<float>& out) const {
    std::vector<size_t> starts;
    for (size_t b0 = 0; b0 < jobs.size(); b0 += std::max<size_t>(1, batch)) starts.push_back(b0);
    sweepInBatches(jobs, starts, r, total, before,
                   [&](const Job* js, size_t n, const std::vector<std::vector<float>>& phi) {
                       foldDeposits(shape_, depositSh, js, n, phi, slopeVoxel_, shRow_, outRow_, sh_, out);
                   });
}

namespace {

// What every job of the isotropic fold shares: band 0 per unit of bin, and the bin
// coefficient per unit of weight (PassRunner::isotropic checks they are shared); and the
// jobs' sweep batches (two per axis and source: one sign each).
struct IsotropicFold {
    double shPerBin = 0;
    float perWeight = 0;
    std::vector<std::vector<const Job*>> batches;
    explicit IsotropicFold(const std::vector<Job>& jobs) : batches(sweepBatches(jobs, 2)) {
        if (jobs.empty()) return;
        shPerBin = jobs[0].shCoef[0] / jobs[0].binCoef[0];
        perWeight = float(jobs[0].binCoef[0] / jobs[0].weight);
    }
};

}  // namespace

// Isotropic bins, SH order 0 and a voxel-constant source: every job folds as one scalar
// (its bin coefficient) times the same pair (1 for the bin, shPerBin for band 0), so jobs
// deposit straight into fixed accumulators: no per-direction buffer and no fold pass.
// The accumulators are the sweep batches (jobs of one axis and one source, one sign a
// batch, in job order: sweepBatches; sweepStepBatch shares their planes), so the sums are
// the same for any thread count.
void PassRunner::runIsotropic(const std::vector<Job>& jobs, int r, Tally& total, bool depositSh,
                              std::vector<float>& out) const {
    const size_t N = m_.voxelCount();
    const IsotropicFold fold(jobs);
    const size_t G = fold.batches.size();
    reserveBuffers(G, N * 3);
    const std::vector<std::vector<float>>& acc = buffers_;
    std::vector<Tally> tallies(G);
    parallelForChunks(G, 1, [&](size_t gb, size_t ge) {
        for (size_t g = gb; g < ge; ++g)
            sweepStepBatch(m_, fold.batches[g], r, depositBuffer(g, N * 3).data(), tallies[g], fold.perWeight);
    });
    for (const Tally& t : tallies) total.add(t);
    parallelForChunks(N * 3, 1 << 14, [&](size_t b, size_t e) {
        for (size_t i = b; i < e; ++i) {
            float sum = 0;
            for (size_t g = 0; g < G; ++g) sum += acc[g][i];
            out[i] += sum;
            if (depositSh) sh_[i] += float(fold.shPerBin * sum);
        }
    });
}

// runIsotropic for the linear source: each batch's 4 moments accumulate in its planes
// (sweepStepLinearBatch); the batches fold into the next source in batch order, each
// added on its own (out += a_g, then the next), so the sums are the same whether the
// batches are swept all at once or, as here, a round of as many as there are threads at
// a time: threads buffers instead of one per batch (6 on a scene with sources, 12 on the
// light pass), each 30 B a voxel: the mean in float, the first moments in bfloat16
// (docs/performance.md, "Session 43"; 48 B in float after keepFirstMomentsInFloat). The
// fold is foldDeposits' for one bin: the mean as it is, the slopes from the first moments
// times 12 (Int xi_k^2 = 1/12) in the voxels that keep slopes, band 0 from the mean.
void PassRunner::runIsotropicLinear(const std::vector<Job>& jobs, int r, Tally& total, bool depositSh,
                                    std::vector<float>& out) const {
    const size_t N = m_.voxelCount();
    const IsotropicFold fold(jobs);
    const size_t round = std::min(size_t(std::max(1, maxThreads())), fold.batches.size());
    const bool exact = exactFirstMoments_;
    const size_t meanLen = N * (exact ? 12 : 3);
    reserveBuffers<float>(round, meanLen);
    if (!exact) reserveBuffers<Bf16>(round, N * 9);
    for (size_t g0 = 0; g0 < fold.batches.size(); g0 += round) {
        const size_t n = std::min(round, fold.batches.size() - g0);
        std::vector<Tally> tallies(n);
        parallelForChunks(n, 1, [&](size_t gb, size_t ge) {
            for (size_t g = gb; g < ge; ++g) {
                float* mean = depositBuffer<float>(g, meanLen).data();
                const LinearBatchDeposits to =
                    exact ? LinearBatchDeposits{mean, nullptr, nullptr}
                          : LinearBatchDeposits{nullptr, mean, depositBuffer<Bf16>(g, N * 9).data()};
                sweepStepLinearBatch(m_, fold.batches[g0 + g], r, to, tallies[g], fold.perWeight);
            }
        });
        for (const Tally& t : tallies) total.add(t);
        parallelForChunks(N, 1 << 12, [&](size_t b, size_t e) {
            for (size_t v = b; v < e; ++v) {
                const bool slopes = slopeVoxel_.empty() || slopeVoxel_[v];
                for (size_t g = 0; g < n; ++g) {
                    const float* a = &buffers_[g][v * (exact ? 12 : 3)];
                    for (int c = 0; c < 3; ++c) {
                        out[v * 12 + size_t(c)] += a[c];
                        if (depositSh) sh_[v * 3 + size_t(c)] += float(fold.shPerBin * a[c]);
                    }
                    const Bf16* first = exact ? nullptr : &bf16Buffers_[g][v * 9];
                    for (int j = 0; j < 9 && slopes; ++j)
                        out[v * 12 + 3 + size_t(j)] += 12.0f * (exact ? a[3 + j] : floatFromBf16(first[j]));
                }
            }
        });
    }
}

}  // namespace lpm

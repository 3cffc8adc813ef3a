// One propagation pass of the solver carried out: a list of sweep jobs (core/sweep.h)
// swept and their deposits folded into the SH result and the next unshot source. Two
// ways, chosen per pass: the isotropic fold (one bin, SH order 0, voxel-constant source),
// where every job's fold is a scalar and batches deposit straight into fixed
// accumulators; and the general fold, per-direction deposits folded voxel by voxel into
// every bin and SH coefficient (docs/performance.md, "Fold"). Both give sums that do not
// depend on the thread count.
#pragma once

#include <cstdint>
#include <functional>
#include <utility>
#include <vector>

#include "core/medium.h"
#include "core/sweep.h"

namespace lpm {

/// Sizes of the per-direction fold: unshot bins, source moments, SH coefficients.
struct FoldShape {
    int bins = 1, moments = 1, coeffs = 1;
};

class PassRunner {
public:
    /// `slopeVoxel`: with a linear source, which voxels keep their slopes (empty: all).
    /// `sh` ([row][coeff][rgb]) receives the SH deposits of passes run with depositSh;
    /// voxel v's row is shRow[v] (core/sh_rows.h: none where it is ShRows::kNone), or v
    /// when shRow is null. The isotropic fold (one coefficient) takes no row map.
    /// `outRow`: where the next source `out` holds voxel v's row (core/mass_rows.h: none
    /// without mass, whose deposits are not folded into it); null: row = voxel. Only for a
    /// voxel-constant source of several bins.
    PassRunner(const Medium& m, FoldShape shape, const std::vector<std::uint8_t>& slopeVoxel, std::vector<float>& sh,
               const std::uint32_t* shRow = nullptr, const std::uint32_t* outRow = nullptr);

    /// Sweeps `jobs` with r rays per voxel; adds their tallies to `total`, their unshot
    /// deposits to `out` ([row][bin][moment][rgb], row = outRow[voxel]) and, with depositSh,
    /// their SH to sh.
    void run(const std::vector<Job>& jobs, int r, Tally& total, bool depositSh, std::vector<float>& out) const;

    /// run() of the general fold in batches of `batch` consecutive jobs, `before(b)` run
    /// before batch b is swept (it fills the sources that batch's jobs read).
    void runFilled(const std::vector<Job>& jobs, size_t batch, int r, Tally& total,
                   const std::function<void(size_t)>& before, bool depositSh, std::vector<float>& out) const;

    /// Whether `jobs` take the isotropic fold.
    bool isotropic(const std::vector<Job>& jobs) const;

    /// Frees the deposit buffers kept from pass to pass (before a phase that needs the memory).
    void releaseBuffers() const;

    /// From now on the linear source's isotropic passes keep their batches' first moments in
    /// float (18 B a voxel more per thread) instead of rounding them to bfloat16: for GMRES,
    /// whose Krylov space needs the pass to be a linear operator (source iteration damps a
    /// rounding; a Krylov basis would carry it). Frees the bfloat16 buffers, which the
    /// float ones replace.
    void keepFirstMomentsInFloat() const;

    /// Bytes of the deposit buffers kept from pass to pass (their capacity).
    size_t heldBufferBytes() const;

    /// Folds one batch's deposits phi[j] ([voxel][moment][rgb]) of jobs[0..n).
    template <class T>
    using BatchFoldOf = std::function<void(const Job* jobs, size_t n, const std::vector<std::vector<T>>& phi)>;
    using BatchFold = BatchFoldOf<float>;
    /// Sweeps `jobs` in batches (batch b: jobs [starts[b], starts[b + 1]), the last to the
    /// end), one deposit buffer per job, in parallel; then `fold` takes the batch. `before(b)`
    /// (may be empty) runs before batch b is swept. Adds the tallies to `total`.
    void sweepInBatches(const std::vector<Job>& jobs, const std::vector<size_t>& starts, int r, Tally& total,
                        const std::function<void(size_t)>& before, const BatchFold& fold) const;
    /// sweepInBatches with every deposit rounded to bfloat16 (core/bf16.h) as its sweep
    /// stores it: half the deposit buffers' memory. Voxel-constant sources only (one moment).
    void sweepInBatchesBf16(const std::vector<Job>& jobs, const std::vector<size_t>& starts, int r, Tally& total,
                            const std::function<void(size_t)>& before, const BatchFoldOf<Bf16>& fold) const;

private:
    template <class T>
    void sweepBatchesInto(const std::vector<Job>& jobs, const std::vector<size_t>& starts, int r, Tally& total,
                          const std::function<void(size_t)>& before, const BatchFoldOf<T>& fold) const;
    /// The deposit buffers of element T (float or Bf16).
    template <class T>
    std::vector<std::vector<T>>& buffersOf() const;
    /// Deposit buffer i (a batch's accumulator or a direction's deposit) of `len` floats for
    /// a sweep that overwrites every stored voxel of the block (sweepStepGroup,
    /// sweepStepBatch and their linear-source twins). The buffers are kept from pass to
    /// pass: allocated and freed every pass, their pages were faulted in again each time (a
    /// fifth of a bake's time, docs/performance.md). Zeroed only when (re)allocated, so
    /// the padding of edge tiles, which no sweep writes, stays 0 while the rest is left
    /// from the last batch (zeroing it for every batch: about 3% of a g = 0.6 bake's CPU).
    template <class T = float>
    std::vector<T>& depositBuffer(size_t i, size_t len) const;
    /// Room for `len` floats in the first `count` buffers, allocated by the calling thread
    /// before the parallel sweeps zero them: a block allocated on a worker would come from
    /// (and go back to) that thread's heap, where it stays resident when freed.
    template <class T = float>
    void reserveBuffers(size_t count, size_t len) const;

    void runGeneral(const std::vector<Job>& jobs, int r, Tally& total, bool depositSh, std::vector<float>& out) const;
    void runIsotropic(const std::vector<Job>& jobs, int r, Tally& total, bool depositSh, std::vector<float>& out) const;
    void runIsotropicLinear(const std::vector<Job>& jobs, int r, Tally& total, bool depositSh,
                            std::vector<float>& out) const;

    const Medium& m_;
    FoldShape shape_;
    const std::vector<std::uint8_t>& slopeVoxel_;
    std::vector<float>& sh_;
    const std::uint32_t* shRow_;
    const std::uint32_t* outRow_;
    mutable std::vector<std::vector<float>> buffers_;
    mutable std::vector<std::vector<Bf16>> bf16Buffers_;
    mutable bool exactFirstMoments_ = false;
};

/// A batch's jobs jobs[0..n) as sweep groups [begin, end) (sweepStepGroup): runs of
/// consecutive jobs that sweep the same planes with one sign, the largest split in halves
/// until there are `threads` groups or none has two jobs. The sums do not depend on the
/// grouping (each job's deposits are those of its own sweep). linear: the linear source's
/// groups (sameLinearPlanes, sweepStepLinearGroup).
std::vector<std::pair<size_t, size_t>> sweepGroups(const Job* jobs, size_t n, int threads, bool linear = false);

/// The jobs grouped into sweep batches (sweepStepBatch): per sweep axis and source (in order
/// of first appearance), the jobs of sign +1 then those of -1, cut into `split` contiguous
/// batches (so with two, one sign each when the signs are balanced); job order within each
/// sign. The grouping depends on the jobs only, never on the thread count.
std::vector<std::vector<const Job*>> sweepBatches(const std::vector<Job>& jobs, int split);

}  // namespace lpm

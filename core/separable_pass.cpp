// The fine passes of a solve with separable sources (core/separable_source.h): sweeps in
// batches of at most 4 jobs of one unshot bin, each bin's source filled from the separable
// form before its jobs are swept, and their deposits folded into the SH result and a
// separable next source. No buffer of bins per fine voxel is allocated.
#include "core/lpm_solve.h"
#include "core/malloc_policy.h"
#include "core/multires.h"

namespace lpm {

LpmSolve::SeparableState::SeparableState(const Medium& fine) : coarse(coarsen(fine)), map(fine, coarse) {}

void LpmSolve::runSeparablePass(const SeparableSource* src, Tally& t, const std::vector<Job>* lightJobs,
                                const HalfBuffer* takeFromNext, const std::vector<float>* takeIsotropic) {
    // 4 deposit buffers of 12 B per voxel in pass 0, 6 B after (8 x 12 B in the full fold)
    constexpr size_t kBatch = 4;
    std::vector<int> jobBin;
    std::vector<Job> binJobs;
    if (src) {
        if (sep_->binSource.empty()) assignZeroed(sep_->binSource, N_ * 3);
        binJobs = jobs_.binJobs(sep_->binSource.data(), m_.albedo, jobBin);
    }
    const std::vector<Job>& jobs = src ? binJobs : *lightJobs;
    std::vector<size_t> starts;
    for (size_t j = 0; j < jobs.size(); ++j)
        if (starts.empty() || j - starts.back() >= kBatch || (src && jobBin[j] != jobBin[j - 1])) starts.push_back(j);
    SeparableFold fold(sep_->map, m_.sigmaT, sep_->binWeight, nc_, shRows_ ? shRows_->map() : nullptr);
    const auto fill = [&](size_t b) { src->fillBin(sep_->map, jobBin[starts[b]], sep_->binSource.data()); };
    if (src)  // the scattering orders after pass 0: their deposits in bfloat16 (core/bf16.h)
        runner_->sweepInBatchesBf16(jobs, starts, r_, t, fill,
                                    [&](const Job* js, size_t n, const std::vector<std::vector<Bf16>>& phi) {
                                        fold.fold(true, js, n, phi, res_.sh);
                                    });
    else  // pass 0 in float: the suns' single scattering is taken out of the SH by the value
          // their own sweep deposits (core/sun_term.h), which a rounded deposit would not match
        runner_->sweepInBatches(jobs, starts, r_, t, nullptr,
                                [&](const Job* js, size_t n, const std::vector<std::vector<float>>& phi) {
                                    fold.fold(true, js, n, phi, res_.sh);
                                });
    // The deposit buffers go before finish() rounds the shape to half precision, which holds
    // its float sum and the rounded copy at once: the fine pass's peak would be there.
    runner_->releaseBuffers();
    sep_->next = fold.finish(takeFromNext, takeIsotropic);
}

}  // namespace lpm

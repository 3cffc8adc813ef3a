// One LPM sweep: a propagation direction swept through the block slice by slice
// (Fattal 2009, sec. 4), depositing each voxel's track-length integral of the radiance.
// docs/lpm_solver.md has the equations; docs/performance.md the fast kernel's design.
//
// Two kernels compute the same thing (and sweepStepLinear, sweepStep's for the linear source):
//   sweepReference: one ray at a time with a double-precision DDA, any source shape
//                   (voxel-constant or linear); the definition the fast kernels are
//                   tested against.
//   sweepStep:      voxel-constant source only. Rays of one lattice class share their
//                   geometry in a slice, so a slice is a few runs of contiguous rays over a
//                   dense plane of the slice's voxels: float32, vectorised (runtime
//                   dispatch to AVX-512 / AVX2), and voxel rows in unallocated (empty) tiles
//                   are skipped, since rays cross them unchanged, as are the chunks at
//                   a row's ends with no extinction and no wanted voxel (Medium::wantedS):
//                   their deposits are 0 instead of the free-space light, nobody reads them.
#pragma once

#include <cstdint>
#include <vector>

#include "core/bf16.h"
#include "core/math.h"
#include "core/medium.h"

namespace lpm {

/// Power bookkeeping of sweeps, per channel (docs/lpm_solver.md, "Scattering orders and energy").
struct Tally {
    double injected[3] = {0, 0, 0}, escaped[3] = {0, 0, 0}, absorbed[3] = {0, 0, 0}, scattered[3] = {0, 0, 0};
    std::uint64_t segments = 0;
    void add(const Tally& o) {
        for (int c = 0; c < 3; ++c) {
            injected[c] += o.injected[c];
            escaped[c] += o.escaped[c];
            absorbed[c] += o.absorbed[c];
            scattered[c] += o.scattered[c];
        }
        segments += o.segments;
    }
    static double mean(const double v[3]) { return (v[0] + v[1] + v[2]) / 3.0; }
};

/// One propagation job: a direction swept through the whole grid, and how its deposit
/// folds into the SH result and the next order's unshot bins.
struct Job {
    Vec3 w;  ///< local unit travel direction
    int axis = 0, sign = 1;
    RGB boundary;                ///< radiance (irradiance for suns) entering through the faces
    double weight = 1;           ///< solid angle of the direction bin (1 for suns)
    const float* src = nullptr;  ///< per-voxel RGB radiance feeding the source, or null
    /// Or the same in bfloat16 (core/bf16.h; a voxel-constant source of stride 3, read by
    /// the fast kernels only): the separable passes' bin source.
    const Bf16* srcBf16 = nullptr;
    size_t srcStride = 3;                 ///< floats between consecutive voxels in src
    bool srcLinear = false;               ///< src also holds the x, y, z slopes (3 RGB triples after the mean)
    RGB srcScale;                         ///< Q_c = sigma_t * srcScale_c * src_c
    double offsetU = 0.5, offsetV = 0.5;  ///< ray-lattice offset within a lattice cell, [0, 1)
    std::vector<double> shCoef;           ///< per SH coefficient: multiplies Phi (includes 1/V)
    std::vector<double> binCoef;          ///< per unshot bin: multiplies Phi (includes 1/V)
    bool hasSource() const { return src || srcBf16; }
};

/// Index of the largest component of w.
int dominantAxis(const Vec3& w);

/// Reference kernel. phi: [stored voxel][moment][rgb], M = Linear ? 4 : 1 moments, added to.
template <bool Linear>
void sweepReference(const Medium& m, const Job& job, int r, float* phi, Tally& tally);

/// Fast kernel for a voxel-constant source: phi [stored voxel][rgb] += depositScale * Phi.
/// Results agree with sweepReference<false> to float rounding (with Medium::wantedS set,
/// at the voxels with extinction or wanted; the skipped dead chunks get nothing); the tally
/// is identical in meaning (it does not include depositScale).
void sweepStep(const Medium& m, const Job& job, int r, float* phi, Tally& tally, float depositScale = 1.0f);

/// Fast kernel for the linear source (docs/performance.md, "Session 42"): sweepStep's geometry and planes with chunks
/// of the linear source (core/linear_segment_lanes.h); phi [stored voxel][mean, x, y, z][rgb] += Phi, as
/// sweepReference<true> adds, agreeing with it to float rounding (with Medium::wantedS
/// set, at the voxels with extinction or wanted). A job without slopes (srcLinear false)
/// sweeps a voxel-constant source and still deposits the 4 moments.
void sweepStepLinear(const Medium& m, const Job& job, int r, float* phi, Tally& tally);

/// Whether two jobs of the linear source's kernel sweep the same planes (one sweep axis,
/// one float source with or without slopes: src, srcStride, srcScale, srcLinear).
bool sameLinearPlanes(const Job& a, const Job& b);

/// sweepStepGroup for the linear source's kernel: jobs of one sweep axis, one sign and
/// one float source (sameLinearPlanes), each layer's planes gathered once for all of
/// them; phi[j] [stored voxel][mean, x, y, z][rgb] and tallies[j] receive exactly what
/// sweepStepLinear of jobs[j] adds to zeros (bit for bit), assigned as sweepStepGroup's.
void sweepStepLinearGroup(const Medium& m, const std::vector<const Job*>& jobs, int r, const std::vector<float*>& phi,
                          std::vector<Tally>& tallies);

/// The sweeps of `jobs`, all with one sweep axis and one voxel-constant source (src,
/// srcStride, srcScale): the jobs of each sign advance together layer by layer, each tile
/// layer's planes (medium, source) gathered once for all of them and their deposits
/// accumulated there (docs/performance.md, "Batched sweeps"):
/// phi [stored voxel][rgb] = depositPerWeight * sum_j weight_j Phi_j, that is sweepStep
/// of each job with depositScale = depositPerWeight * weight_j into zeros, in job order
/// (float rounding differs). phi is assigned, not added to, as in sweepStepGroup: every
/// stored voxel of the block is overwritten, edge tiles' padding left as it is. The tally
/// sums those of the jobs.
void sweepStepBatch(const Medium& m, const std::vector<const Job*>& jobs, int r, float* phi, Tally& tally,
                    float depositPerWeight);

/// Where a linear-source batch writes its sums: with `whole`, all 4 moments there
/// ([stored voxel][mean, x, y, z][rgb], float); else the mean [stored voxel][rgb] in float
/// and the first moments [stored voxel][x, y, z][rgb] rounded to bfloat16 (core/bf16.h;
/// 18 B a voxel instead of 36: docs/performance.md, "Session 43").
struct LinearBatchDeposits {
    float* whole = nullptr;
    float* mean = nullptr;
    Bf16* slopes = nullptr;
};

/// sweepStepBatch for the linear source's kernel (jobs of one sweep axis and one float
/// source, sameLinearPlanes): out = depositPerWeight * sum_j weight_j Phi_j
/// (sweepStepLinear's deposits [mean, x, y, z][rgb]; float rounding differs, and without
/// `whole` each first moment is rounded once to bfloat16 when the batch holds one sign, as
/// sweepBatches' batches do), assigned over the block's stored voxels; the tally sums the
/// jobs'.
void sweepStepLinearBatch(const Medium& m, const std::vector<const Job*>& jobs, int r, LinearBatchDeposits out,
                          Tally& tally, float depositPerWeight);

/// Whether two jobs sweep the same planes (one sweep axis, one voxel-constant source:
/// src, srcStride, srcScale), so a batch or a group can gather them once for both.
bool samePlanes(const Job& a, const Job& b);

/// The sweeps of `jobs`, all with one sweep axis, one sign and one voxel-constant source,
/// each with its own deposits: phi[j] and tallies[j] receive exactly what sweepStep of
/// jobs[j] adds to zeros (bit for bit); each tile layer's planes are gathered once for all
/// of them (a bin's directions in the separable passes, docs/performance.md "Sweep
/// groups"). phi[j] is assigned, not added to: every stored voxel of the block is
/// overwritten, so a buffer need not be zeroed between uses; the stored voxels outside the
/// block (edge tiles' padding) are left as they are.
void sweepStepGroup(const Medium& m, const std::vector<const Job*>& jobs, int r, const std::vector<float*>& phi,
                    std::vector<Tally>& tallies);
/// sweepStepGroup with each deposit rounded to bfloat16 (core/bf16.h) as it is stored:
/// phi[j] is bf16FromFloat of what the float version stores, the tallies the same.
void sweepStepGroup(const Medium& m, const std::vector<const Job*>& jobs, int r, const std::vector<Bf16*>& phi,
                    std::vector<Tally>& tallies);

/// The exponential used by sweepStep: exp(-x) for x >= 0, relative error below 3e-7
/// (measured over [0, 87] in tests/core/sweep_test.cpp), exactly 0 above 87.
float expNeg(float x);

}  // namespace lpm

// The GMRES continuation of a solve (core/gmres.h; docs/lpm_solver.md, "Krylov
// acceleration"): the remaining sum X of sources solves (I - K) X = B, B the last pass's
// scattered source; then one physical pass deposits S from X.
//
// On the coarse grid of a two-grid solve (docs/multires.md) everything GMRES computes is a
// prediction the cycle's next fine residual corrects. With a voxel-constant source of
// several bins, B waits in half precision there, and K is applied to each Krylov vector as
// it is stored: a batch's bins are decoded into float slots before it is swept; and GMRES
// starts from the source sum so far (startFromSourceSum). It then holds X and one product
// in float, beside the half-precision basis and B.
#include <algorithm>
#include <cmath>
#include <cstdio>

#include "core/gmres.h"
#include "core/half_buffer.h"
#include "core/half_source_pass.h"
#include "core/lpm_solve.h"
#include "core/malloc_policy.h"
#include "core/parallel.h"

namespace lpm {

// A v for a Krylov vector v in half precision, K v formed from v as stored, in batches of
// 4 jobs (core/half_source_pass.h).
HalfOperator LpmSolve::basisOperator() {
    halfSlots_.resize(4);
    return [this](const HalfBuffer& v, std::vector<float>& outv) {
        const auto tp = Clock::now();
        std::fill(outv.begin(), outv.end(), 0.0f);
        Tally t;
        propagateHalfSource(*runner_, jobs_, v, nb_, m_.albedo, r_, halfSlots_, t, outv, rows_);
        recordPass(pass_++, t, tp, false);
        parallelForChunks(outv.size(), 1 << 16, [&](size_t b0, size_t e0) {
            for (size_t i = b0; i < e0; ++i) outv[i] = v.at(i) - outv[i];
        });
    };
}

// On the coarse grid GMRES solves for the whole tail T = S + X (S the sources so far):
// (I - K) T = B' with B' = B + (I - K) S, from T_0 = S, so S need not wait beside its
// vectors. One more product, K S (a pass; `sumTally` its tally, which the final pass's
// sweep of T counts again). B' is held in half precision; the first residual is that of
// the rounded system, B'_h - A S, as GMRES's restarts form it.
void LpmSolve::startFromSourceSum(std::vector<float>& B, HalfBuffer& halfB, std::vector<float>& X,
                                  std::vector<float>& firstResidual, Tally& sumTally) {
    const size_t len = B.size();
    X = std::move(res_.sourceSum);
    const auto tp = Clock::now();
    assignZeroed(firstResidual, len);
    propagate(X, sumTally, false, firstResidual);  // K S
    recordPass(pass_++, sumTally, tp, false);
    parallelForChunks(len, 1 << 16, [&](size_t b0, size_t e0) {
        for (size_t i = b0; i < e0; ++i) {
            firstResidual[i] = X[i] - firstResidual[i];  // A S, as the operator forms it
            B[i] += firstResidual[i];
        }
    });
    halfB = HalfBuffer::encode(B);
    B = std::vector<float>();
    parallelForChunks(len, 1 << 16, [&](size_t b0, size_t e0) {
        for (size_t i = b0; i < e0; ++i) firstResidual[i] = halfB.at(i) - firstResidual[i];
    });
}

// The source power that X fails to account for, |B + K X - X| (radiance per bin) times
// sigma_s V w_d, mean over RGB; KX holds K X.
template <class Rhs>
double LpmSolve::unaccounted(const Rhs& B, const std::vector<float>& KX, const std::vector<float>& X) const {
    double miss = 0;
    for (int d = 0; d < nb_; ++d)
        for (size_t x = 0; x < S_; ++x)
            for (int c = 0; c < 3; ++c) {
                const size_t i = (x * nb_ + d) * M_ * 3 + c;
                miss += std::fabs(double(B(i)) + KX[i] - X[i]) * m_.sigmaT[voxelOf(x)] * m_.albedo[c] *
                        ff_->binWeight(d) * V_;
            }
    return miss / 3.0;
}

// The residual norm GMRES stops at. On the fine grid it is the stop test of source
// iteration (LpmSolve::iterate): what X misses is A^-1 R, R = B - (I - K) X the residual,
// and A^-1 = sum_j K^j. K is a non-negative operator and each pass scatters at most the
// largest albedo c of what it propagates, so P(A^-1 R) <= P(R) / (1 - c) in scattered
// power P; the solve stops when that bound is below tol * input. (The per-pass ratio rho
// is no bound: at the switch it can be 0.8 where the slowest mode decays at 0.9999.)
// GMRES measures R in its weighted L2 norm; B's power (the last pass's scattered power)
// converts: |R|_w <= tol * input * (1 - c) / P(B) * |B|_w, never tighter than the fixed
// tenth of the tolerance relative to B used before (and still on the coarse grid of a
// two-grid solve, where what GMRES leaves goes into the cycle's next fine residual, which
// the cycle measures and corrects).
double LpmSolve::gmresTarget(double bNorm, bool coarse) const {
    const double relativeToB = 0.1 * s_.tolerance;
    const double last = res_.passes.back().scattered;
    if (coarse || !(last > 0) || !(res_.input > 0)) return relativeToB * bNorm;
    const double c = std::max({m_.albedo[0], m_.albedo[1], m_.albedo[2]});
    return std::max(relativeToB, s_.tolerance * res_.input * (1.0 - c) / last) * bNorm;
}

// A one-grid solve whose passes decay geometrically (extrapolateTail): the sources still to
// come, next (1 + rho + rho^2 + ...), are swept as one source X = next / (1 - rho), which
// deposits their S. What X misses is measured as GMRES's is: |B + K X - X| with B = next
// = X (1 - rho), i.e. |K X - rho X|, the pass's reported scattered power.
void LpmSolve::finishWithGeometricTail() {
    const auto tp = Clock::now();
    const float f = tailFactor_;
    std::swap(unshot_, next_);
    parallelForChunks(unshot_.size(), 1 << 16, [&](size_t b, size_t e) {
        for (size_t i = b; i < e; ++i) unshot_[i] *= f;
    });
    assignZeroed(next_, perVoxel_ * S_);
    Tally t;
    propagate(unshot_, t, depositSh_, next_);
    recordPass(pass_, t, tp);
    res_.passes.back().scattered = unaccounted([&](size_t i) { return unshot_[i] / f; }, next_, unshot_);
    extrapolatedError_ = -1;  // the measured residual is reported
}

// Remaining sum X = sum_{j >= 1} U_{k+j} solves (I - K) X = B, B = `next`, where K is one
// propagation pass (source -> next unshot), in the inner product <a, b> = sum_d w_d a.b.
void LpmSolve::finishWithGmres() {
    runner_->keepFirstMomentsInFloat();  // K must be linear for the Krylov basis
    const size_t len = next_.size();
    // One voxel's weights (they repeat): slopes enter with the weight of their L2 norm over
    // the voxel (Int xi^2 = 1/12).
    std::vector<double> binW(perVoxel_);
    for (size_t i = 0; i < perVoxel_; ++i)
        binW[i] = ff_->binWeight(int((i / (3 * M_)) % nb_)) * ((i / 3) % M_ == 0 ? 1.0 : 1.0 / 12);
    // B takes next's storage; the previous pass's source is no longer needed. K v is
    // deposited into A v's own storage, then A v = v - K v in place: no buffer for K v.
    std::vector<float> B = std::move(next_);
    unshot_ = std::vector<float>();
    const double bNorm = std::sqrt(weightedDot(binW, B, B));
    // A coarse solve's sum of the sources so far (the two-grid cycle's tail, which is
    // rounded to half anyway) waits in half precision while GMRES holds its vectors; where
    // the source has bins (with one, the vectors are 1/24 the size), GMRES starts from it
    // instead, and B is held in half precision.
    const bool coarse = initialSource_ != nullptr, halfKrylov = coarse && M_ == 1 && nb_ > 1;
    HalfBuffer halfB, heldSum;
    std::vector<float> X, firstResidual;
    Tally sumTally;  // the sweep of the source sum X_0
    if (halfKrylov) startFromSourceSum(B, halfB, X, firstResidual, sumTally);
    else if (coarse) {
        heldSum = HalfBuffer::encode(res_.sourceSum);
        res_.sourceSum = std::vector<float>();
    }
    returnFreedHeapPages();  // GMRES's vectors come next: the fine passes' freed buffers go back
    const LinearOperator A = [&](const std::vector<float>& v, std::vector<float>& outv) {  // A v = v - K v
        const auto tp = Clock::now();
        std::fill(outv.begin(), outv.end(), 0.0f);
        Tally t;
        propagate(v, t, false, outv);
        recordPass(pass_++, t, tp, false);
        parallelForChunks(len, 1 << 16, [&](size_t b0, size_t e0) {
            for (size_t i = b0; i < e0; ++i) outv[i] = v[i] - outv[i];
        });
    };
    // Krylov vectors are the big memory cost: cap their number by the memory budget (the
    // planner's, core/solve_plan.cpp, at most the settings'), down to 3 (core/two_grid.cpp:
    // GMRES(2) took 1.7x the passes). They are held in half precision (core/gmres.h).
    const size_t vecBytes = len * sizeof(std::uint16_t);
    const double basisBytes = std::min(s_.krylovBytes, plan_.krylovBytes);
    const int restart = int(std::clamp<size_t>(size_t(basisBytes / double(std::max<size_t>(1, vecBytes))), 3,
                                               size_t(std::max(4, s_.krylovRestart))));
    const auto budget = [&] { return pass_ < s_.maxOrders; };
    const double target = gmresTarget(bNorm, coarse);
    GmresReport rep;
    if (halfKrylov)
        rep = solveGmres(A, basisOperator(), halfB, binW, target, restart, budget, X, std::move(firstResidual));
    else rep = solveGmres(A, B, binW, target, restart, budget, X);
    halfSlots_ = std::vector<std::vector<float>>();
    // Negative round-off in X would act as a negative source: clamp it.
    for (size_t i = 0; i < len; i += 3 * M_)
        for (int c = 0; c < 3; ++c) X[i + c] = std::max(0.0f, X[i + c]);
    // Final physical pass: deposit S from the whole remaining sum.
    const auto tp = Clock::now();
    assignZeroed(next_, len);                           // GMRES's vectors are freed by now
    if (halfKrylov) assignZeroed(res_.sourceSum, len);  // X holds the whole tail
    else if (coarse) {
        assignZeroed(res_.sourceSum, heldSum.size());
        parallelForChunks(heldSum.size(), 1 << 16, [&](size_t b0, size_t e0) {
            for (size_t i = b0; i < e0; ++i) res_.sourceSum[i] = heldSum.at(i);
        });
        heldSum = HalfBuffer();
    }
    addToSourceSum(X);
    Tally t;
    propagate(X, t, depositSh_, next_);
    for (int c = 0; c < 3; ++c) {  // X_0's part was counted in the passes before GMRES
        t.injected[c] -= sumTally.injected[c];
        t.absorbed[c] -= sumTally.absorbed[c];
        t.escaped[c] -= sumTally.escaped[c];
    }
    recordPass(pass_, t, tp);
    res_.passes.back().scattered = halfKrylov ? unaccounted([&](size_t i) { return halfB.at(i); }, next_, X)
                                              : unaccounted([&](size_t i) { return B[i]; }, next_, X);
    char buf[200];
    std::snprintf(buf, sizeof buf, "GMRES: %d passes (restart %d), relative residual %.3g", rep.matvecs, restart,
                  bNorm > 0 ? rep.residualNorm / bNorm : 0.0);
    res_.decisions.push_back(buf);
    res_.converged = rep.converged;
}

}  // namespace lpm

// The two-grid cycle with its tail from a diffusion solve on the fine grid (diffusion
// synthetic acceleration; core/diffusion_tail.h, docs/performance.md session 49). The
// remaining sum X of sources solves X = B + K X; a cycle solves the diffusion problem of
// its residual r for J and sweeps E = r + omega rho J at full resolution: the pass
// deposits S and returns K E, and r' = K E - omega rho J is the exact residual, whatever
// J is. The factor omega follows the residual: the cycle maps r's signed power P to
// q P, so the next factor omega / (1 - q) would have cancelled it; it is kept within
// [0.5, 1] (the correction overshoots in media with thin wisps, where the residual then
// alternates in sign, and undershoots in clouds, where over-relaxing it stalled the
// absolute residual). Each residual is smoothed by one plain pass, as the coarse cycle's.
// The diffusion problem is solved by CG with a multigrid preconditioner
// (core/diffusion_multigrid.h).
#include <algorithm>
#include <cmath>
#include <cstdio>

#include "core/diffusion_multigrid.h"
#include "core/diffusion_tail.h"
#include "core/lpm_solve.h"
#include "core/malloc_policy.h"
#include "core/parallel.h"

namespace lpm {

namespace {

/// Cycles at most (the coarse cycle's cap with the shaped tail).
constexpr int kMaxDiffusionCycles = 10;
/// The CG's relative residual. The cycle corrects what the diffusion solve misses, but not
/// every miss: with the multigrid at 1e-2 the 1M cumulus at albedo 0.99 (voxels up to
/// optical depth 4) met the signed stop test while its absolute residual grew from cycle 5
/// on (the cap, 22 passes); at 1e-3 and 1e-4 it converged in 13 passes, as Jacobi's CG
/// at 1e-2 had (docs/multires.md, "Diffusion tail").
constexpr double kCgTolerance = 1e-3;
constexpr int kCgMaxIterations = 1000;
/// D at most one voxel edge: thin wisps would otherwise make the matrix ill-conditioned
/// (the 1M smoke's CG did not reach 1e-4 in 2000 iterations uncapped).
constexpr double kDiffusionCap = 1.0;
/// D at least 0.15 voxel edge, 1 / (3 sigma_t) in voxels up to optical depth 2.2: in thicker
/// voxels the discrete transport (a value, or a linear source, per voxel) carries light
/// between neighbours faster than continuum diffusion would, the tail over-corrects the
/// residual's voxel-to-voxel variation, and the correction alternates in sign. Without it
/// a 96^3 cloud at albedo 0.99 and voxels up to optical depth 8 ended its cycles 8.7% from
/// its fixed point (absolute residual 2.6x the input), one at depth 4 stopped at the cap;
/// floors 0.15-0.2 converged every cloud measured (docs/multires.md, "Diffusion tail").
constexpr double kDiffusionFloor = 0.15;

}  // namespace

void LpmSolve::continueWithDiffusion(int firstPass) {
    const auto tp = Clock::now();
    std::vector<float> r = std::move(next_);
    unshot_ = std::vector<float>();
    const size_t per = size_t(nb_) * M_ * 3;
    double cgSeconds = 0;
    // J from r's means (each voxel's first values of its bin-0 row), the operator and its
    // multigrid built for the solve and freed before the fine pass (not held across it:
    // 36 B a stored voxel off the peak). The multigrid: CG 3.0 s instead of Jacobi's 7.6 s
    // on the 1M smoke at albedo 0.99.
    const auto solveDiffusion = [&] {
        const auto tc = Clock::now();
        const DiffusionOperator diffusion(m_, kDiffusionCap, kDiffusionFloor);
        const DiffusionMultigrid multigrid(diffusion);
        DiffusionSolve d = diffusion.solve(r.data(), per, m_.albedo, kCgTolerance, kCgMaxIterations, &multigrid);
        cgSeconds += std::chrono::duration<double>(Clock::now() - tc).count();
        return d;
    };
    int cycles = 0, p = firstPass, cgIterations = 0;
    float omega = 1.0f, lowest = 1.0f;
    Residual left{res_.passes.back().scattered, sourcePower(r, true)};
    for (; cycles < kMaxDiffusionCycles && p < s_.maxOrders; ++cycles) {
        // The pass's buffers go back to the heap before the CG: its vectors take their place
        // (with the Jacobi CG the 1M cumulus at albedo 0.99 peaked at 488 MiB without, 425
        // with; docs/performance.md, session 50).
        runner_->releaseBuffers();
        const double inPower = sourcePower(r);
        const DiffusionSolve d = solveDiffusion();
        cgIterations += d.iterations;
        const auto addTail = [&](std::vector<float>& u, float sign) {
            parallelForChunks(N_, 1 << 14, [&](size_t vb, size_t ve) {
                for (size_t v = vb; v < ve; ++v)
                    for (int c = 0; c < 3; ++c)
                        u[v * per + size_t(c)] += sign * omega * m_.albedo[c] * d.J[v * 3 + size_t(c)];
            });
        };
        addTail(r, 1.0f);  // r now holds E
        sweepInPlace(r, p);
        next_ = std::vector<float>();
        addTail(r, -1.0f);  // r' = K E - omega rho J
        left = {sourcePower(r), sourcePower(r, true)};
        res_.passes.back().scattered = std::fabs(left.power);
        reportCycle(cycles, left);
        if (inPower != 0) omega = float(std::clamp(omega / (1.0 - left.power / inPower), 0.5, 1.0));
        lowest = std::min(lowest, omega);
        if (!cycleConverged(left, true)) left = smoothResidual(r, p);
        if (cycleConverged(left, true)) {
            ++cycles;
            break;
        }
    }
    res_.converged = cycleConverged(left, true);
    recordAbsoluteResidual(left, true);
    res_.stoppedAtCycleCap = !res_.converged && cycles >= kMaxDiffusionCycles && int(res_.passes.size()) < s_.maxOrders;
    char buf[300];
    std::snprintf(buf, sizeof buf,
                  "two-grid: diffusion tail, %d cycle(s) of a diffusion solve and one fine pass, %d CG iterations, "
                  "factor down to %.3g, each residual smoothed by fine passes; source left %.3g of the input "
                  "(absolute %.3g)",
                  cycles, cgIterations, lowest, res_.input > 0 ? std::fabs(left.power) / res_.input : 0.0,
                  res_.input > 0 ? left.absolute / res_.input : 0.0);
    if (s_.progress)
        s_.progress("two-grid: " + std::to_string(std::chrono::duration<double>(Clock::now() - tp).count()) +
                    " s, of which the diffusion solves " + std::to_string(cgSeconds) + " s");
    res_.decisions.push_back(buf);
    continuedOnCoarse_ = true;
}

}  // namespace lpm

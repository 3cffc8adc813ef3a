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
#include <chrono>
#include <cmath>
#include <cstdio>
#include <string>

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

/// What both forms of the cycle share: the diffusion solve of a residual's means (the
/// operator and its multigrid built for each solve and freed after it, not held across the
/// fine pass: 36 B a stored voxel off the peak; the multigrid: CG 3.0 s instead of Jacobi's
/// 7.6 s on the 1M smoke at albedo 0.99) and the factor omega that follows the residual.
class DiffusionTail {
public:
    explicit DiffusionTail(const Medium& m)
        : m_(m), transport_(1.0 - (m.albedo[0] + m.albedo[1] + m.albedo[2]) / 3.0 * m.g) {}
    /// J for the means b (voxel v's channel c at b[v * stride + c]), [voxel][rgb].
    DiffusionSolve solve(const float* b, size_t stride) {
        const auto tc = std::chrono::steady_clock::now();
        const DiffusionOperator diffusion(m_, kDiffusionCap, kDiffusionFloor, transport_);
        const DiffusionMultigrid multigrid(diffusion);
        DiffusionSolve d = diffusion.solve(b, stride, m_.albedo, kCgTolerance, kCgMaxIterations, &multigrid);
        cgSeconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - tc).count();
        cgIterations_ += d.iterations;
        return d;
    }
    /// The tail factor omega rho_c for channel c.
    float scale(int c) const { return omega_ * m_.albedo[c]; }
    /// After a cycle took the signed power inPower to outPower: the next factor.
    void update(double inPower, double outPower) {
        if (inPower != 0) omega_ = float(std::clamp(omega_ / (1.0 - outPower / inPower), 0.5, 1.0));
        lowest_ = std::min(lowest_, omega_);
    }
    /// The solve's line for the result's decisions.
    std::string summary(int cycles, double power, double absolute, double input) const {
        const double left = input > 0 ? std::fabs(power) / input : 0.0;
        const double leftAbsolute = input > 0 ? absolute / input : 0.0;
        char buf[300];
        std::snprintf(buf, sizeof buf,
                      "two-grid: diffusion tail, %d cycle(s) of a diffusion solve and one fine pass, %d CG "
                      "iterations, factor down to %.3g, each residual smoothed by fine passes; source left %.3g of "
                      "the input (absolute %.3g)",
                      cycles, cgIterations_, lowest_, left, leftAbsolute);
        return buf;
    }
    double cgSeconds = 0;

private:
    const Medium& m_;
    double transport_;  ///< sigma_tr / sigma_t = 1 - rho g
    float omega_ = 1.0f, lowest_ = 1.0f;
    int cgIterations_ = 0;
};

}  // namespace

void LpmSolve::continueWithDiffusion(int firstPass) {
    if (sep_) {
        continueWithDiffusionSeparable(firstPass);
        return;
    }
    const auto tp = Clock::now();
    std::vector<float> r = std::move(next_);
    unshot_ = std::vector<float>();
    const size_t per = size_t(nb_) * M_ * 3;
    DiffusionTail tail(m_);
    int cycles = 0, p = firstPass;
    Residual left{res_.passes.back().scattered, sourcePower(r, true)};
    for (; cycles < kMaxDiffusionCycles && p < s_.maxOrders; ++cycles) {
        // The pass's buffers go back to the heap before the CG: its vectors take their place
        // (with the Jacobi CG the 1M cumulus at albedo 0.99 peaked at 488 MiB without, 425
        // with; docs/performance.md, session 50).
        runner_->releaseBuffers();
        const double inPower = sourcePower(r);
        // J from r's means: each voxel's first values of its bin-0 row (one bin here)
        const DiffusionSolve d = tail.solve(r.data(), per);
        const auto addTail = [&](std::vector<float>& u, float sign) {
            parallelForChunks(N_, 1 << 14, [&](size_t vb, size_t ve) {
                for (size_t v = vb; v < ve; ++v)
                    for (int c = 0; c < 3; ++c) u[v * per + size_t(c)] += sign * tail.scale(c) * d.J[v * 3 + size_t(c)];
            });
        };
        addTail(r, 1.0f);  // r now holds E
        sweepInPlace(r, p);
        next_ = std::vector<float>();
        addTail(r, -1.0f);  // r' = K E - omega rho J
        left = {sourcePower(r), sourcePower(r, true)};
        res_.passes.back().scattered = std::fabs(left.power);
        reportCycle(cycles, left);
        tail.update(inPower, left.power);
        if (!cycleConverged(left, true)) left = smoothResidual(r, p);
        if (cycleConverged(left, true)) {
            ++cycles;
            break;
        }
    }
    finishDiffusionCycles(cycles, left, tail.summary(cycles, left.power, left.absolute, res_.input), tail.cgSeconds,
                          tp);
}

// The same cycle with separable fine sources (core/separable_source.h): the tail omega rho J
// is isotropic, held as E's isotropic part (every bin of a fine voxel the same), and taken
// from K E's separable form as the fold finishes (SeparableFold::finish), so r' holds none.
// J solves for r's mean over the bins, m_f / W. With g != 0 the diffusion coefficient is the
// transport one, 1 / (3 sigma_t (1 - rho g)) (DSA for anisotropic scattering corrects the
// isotropic part; the directional error decays by rho g_l a pass).
void LpmSolve::continueWithDiffusionSeparable(int firstPass) {
    const auto tp = Clock::now();
    SeparableSource r = std::move(sep_->next);
    sep_->unshot = SeparableSource();
    DiffusionTail tail(m_);
    int cycles = 0, p = firstPass;
    Residual left{res_.passes.back().scattered, r.absolutePower(m_.sigmaT, m_.albedo, V_)};
    for (; cycles < kMaxDiffusionCycles && p < s_.maxOrders; ++cycles) {
        runner_->releaseBuffers();
        sep_->binSource = std::vector<Bf16>();
        const double inPower = r.power(sep_->map, sep_->binWeight, m_.albedo, V_);
        // The solve is linear: J of the integrals m_f, times 1 / W, is J of the means.
        DiffusionSolve d = tail.solve(r.magnitude.data(), 3);
        parallelForChunks(N_, 1 << 14, [&](size_t vb, size_t ve) {
            for (size_t v = vb; v < ve; ++v)
                for (int c = 0; c < 3; ++c)
                    d.J[v * 3 + size_t(c)] *=
                        sep_->map.parent[v] == FineCoarseMap::kNone ? 0.0f : tail.scale(c) * r.invWeight;
        });
        r.isotropic = std::move(d.J);  // r now holds E
        const auto tf = Clock::now();
        Tally t;
        runSeparablePass(&r, t, nullptr, nullptr, &r.isotropic);  // r' = K E - omega rho J
        recordPass(p++, t, tf);
        r = std::move(sep_->next);
        left = {r.power(sep_->map, sep_->binWeight, m_.albedo, V_), r.absolutePower(m_.sigmaT, m_.albedo, V_)};
        res_.passes.back().scattered = std::fabs(left.power);
        reportCycle(cycles, left);
        tail.update(inPower, left.power);
        if (!cycleConverged(left, true)) left = smoothSeparableResidual(r, p);
        if (cycleConverged(left, true)) {
            ++cycles;
            break;
        }
    }
    finishDiffusionCycles(cycles, left, tail.summary(cycles, left.power, left.absolute, res_.input), tail.cgSeconds,
                          tp);
}

void LpmSolve::finishDiffusionCycles(int cycles, const Residual& left, const std::string& summary, double cgSeconds,
                                     Clock::time_point start) {
    res_.converged = cycleConverged(left, true);
    recordAbsoluteResidual(left, true);
    res_.stoppedAtCycleCap = !res_.converged && cycles >= kMaxDiffusionCycles && int(res_.passes.size()) < s_.maxOrders;
    if (s_.progress)
        s_.progress("two-grid: " + std::to_string(std::chrono::duration<double>(Clock::now() - start).count()) +
                    " s, of which the diffusion solves " + std::to_string(cgSeconds) + " s");
    res_.decisions.push_back(summary);
    continuedOnCoarse_ = true;
}

}  // namespace lpm

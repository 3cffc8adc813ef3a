// Two-grid continuation of the scattering orders (docs/multires.md). The remaining sum X of
// sources solves X = B + K X (B = the current source, K one fine pass). A cycle restricts
// the source r still to be distributed (first B) to the coarse grid, iterates the orders
// there, and takes E = r + (coarse sum of the sources it propagated beyond r, injected
// piecewise constant, which keeps its power) as the sum r gives rise to. One fine pass of
// E deposits S at full resolution; its new residual r' = r + K E - E = K E - tail is what
// the coarse grid got wrong, and the next cycle distributes it, until its power falls
// below the tolerance (at most kMaxCycles cycles). The tail is brought back shaped by the
// first residual (core/tail_shape.h), the coarse solves measure the residual, which
// changes sign between voxels, by its absolute power (docs/multires.md, "Shaped tail").
// Each residual is smoothed by a plain source-iteration pass before the next coarse solve
// ("Smoothing"; not with separable sources).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <optional>

#include "core/held_sh.h"
#include "core/lpm_solve.h"
#include "core/malloc_policy.h"
#include "core/multires.h"
#include "core/parallel.h"
#include "core/separable_source.h"
#include "core/tail_shape.h"

namespace lpm {

namespace {

/// Cycles at most. Three were enough while the tolerance was a share of the light entering
/// the block; as a share of the light the medium takes (stricter where light crosses the
/// block without meeting it) a thick cloud at albedo 0.99 needs a fourth
/// (SeparableSource.ThickHighAlbedoCycleConverges). Each cycle costs one fine pass.
constexpr int kMaxCycles = 5;

/// Cycles at most with the shaped tail, whose residual must also fall in absolute power
/// (kAbsoluteGuard): the 1M-voxel smoke at density scale 150 took 5 at albedo 0.9 and 7
/// at 0.95, and at 0.99 stops at this cap (0.32% left after 8 cycles, 0.24% after 10; the
/// flat tail stopped at 5 there too). 8 left the 1M cumulus at albedo 0.99 and coarse
/// depth 1.2 at 0.105% against a tolerance of 0.1%; it converged in 9. With smoothing
/// (session 47): the smoke 3 cycles at albedo 0.9, 10 at 0.99 (0.14% left), the cumulus 5.
constexpr int kMaxShapedCycles = 10;

int maxCycles(bool shapedTail) { return shapedTail ? kMaxShapedCycles : kMaxCycles; }

/// The coarse solve of a cycle stops once what it has still to distribute is this share
/// of the residual's power (absolute with the shaped tail, signed with the flat one), or
/// the bake's tolerance if that is larger: a cycle removes only a half to four fifths of
/// the residual's absolute power (the coarse and fine operators differ), so solving the
/// coarse grid further buys nothing. At albedo 0.99, solving it to the bake's tolerance
/// left the shaped residual at -1% of the input, cycle after cycle, where 0.1 lets it
/// shrink (docs/multires.md, "Shaped tail"); on the flat tail (session 48) it takes the
/// 1M smoke at g = 0.6 from 0.30% to 0.18% of its converged solve in 26 -> 17 coarse passes.
constexpr double kCoarseShare = 0.1;

/// A cycle ends once its residual's signed power is within the tolerance and, with the
/// shaped tail, its absolute power within this many times it: the shaped tail's residual
/// changes sign between voxels, and on a cloud at albedo 0.99 its signed power fell to
/// 0.07% of the input after one cycle with 41% in absolute power left (band 0 1.9% from
/// the converged solve).
constexpr double kAbsoluteGuard = 10.0;

/// The coarse grid's settings: the fine solve's bins (the restricted source is in them) and
/// rays, the plan's coarse directions, GMRES earlier (coarse passes are cheap next to the
/// fine ones and its Krylov vectors 1/8 the size).
LpmSettings coarseSettings(const LpmSettings& s, const SolvePlan& plan, const std::shared_ptr<LpmCache>& cache,
                           size_t fineStoredVoxels) {
    LpmSettings cs = s;
    cs.multires = 0;
    cs.deltaM = 0;  // the fine medium is already scaled
    cs.cache = cache;
    cs.binsPerFace = plan.binsPerFace;
    cs.raysPerVoxel = cs.raysHigherOrders = plan.raysHigher;
    cs.krylovAfter = std::min(s.krylovAfter, s.coarseKrylovAfter);
    // Its Krylov vectors (half precision): 40 B per fine stored voxel (issue 9's budget is
    // 300 B per active voxel). With one unshot bin that is 40 vectors, with 24 bins (144 B
    // per coarse row with mass, about half the coarse voxels) 3: the 1M-voxel cumulus at
    // g = 0.6, albedo 0.99 peaked at 2839 MiB with 29 float vectors (the former flat 2 GiB)
    // and at 1315 MiB with 4, in 39 s against 41 s; with 3 half vectors (session 22) at
    // 747 MiB against 783 MiB with 4, in 60 coarse passes against 63 (2: 713 MiB, 105
    // passes). Session 27's rows halved the vectors, and the former 64 B gave 5: 551-566
    // MiB in 52 GMRES passes, against 520 MiB in 63 with 3 (session 28; the bake's solve
    // 1.05-1.25x as long in 5 interleaved pairs, its peak now the fine passes').
    cs.krylovBytes = std::min(s.krylovBytes, 40.0 * double(fineStoredVoxels));
    cs.directionsPerFace = plan.coarseDirectionsPerFace;
    cs.sunTerms = false;
    cs.validate();
    return cs;
}

/// The tail's words in the two-grid report.
const char* tailWords(bool shaped, bool smoothed) {
    if (shaped)
        return smoothed ? "shaped by the fine source, each residual smoothed by fine passes"
                        : "shaped by the fine source";
    return smoothed ? "flat, each residual smoothed by fine passes" : "flat";
}

}  // namespace

bool LpmSolve::cycleConverged(const Residual& r, bool shapedTail) const {
    const double line = s_.tolerance * res_.input;
    return std::fabs(r.power) <= line && (!shapedTail || r.absolute <= kAbsoluteGuard * line);
}

void LpmSolve::recordAbsoluteResidual(const Residual& r, bool shapedTail) {
    if (!shapedTail || !(res_.input > 0)) return;
    res_.absoluteResidual = r.absolute / res_.input;
    res_.absoluteLine = kAbsoluteGuard * s_.tolerance;
}

// Iterates the orders of the restricted source `uc` (taken over) on the coarse grid
// (passes numbered from p on); returns the sources it propagated beyond uc (the tail).
// With `rows` (core/mass_rows.h) both are held by those rows; so is the coarse solve's
// every source, unless its plan keeps slopes (a linear source is swept as held, by voxel).
std::vector<float> LpmSolve::coarseOrders(const Medium& mc, LpmSettings& cs, const SolvePlan& coarsePlan,
                                          std::vector<float> uc, const Residual& left, bool shapedTail, int cycle,
                                          int& p, TwoGridCount& count, const MassRows* rows) {
    cs.maxOrders = std::max(1, s_.maxOrders - p);
    const double measure = shapedTail ? left.absolute : std::fabs(left.power);
    const double bakeShare = measure > 0 ? s_.tolerance * res_.input / measure : s_.tolerance;
    cs.tolerance = std::max(bakeShare, kCoarseShare);
    cs.extrapolationTolerance = bakeShare;
    cs.absoluteSourcePower = shapedTail;
    const size_t width = size_t(nb_) * 3;
    const bool byVoxel = rows && coarsePlan.linearSource;
    if (byVoxel) uc = expandRows(*rows, uc, width);
    LpmResult cr = LpmSolve(mc, Lights{}, cs, coarsePlan, cache_, &uc, nullptr, byVoxel ? nullptr : rows).run();
    for (size_t i = 1; i < cr.passes.size(); ++i) {
        PassStats ps = cr.passes[i];
        ps.pass = p++;
        ps.coarse = true;
        res_.passes.push_back(ps);
    }
    count.coarsePasses += int(cr.passes.size()) - 1;
    count.converged = count.converged && cr.converged;
    res_.segments += cr.segments;
    if (cycle == 0)
        for (const std::string& d : cr.decisions) res_.decisions.push_back("coarse grid: " + d);
    return byVoxel ? gatherRows(*rows, cr.sourceSum, width) : std::move(cr.sourceSum);
}

void LpmSolve::reportTwoGrid(const Medium& mc, const LpmSettings& cs, int cycles, const TwoGridCount& count,
                             const Residual& r, bool shapedTail, bool smoothed, Clock::time_point start) {
    res_.converged = count.converged && cycleConverged(r, shapedTail);
    recordAbsoluteResidual(r, shapedTail);
    res_.stoppedAtCycleCap =
        !res_.converged && cycles >= maxCycles(shapedTail) && int(res_.passes.size()) < s_.maxOrders;
    char buf[400];
    std::snprintf(buf, sizeof buf,
                  "two-grid: coarse grid %dx%dx%d (%zu stored voxels) with %d directions per face, %d cycle(s) of "
                  "coarse orders and one fine pass, %d coarse passes, tail %s; source left %.3g of the input "
                  "(absolute %.3g)",
                  mc.nx, mc.ny, mc.nz, mc.voxelCount(), cs.directionsPerFace, cycles, count.coarsePasses,
                  tailWords(shapedTail, smoothed), res_.input > 0 ? std::fabs(r.power) / res_.input : 0.0,
                  res_.input > 0 ? r.absolute / res_.input : 0.0);
    if (s_.progress)
        s_.progress("two-grid: " + std::to_string(std::chrono::duration<double>(Clock::now() - start).count()) + " s");
    res_.decisions.push_back(buf);
    continuedOnCoarse_ = true;
}

void LpmSolve::reportCycle(int cycle, const Residual& left) const {
    if (!s_.progress || !(res_.input > 0)) return;
    char buf[160];
    if (cycle < 0)
        std::snprintf(buf, sizeof buf, "two-grid smoothing pass: residual %.3g of the input (absolute %.3g)",
                      left.power / res_.input, left.absolute / res_.input);
    else
        std::snprintf(buf, sizeof buf, "two-grid cycle %d: residual %.3g of the input (absolute %.3g)", cycle + 1,
                      left.power / res_.input, left.absolute / res_.input);
    s_.progress(buf);
}

void LpmSolve::continueOnCoarse(int firstPass) {
    if (plan_.diffusionTail) {
        continueWithDiffusion(firstPass);
        return;
    }
    if (sep_) {
        continueOnCoarseSeparable(firstPass);
        return;
    }
    const auto tp = Clock::now();
    const Medium mc = coarsen(m_);
    LpmSettings cs = coarseSettings(s_, plan_, cache_, N_);
    const SolvePlan coarsePlan = planSolve(summarizeScene(mc, Lights{}, nullptr, true), cs, maxThreads());
    // Two fine source-sized buffers: r (also holds E during the fine pass) takes next's
    // storage; the source iteration's `unshot` is freed, and so is next during each coarse
    // solve (the peak of an anisotropic bake was there: 24 bins x RGB, 288 B per stored
    // voxel each). The tail (the coarse sources beyond r) stays on the coarse grid: it is
    // added to r before the fine pass and taken from next after it, each fine voxel its
    // coarse parent's value times its weight in the shape (means only; the tail has no slopes).
    std::vector<float> r = std::move(next_);
    unshot_ = std::vector<float>();
    const std::vector<float> shape = plan_.shapedTail ? tailShapeOf(mc, r) : std::vector<float>();
    const bool shaped = !shape.empty();
    int cycles = 0, p = firstPass;
    TwoGridCount count;
    Residual left{res_.passes.back().scattered, sourcePower(r, true)};
    for (; cycles < maxCycles(shaped) && p < s_.maxOrders; ++cycles) {
        runner_->releaseBuffers();  // the coarse solve needs the memory more than the next fine pass its pages
        // The heap's free pages stay (unlike the separable cycle's): giving them back saved
        // 0-15 MiB here for 8k more page faults (docs/performance.md, session 18).
        next_ = std::vector<float>();
        // The restricted source and the coarse result are freed before the fine pass.
        const std::vector<float> tailCoarse =
            coarseOrders(mc, cs, coarsePlan, restrictSource(m_, mc, r, nb_, M_), left, shaped, cycles, p, count);
        addCoarse(m_, mc, tailCoarse, nb_, M_, 1.0f, r, shaped ? &shape : nullptr);  // r now holds E
        sweepInPlace(r, p);  // r = K E; next_ (E) is freed before the next coarse solve
        addCoarse(m_, mc, tailCoarse, nb_, M_, -1.0f, r, shaped ? &shape : nullptr);  // r' = K E - tail
        left = {sourcePower(r), sourcePower(r, true)};
        res_.passes.back().scattered = std::fabs(left.power);
        reportCycle(cycles, left);
        if (!cycleConverged(left, shaped)) left = smoothResidual(r, p);
        if (cycleConverged(left, shaped)) {
            ++cycles;
            break;
        }
    }
    reportTwoGrid(mc, cs, cycles, count, left, shaped, s_.cycleSmoothing > 0, tp);
}

void LpmSolve::sweepInPlace(std::vector<float>& r, int& p) {
    const auto tf = Clock::now();
    assignZeroed(next_, N_ * perVoxel_);
    Tally t;
    runner_->run(sourceJobs(r), r_, t, true, next_);
    recordPass(p++, t, tf);
    std::swap(r, next_);
}

// Post-smoothing of a cycle (docs/multires.md, "Smoothing"): plain source iteration
// on the fine grid, r <- K r, each pass physical (its deposits are S's share of r). The
// residual a coarse correction leaves changes sign between the lit surface and the
// interior (absolute power up to 4x its signed power's input); K, which smooths, takes
// most of that away, and the next coarse solve starts from a smooth residual. Returns the
// new residual's powers.
LpmSolve::Residual LpmSolve::smoothResidual(std::vector<float>& r, int& p) {
    Residual left{sourcePower(r), sourcePower(r, true)};
    for (int k = 0; k < s_.cycleSmoothing && p < s_.maxOrders; ++k) {
        sweepInPlace(r, p);
        next_ = std::vector<float>();
        left = {sourcePower(r), sourcePower(r, true)};
        res_.passes.back().scattered = std::fabs(left.power);
        reportCycle(-1, left);
    }
    return left;
}

// The tail's weights inside each coarse voxel from the first residual r (core/tail_shape.h):
// each fine voxel's strength is the sum of its means over bins and channels.
std::vector<float> LpmSolve::tailShapeOf(const Medium& mc, const std::vector<float>& r) const {
    std::vector<float> strength(N_, 0.0f);
    parallelForChunks(N_, 4096, [&](size_t vb, size_t ve) {
        for (size_t v = vb; v < ve; ++v) {
            double sum = 0;
            for (int d = 0; d < nb_; ++d)
                for (int c = 0; c < 3; ++c) sum += r[(v * nb_ + d) * M_ * 3 + c];
            strength[v] = float(sum);
        }
    });
    return tailShape(m_.sigmaT, coarseParents(m_, mc), mc.voxelCount(), strength);
}

// The same cycle with separable fine sources (core/separable_source.h): r, E and K E are
// held separably, so no fine buffer of bins is ever allocated; the tail is E's coarse
// offset, and r' = K E - tail takes it from K E's coarse shape (r never holds an offset).
// The tail stays flat here: shaped, the part of it beyond its flat value must be taken
// from K E with its own angular shape, and even held so (tried) the cycle's signed residual
// stalled at -0.5% on a thick plume at g = 0.6, per voxel no closer to full resolution
// (docs/multires.md, "Shaped tail").
void LpmSolve::continueOnCoarseSeparable(int firstPass) {
    const auto tp = Clock::now();
    const Medium& mc = sep_->coarse;
    LpmSettings cs = coarseSettings(s_, plan_, cache_, N_);
    const SolvePlan coarsePlan = planSolve(summarizeScene(mc, Lights{}, nullptr, true), cs, maxThreads());
    SeparableSource r = std::move(sep_->next);
    sep_->unshot = SeparableSource();
    int cycles = 0, p = firstPass;
    TwoGridCount count;
    Residual left{res_.passes.back().scattered, r.absolutePower(m_.sigmaT, m_.albedo, V_)};
    for (; cycles < kMaxCycles && p < s_.maxOrders; ++cycles) {
        runner_->releaseBuffers();  // and the bin source: the coarse solve is the peak
        sep_->binSource = std::vector<Bf16>();
        // So does the SH result, which waits with its directional bands in half precision
        // (core/held_sh.h) until the next fine pass adds to it.
        std::optional<HeldSh> heldSh;
        if (nc_ > 1 && !res_.sh.empty()) {
            returnFreedHeapPages();  // the fine pass's freed buffers, before the held copy is written
            heldSh.emplace(res_.sh, nc_);
        }
        returnFreedHeapPages();
        // E = r + tail. The tail is held in half precision (core/half_buffer.h): the same
        // rounded tail is added to E and taken from r', so the rounding moves no energy.
        r.offset.push_back(SeparableSource::holdByBin(
            coarseOrders(mc, cs, coarsePlan, r.restricted(), left, false, cycles, p, count, &sep_->map.coarseRows),
            r.bins));
        if (heldSh) {
            returnFreedHeapPages();    // the coarse solve's freed buffers, before the SH comes back
            heldSh->restore(res_.sh);  // into its own pages (core/held_sh.h)
        }
        const auto tf = Clock::now();
        Tally t;
        // r' = K E - tail, the tail taken from K E's coarse shape as the fold finishes, so
        // r' holds no offset and E never more than its tail (SeparableFold::finish).
        runSeparablePass(&r, t, nullptr, &r.offset.back());
        recordPass(p++, t, tf);
        r = std::move(sep_->next);
        left = {r.power(sep_->map, sep_->binWeight, m_.albedo, V_), r.absolutePower(m_.sigmaT, m_.albedo, V_)};
        res_.passes.back().scattered = std::fabs(left.power);
        reportCycle(cycles, left);
        if (!cycleConverged(left, false)) left = smoothSeparableResidual(r, p);
        if (cycleConverged(left, false)) {
            ++cycles;
            break;
        }
    }
    reportTwoGrid(mc, cs, cycles, count, left, false, s_.cycleSmoothing > 0, tp);
}

// smoothResidual for separable sources: r <- K r, each pass a physical separable pass.
LpmSolve::Residual LpmSolve::smoothSeparableResidual(SeparableSource& r, int& p) {
    Residual left{r.power(sep_->map, sep_->binWeight, m_.albedo, V_), r.absolutePower(m_.sigmaT, m_.albedo, V_)};
    for (int k = 0; k < s_.cycleSmoothing && p < s_.maxOrders; ++k) {
        const auto tf = Clock::now();
        Tally t;
        runSeparablePass(&r, t);
        recordPass(p++, t, tf);
        r = std::move(sep_->next);
        left = {r.power(sep_->map, sep_->binWeight, m_.albedo, V_), r.absolutePower(m_.sigmaT, m_.albedo, V_)};
        res_.passes.back().scattered = std::fabs(left.power);
        reportCycle(-1, left);
    }
    return left;
}

}  // namespace lpm

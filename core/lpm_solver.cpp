// Light Propagation Maps solver. Equations (docs/lpm_solver.md):
//   segment of length l in a voxel with extinction s, tau = s l, T = exp(-tau):
//     L_out = L_in T + Q l phi1(tau)
//     Int L ds = L_in l phi1(tau) + Q l^2 phi2(tau)
//   with phi1 = (1 - e^-tau)/tau, phi2 = (tau - 1 + e^-tau)/tau^2 (no 0/0 at s = 0).
//   A ray of direction i (solid angle w_i, tube cross-section A_perp) deposits
//   Phi_i(x) += A_perp Int L ds; W_i = w_i Phi_i / V is the radiance integrated over bin i.
// What a solve does is decided by the effect planner (core/solve_plan.h); this file carries
// the plan out: pass 0, source iteration, and the hand-over to the two-grid continuation
// (core/two_grid.cpp) or to GMRES (core/gmres.h).
#include "core/lpm_solver.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>

#include "core/delta_m.h"
#include "core/env_binning.h"
#include "core/flush_denormals.h"
#include "core/gmres.h"
#include "core/half_buffer.h"
#include "core/half_source_pass.h"
#include "core/lpm_solve.h"
#include "core/malloc_policy.h"
#include "core/parallel.h"
#include "core/scratch_pool.h"
#include "core/sh_rows.h"
#include "core/subdivide.h"

namespace lpm {

namespace {

/// The power a medium's emission puts in, mean over RGB: 4 pi sum sigma_a L_e V.
double emittedPower(const Medium& m) {
    if (!m.hasEmission()) return 0.0;
    double p = 0;
    for (size_t v = 0; v < m.voxelCount(); ++v)
        for (int c = 0; c < 3; ++c) p += double(m.sigmaT[v]) * (1.0 - m.albedo[c]) * m.emission[v][c];
    return kFourPi * p * m.voxelVolume() / 3.0;
}

double secondsSince(std::chrono::steady_clock::time_point t0) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

std::string format(const char* fmt, double a, double b = 0, double c = 0) {
    char buf[240];
    std::snprintf(buf, sizeof buf, fmt, a, b, c);
    return buf;
}

void validateLights(const Lights& lights) {
    for (const Sun& sun : lights.suns) sun.validate();
}

std::shared_ptr<const EnvBinning> binning(const Medium& m, const Lights& lights, const LpmSettings& s,
                                          LpmCache& cache) {
    if (!lights.env || !(lights.env->integral() > 0)) return nullptr;
    return cache.envBinning(*lights.env, s.directionsPerFace, m.localToWorld.transposed(), s.envHotShare);
}

/// The exact sun term's transmittance (core/sun_term.h): each sun's job of pass 0 swept
/// again with unit irradiance; its deposit per voxel volume is the voxel mean of the
/// beam's transmittance. `jobs` ends with the suns' jobs, in `suns` order (black suns
/// have none); the first `explicitSuns` suns came from the lights, the rest are hot pixels.
void sweepSunTerms(const Medium& m, const std::vector<Sun>& suns, size_t explicitSuns, const std::vector<Job>& jobs,
                   int raysPerVoxel, int moments, double voxelVolume, LpmResult& res) {
    size_t lit = 0;
    for (const Sun& sun : suns) lit += sun.irradiance.isBlack() ? 0 : 1;
    size_t job = jobs.size() - lit;
    for (size_t i = 0; i < suns.size(); ++i) {
        if (suns[i].irradiance.isBlack()) continue;
        Job unit = jobs[job++];
        unit.boundary = RGB(1.0f);
        std::vector<float> phi(m.voxelCount() * 3 * moments, 0.0f);
        Tally ignored;
        if (moments == 4) sweepStepLinear(m, unit, raysPerVoxel, phi.data(), ignored);
        else sweepStep(m, unit, raysPerVoxel, phi.data(), ignored);
        SunTerm t;
        t.toSun = normalize(suns[i].toSun);
        t.irradiance = suns[i].irradiance;
        t.angularDiameterDeg = suns[i].angularDiameterDeg;
        t.fromEnvironment = i >= explicitSuns;
        t.transmittance.resize(m.voxelCount());
        for (size_t v = 0; v < t.transmittance.size(); ++v)
            t.transmittance[v] = float(std::clamp(phi[v * 3 * moments] / voxelVolume, 0.0, 1.0));
        res.sunTerms.push_back(std::move(t));
    }
}

/// Solves on the k-fold subdivided medium and averages S (and the sun terms) back.
LpmResult solveSubdivided(const Medium& m, const Lights& lights, const LpmSettings& s, const SolvePlan& plan) {
    const auto t0 = std::chrono::steady_clock::now();
    const int k = plan.subdivide;
    LpmSettings fs = s;
    fs.subdivide = 1;
    fs.keepShRows = false;  // averaged back voxel by voxel
    const Medium fm = subdivided(m, k);
    LpmResult res = solveLpm(fm, lights, fs);
    res.sh = averageBack(m, fm, k, res.sh, size_t(res.coeffs) * 3);
    for (SunTerm& t : res.sunTerms) t.transmittance = averageBack(m, fm, k, t.transmittance);
    res.decisions.push_back(plan.decisions.front().text());
    res.plan = plan;
    res.seconds = secondsSince(t0);
    return res;
}

/// The solve on m's own voxels (delta-M scaled when planned), its SH result held only for
/// the wanted voxels (core/sh_rows.h): returned so with s.keepShRows, else expanded to
/// one row per stored voxel once the solve's buffers are gone (the solve's peak never
/// holds both).
LpmResult solveUnsubdivided(const Medium& m, const Lights& lights, const LpmSettings& s, const SolvePlan& plan) {
    ShRows rows(m, shCount(plan.shOrder));
    LpmResult res = plan.deltaM
                        ? LpmSolve(deltaMScaled(m, plan.deltaMFraction), lights, s, plan, s.cache, nullptr, &rows).run()
                        : LpmSolve(m, lights, s, plan, s.cache, nullptr, &rows).run();
    if (rows.compact()) {
        releaseScratchPool();
        returnFreedHeapPages();  // the pages kept for the passes' buffers: what follows takes new ones
        if (s.keepShRows) res.shRow = rows.takeMap();
        else rows.expand(res.sh, res.coeffs);
    }
    return res;
}

}  // namespace

LpmSolve::LpmSolve(const Medium& m, const Lights& lights, const LpmSettings& s, const SolvePlan& plan,
                   std::shared_ptr<LpmCache> cache, std::vector<float>* initialSource, const ShRows* shRows,
                   const MassRows* sourceRows)
    : m_(m), lights_(lights), s_(s), plan_(plan), cache_(std::move(cache)), initialSource_(initialSource),
      N_(m.voxelCount()), rows_(sourceRows), S_(sourceRows ? sourceRows->size() : N_), V_(m.voxelVolume()),
      M_(plan.linearSource ? 4 : 1), nb_(0), nc_(shCount(plan.shOrder)), r_(plan.raysSingle), perVoxel_(0),
      shRows_(shRows), quad_(s.directionsPerFace), ff_(cache_->formFactors(s.directionsPerFace, plan.binsPerFace, m.g)),
      jobs_(quad_, *ff_, m.localToWorld, m.voxelVolume(), shCount(plan.shOrder), plan.gOut) {
    nb_ = ff_->binCount();
    perVoxel_ = size_t(nb_) * M_ * 3;
    res_.shOrder = plan.shOrder;
    res_.coeffs = nc_;
    res_.directionCount = quad_.count();
    res_.binCount = nb_;
    res_.decisions = plan.lines();
    // A coarse continuation hands back only its source sum (its plan has SH order 0, "no
    // SH"): its band-0 result, 12 B per coarse voxel, is neither allocated nor folded.
    depositSh_ = initialSource_ == nullptr;
    if (depositSh_) assignZeroed(res_.sh, (shRows_ ? shRows_->count() : N_) * nc_ * 3);
    // Linear source: voxels thicker than linearSourceVoxelCap keep a constant source. In
    // them the fitted slope approaches its bound 6 U0 (all light deposited at one face), the
    // linear profile goes strongly negative and the iteration loses accuracy (white furnace
    // of line depth 500, voxels up to ~60: worst error 0.5% / 0.7% / 1.8% / no convergence
    // with caps 4 / 8 / 16 / none).
    if (plan.linearSource) {
        const double hmax = std::max(m.voxelSize.x, std::max(m.voxelSize.y, m.voxelSize.z));
        slopeVoxel_.resize(N_);
        size_t capped = 0;
        for (size_t x = 0; x < N_; ++x) {
            slopeVoxel_[x] = double(m.sigmaT[x]) * hmax <= s.linearSourceVoxelCap;
            capped += slopeVoxel_[x] ? 0 : 1;
        }
        if (capped)
            res_.decisions.push_back(std::to_string(capped) + " voxels thicker than optical depth " +
                                     format("%g", s.linearSourceVoxelCap) + " keep a constant source");
    }
    // unshot_ (the source of passes 1..) is allocated when pass 1 starts: pass 0 needs only next_.
    if (plan.separableSource) {
        sep_ = std::make_unique<SeparableState>(m);
        for (int d = 0; d < nb_; ++d) sep_->binWeight.push_back(ff_->binWeight(d));
    } else if (!initialSource_ || M_ != 1) {
        assignZeroed(next_, perVoxel_ * N_);  // else the initial source becomes next_ (startFromSource)
    }
    if (rows_ && (!initialSource_ || M_ != 1 || nb_ == 1 || plan.separableSource))
        throw Error("LpmSolve", "sources held by rows are for a coarse continuation's voxel-constant bins");
    runner_ = std::make_unique<PassRunner>(m, FoldShape{nb_, M_, nc_}, slopeVoxel_, res_.sh,
                                           shRows_ ? shRows_->map() : nullptr, rows_ ? rows_->rowOf.data() : nullptr);
    if (initialSource_) assignZeroed(res_.sourceSum, S_ * size_t(nb_) * 3);
}

void LpmSolve::recordPass(int pass, const Tally& t, Clock::time_point start, bool physical) {
    PassStats ps;
    ps.pass = pass;
    ps.krylov = !physical;
    ps.injected = Tally::mean(t.injected);
    ps.absorbed = Tally::mean(t.absorbed);
    ps.escaped = Tally::mean(t.escaped);
    ps.scattered = Tally::mean(t.scattered);
    ps.seconds = secondsSince(start);
    ps.segments = t.segments;
    res_.passes.push_back(ps);
    if (physical) {
        res_.absorbed += ps.absorbed;
        res_.escaped += ps.escaped;
    }
    res_.segments += t.segments;
    if (s_.progress) {
        char buf[200];
        std::snprintf(buf, sizeof buf, "pass %d: scattered %.6g (%.3g of the input), %.2f s", pass, ps.scattered,
                      res_.input > 0 ? ps.scattered / res_.input : 0.0, ps.seconds);
        s_.progress(buf);
    }
}

double LpmSolve::sourcePower(const std::vector<float>& u, bool absolute) const {
    // Fixed runs of voxels added in order: the same sum for any thread count.
    const double p = parallelSumOfChunks(S_, 1 << 12, [&](size_t vb, size_t ve) {
        double part = 0;
        for (size_t v = vb; v < ve; ++v)
            for (int d = 0; d < nb_; ++d)
                for (int c = 0; c < 3; ++c) {
                    const double x = u[(v * nb_ + d) * M_ * 3 + c];
                    part += (absolute ? std::fabs(x) : x) * m_.sigmaT[voxelOf(v)] * m_.albedo[c] * ff_->binWeight(d);
                }
        return part;
    });
    return p * V_ / 3.0;
}

void LpmSolve::propagate(const std::vector<float>& src, Tally& t, bool depositSh, std::vector<float>& out) {
    if (!rows_) {
        runner_->run(sourceJobs(src), r_, t, depositSh, out);
        return;
    }
    if (halfSlots_.empty()) halfSlots_.resize(4);
    propagateRowSource(*runner_, jobs_, src, nb_, m_.albedo, r_, halfSlots_, *rows_, t, out);
}

// Coarse continuation: the sum of every propagated source (means), for the fine pass.
void LpmSolve::addToSourceSum(const std::vector<float>& src, float scale) {
    if (!initialSource_) return;
    parallelForChunks(S_ * size_t(nb_), 4096, [&](size_t b, size_t e) {
        for (size_t i = b; i < e; ++i)
            for (int c = 0; c < 3; ++c) res_.sourceSum[i * 3 + c] += scale * src[i * M_ * 3 + c];
    });
}

// The coarse continuation of a two-grid solve stops early once its passes decay
// geometrically: the sources still to come are taken as next (rho + rho^2 + ...) =
// next rho / (1 - rho), added to the source sum with next (weight 1 / (1 - rho)). Whatever
// that misses goes into the fine residual, which the cycle measures exactly and hands to
// the next cycle (docs/multires.md, "Geometric tail"). The estimate's error is the drift
// of rho through d/drho [rho / (1 - rho)] = 1 / (1 - rho)^2, taken 3 times (the drift
// goes on over the passes skipped: 3x covered it on the 1M plume at g = 0.6); it must be
// within the tolerance (for a coarse solve, the bake's share of its input, though the
// solve itself stops at a tenth: LpmSettings::extrapolationTolerance), and rho at most 0.9
// (nearer 1 GMRES does better). On one grid (no coarse continuation, no separable
// sources) the same test, within a tenth of the tolerance (nothing corrects what the
// series misses there), ends the solve with one last pass of next / (1 - rho)
// (finishWithGeometricTail; docs/lpm_solver.md).
bool LpmSolve::extrapolateTail(double last, double ratio) {
    const size_t n = res_.passes.size();
    const bool oneGrid = !initialSource_ && plan_.coarseFrom == 0 && !sep_;
    const bool allowed = s_.coarseTailExtrapolation && (initialSource_ || oneGrid);
    if (!allowed || n < 4 || !(ratio > 0 && ratio <= 0.9)) return false;
    const double before = res_.passes[n - 3].scattered;
    if (!(before > 0)) return false;
    const double drift = std::fabs(ratio - res_.passes[n - 2].scattered / before);
    const double error = 3.0 * last * drift / ((1.0 - ratio) * (1.0 - ratio));
    const double share = initialSource_ ? 1.0 : 0.1;
    const double tolerance = s_.extrapolationTolerance > 0 ? s_.extrapolationTolerance : s_.tolerance;
    if (!(error <= share * tolerance * res_.input)) return false;
    tailFactor_ = float(1.0 / (1.0 - ratio));
    extrapolatedError_ = error;
    finishWithTail_ = !initialSource_;
    char buf[260];
    std::snprintf(buf, sizeof buf,
                  "geometric tail after pass %d: energy ratio per pass %.4f (drift %.2g), the sources still to come "
                  "(%.3g of the input) added as that series; estimated error %.2g of the input",
                  pass_ - 1, ratio, drift, last * ratio / (1.0 - ratio) / res_.input, error / res_.input);
    res_.decisions.push_back(buf);
    return true;
}

// The restricted source of a coarse continuation replaces pass 0. It is not part of the
// source sum (the two-grid cycle wants what it gives rise to beyond itself).
void LpmSolve::startFromSource() {
    double power = 0;
    for (size_t x = 0; x < S_; ++x)
        for (int d = 0; d < nb_; ++d)
            for (int c = 0; c < 3; ++c) {
                const float u = (*initialSource_)[(x * nb_ + d) * 3 + c];
                if (M_ != 1) next_[(x * nb_ + d) * M_ * 3 + c] = u;
                power += (s_.absoluteSourcePower ? std::fabs(double(u)) : double(u)) * m_.sigmaT[voxelOf(x)] *
                         m_.albedo[c] * ff_->binWeight(d) * V_;
            }
    if (M_ == 1) next_ = std::move(*initialSource_);
    res_.injected = res_.input = power / 3.0;
    PassStats ps;
    ps.injected = ps.scattered = res_.injected;
    res_.passes.push_back(ps);
}

// Pass 0: external light (environment through the boundary, emission, suns and hot pixels).
void LpmSolve::passZero() {
    const auto tp = Clock::now();
    std::vector<RGB> envBin(quad_.count(), RGB(0.f));
    std::vector<Sun> suns = lights_.suns;
    if (const std::shared_ptr<const EnvBinning> binned = binning(m_, lights_, s_, *cache_)) {
        envBin = binned->radiance;
        suns.insert(suns.end(), binned->hotSuns.begin(), binned->hotSuns.end());
    }
    const std::vector<Job> jobs = jobs_.lightJobs(m_, envBin, plan_.environmentPass || plan_.emissionPass, suns);
    Tally t;
    if (sep_) runSeparablePass(nullptr, t, &jobs);
    else runner_->run(jobs, r_, t, true, next_);
    res_.injected = Tally::mean(t.injected);
    res_.input = Tally::mean(t.absorbed) + Tally::mean(t.scattered) + (plan_.emissionPass ? emittedPower(m_) : 0.0);
    if (s_.sunTerms) {
        const auto ts = Clock::now();
        sweepSunTerms(m_, suns, lights_.suns.size(), jobs, r_, M_, V_, res_);
        res_.sunTermSeconds = secondsSince(ts);
    }
    recordPass(0, t, tp);
}

// Passes 1..: propagate what the previous pass scattered (source iteration). Stops on the
// estimated energy still to come: the last pass's scattered power times the geometric tail
// rho / (1 - rho) of the per-pass ratio (at least 1x). Returns true when the per-pass
// ratio shows that plain iteration would need many more passes (albedo near 1, thick
// media) and GMRES is to solve for the remaining sum.
bool LpmSolve::iterate() {
    for (;; ++pass_) {
        const double last = res_.passes.back().scattered;
        const double prevP = res_.passes.size() >= 2 ? res_.passes[res_.passes.size() - 2].scattered : 0.0;
        const double ratio = prevP > 0 ? last / prevP : 0.0;
        const double tail = last * std::max(1.0, ratio < 1.0 ? ratio / (1.0 - ratio) : 1e9);
        if (res_.input <= 0 || tail <= s_.tolerance * res_.input || extrapolateTail(last, ratio)) {
            res_.converged = true;
            return false;
        }
        if (pass_ >= s_.maxOrders) return false;
        if (plan_.coarseFrom > 0 && pass_ == plan_.coarseFrom) {
            continueOnCoarse(pass_);
            return false;
        }
        if (plan_.krylov && !sep_ && pass_ >= 4 && ratio > 0.8 && ratio < 1.0) {
            // Passes j until the stop test above holds: last ratio^j rho/(1-rho) <= tol input.
            const double more =
                std::log(s_.tolerance * res_.input / (last * (ratio / (1.0 - ratio)))) / std::log(ratio);
            if (more > plan_.krylovAfter) {
                char buf[240];
                std::snprintf(buf, sizeof buf,
                              "Krylov (GMRES) acceleration after pass %d: energy ratio per pass %.4f, plain source "
                              "iteration would need about %.0f more passes",
                              pass_ - 1, ratio, more);
                res_.decisions.push_back(buf);
                return true;
            }
        }
        const auto tp = Clock::now();
        Tally t;
        if (sep_) {
            sep_->unshot = std::move(sep_->next);
            runSeparablePass(&sep_->unshot, t);
        } else {
            std::swap(unshot_, next_);
            assignZeroed(next_, perVoxel_ * S_);
            if (pass_ > 1 || !initialSource_) addToSourceSum(unshot_);  // not the initial source
            propagate(unshot_, t, depositSh_, next_);
        }
        recordPass(pass_, t, tp);
        if (s_.absoluteSourcePower && !sep_) res_.passes.back().scattered = sourcePower(next_, true);
    }
}

// A linear source can dip below zero in a voxel's corners (no slope limiter: one would
// break the scheme's linearity, and with it GMRES and the exact white furnace). Voxel
// averages stay non-negative in every measured case; any that does not is clamped to
// zero and reported. The result's rows are the held ones (core/sh_rows.h: the wanted
// voxels' when compact), so only values the caller reads are counted.
void LpmSolve::clampNegativeLinear() {
    size_t clamped = 0;
    const size_t width = size_t(nc_) * 3, rows = res_.sh.size() / width;
    for (size_t row = 0; depositSh_ && row < rows; ++row)
        for (size_t c = 0; c < 3; ++c)
            if (res_.sh[row * width + c] < 0) {
                res_.sh[row * width + c] = 0;
                ++clamped;
            }
    if (clamped)
        res_.decisions.push_back("warning: " + std::to_string(clamped) +
                                 " negative band-0 values from the linear source clamped to zero");
}

LpmResult LpmSolve::run() {
    const auto t0 = Clock::now();
    if (initialSource_) startFromSource();
    else passZero();
    r_ = plan_.raysHigher;
    const bool gmres = iterate();
    if (gmres) finishWithGmres();
    else if (finishWithTail_) finishWithGeometricTail();
    else if (!continuedOnCoarse_ && (pass_ > 1 || !initialSource_))
        addToSourceSum(next_, tailFactor_);  // the remainder not propagated (unless it is the initial source)
    if (plan_.linearSource) clampNegativeLinear();
    res_.unshot = extrapolatedError_ >= 0 ? extrapolatedError_ : res_.passes.back().scattered;
    res_.residual = res_.input > 0 ? res_.unshot / res_.input : 0.0;
    char buf[200];
    std::snprintf(buf, sizeof buf, "%s after %d passes: residual %.3g (tolerance %.3g)",
                  res_.converged           ? "converged"
                  : res_.stoppedAtCycleCap ? "stopped at the two-grid cycle cap"
                                           : "stopped at the order cap",
                  int(res_.passes.size()), res_.residual, s_.tolerance);
    res_.decisions.push_back(buf);
    res_.plan = plan_;
    res_.seconds = secondsSince(t0);
    return std::move(res_);
}

SolvePlan planLpm(const Medium& m, const Lights& lights, const LpmSettings& s) {
    s.validate();
    std::shared_ptr<LpmCache> cache = s.cache ? s.cache : std::make_shared<LpmCache>();
    const std::shared_ptr<const EnvBinning> binned = binning(m, lights, s, *cache);
    return planSolve(summarizeScene(m, lights, binned.get(), false), s, maxThreads());
}

const float* LpmResult::shAt(size_t voxel) const {
    if (shRow.empty()) return &sh[voxel * size_t(coeffs) * 3];
    const std::uint32_t row = shRow.at(voxel);
    return row == ShRows::kNone ? nullptr : &sh[size_t(row) * size_t(coeffs) * 3];
}

void LpmResult::expandSh() {
    expandShRows(sh, shRow, coeffs);
    shRow = std::vector<std::uint32_t>();
}

LpmResult solveLpm(const Medium& m, const Lights& lights, const LpmSettings& settings) {
    const FlushDenormals flush;  // as every parallel task does (core/flush_denormals.h)
    m.validate();
    validateLights(lights);
    LpmSettings s = settings;
    if (!s.cache) s.cache = std::make_shared<LpmCache>();
    const SolvePlan plan = planLpm(m, lights, s);
    LpmResult res;
    if (plan.subdivide > 1) res = solveSubdivided(m, lights, s, plan);
    else res = solveUnsubdivided(m, lights, s, plan);
    releaseScratchPool();  // the sweeps' ray-row arenas: what runs next (the write) needs the memory
    return res;
}

}  // namespace lpm

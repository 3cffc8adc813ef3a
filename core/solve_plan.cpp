// The effect planner (core/solve_plan.h, docs/solve_plan.md). Each plan* function below
// makes one kind of decision, from the summary and the settings only.
#include "core/solve_plan.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <string>

#include "core/env_binning.h"
#include "core/medium.h"
#include "core/optical_size.h"
#include "core/quadrature.h"
#include "core/sh.h"

namespace lpm {

namespace {

std::string format(const char* fmt, double a = 0, double b = 0, double c = 0, double d = 0, double e = 0) {
    char buf[320];
    std::snprintf(buf, sizeof buf, fmt, a, b, c, d, e);
    return buf;
}

/// Issue 9's memory line (target 5): 300 B a written voxel + 200 MiB.
constexpr double kMemoryLinePerVoxel = 300;
constexpr double kMemoryLineBase = 200.0 * 1024 * 1024;
/// What a bake takes beside the solve's buffers (libraries, the grids read, the binned
/// environment): 65.6 MiB peak for the bundled fire at albedo 0.3 and g = 0, whose buffers
/// the planner predicts at 3 MiB.
constexpr double kProcessBytes = 64.0 * 1024 * 1024;

std::string dims(int k) { return std::to_string(k) + "x" + std::to_string(k) + "x" + std::to_string(k); }

/// Mean ray segments a ray makes per voxel slice it crosses, over the directions of an
/// n x n-per-face quadrature: 1 + (|w_u| + |w_v|) / |w_axis|.
double segmentsPerSlice(int n) {
    const CubeQuadrature quad(n);
    double sum = 0;
    for (int i = 0; i < quad.count(); ++i) {
        const Vec3& w = quad.dir(i);
        const int a = CubeQuadrature::faceAxis(quad.face(i));
        sum += (std::fabs(w.x) + std::fabs(w.y) + std::fabs(w.z)) / std::fabs(w[a]);
    }
    return sum / quad.count();
}

void planSubdivision(SceneSummary& scene, const LpmSettings& s, SolvePlan& plan) {
    plan.subdivide = s.subdivide;
    if (s.subdivide == 1) return;
    const int k = s.subdivide;
    for (int& d : scene.dims) d *= k;
    scene.storedVoxels *= size_t(k) * k * k;
    scene.wantedVoxels = scene.storedVoxels;  // the split medium holds S everywhere (it is averaged back)
    scene.maxVoxelTau /= k;
    plan.decisions.push_back(
        {"solved on voxels split " + dims(k) + " and averaged back",
         "requested (--subdivide): the medium is the same, the voxels " + std::to_string(k) + "x thinner optically"});
}

/// Delta-M (Wiscombe 1977) with f = g^4 (core/delta_m.h): the propagation then sees the
/// scaled medium; S keeps the true phase function's g.
void planDeltaM(SceneSummary& scene, const LpmSettings& s, SolvePlan& plan) {
    plan.gOut = plan.gPropagation = scene.g;
    if (scene.continuation || s.deltaM == 0 || scene.g <= 0) return;
    if (s.deltaM < 0 && !(scene.g > s.deltaMAbove)) return;
    const RGB& a = scene.albedo;
    if (!(a.r == a.g && a.g == a.b)) {
        plan.decisions.push_back(
            {"no delta-M", "the albedo is not grey (the scaled extinction would differ per channel)"});
        return;
    }
    const double g = scene.g, f = g * g * g * g, c = a.r, k = 1 - c * f;
    plan.deltaM = true;
    plan.deltaMFraction = f;
    plan.gPropagation = (g - f) / (1 - f);
    scene.maxVoxelTau *= k;
    scene.opticalSize *= k;
    plan.decisions.push_back(
        {format("delta-M forward-peak truncation (g = %.4g > %.3g)", g, s.deltaM > 0 ? 0.0 : s.deltaMAbove),
         format("f = g^4 = %.4g of scattering treated as unscattered; propagation with g' = %.4g, albedo %.4g, "
                "extinction x %.4g",
                f, plan.gPropagation, c * (1 - f) / k, k)});
}

/// SH order of the result and the unshot bins of the propagation.
void planAngular(const SceneSummary& scene, const LpmSettings& s, SolvePlan& plan) {
    plan.shOrder = s.shOrder;
    if (scene.continuation) {
        plan.shOrder = 0;
        plan.decisions.push_back({"no SH", "the coarse grid's S is not kept (two-grid continuation)"});
    } else if (plan.gOut == 0.0 && s.shOrder > 0) {
        plan.shOrder = 0;
        plan.decisions.push_back(
            {"SH order 0", "the phase function is isotropic (g = 0), so S has no directional part"});
    }
    // At order >= 1 the SH rows are held only for the wanted voxels (core/sh_rows.h).
    const size_t rows = scene.wantedVoxels > 0 ? scene.wantedVoxels : scene.storedVoxels;
    const double shBytes = double(rows) * shCount(plan.shOrder) * 3 * sizeof(float);
    if (plan.shOrder > 0) {
        std::string why = format("g = %.4g: S depends on the viewing direction", plan.gOut);
        if (rows < scene.storedVoxels)
            why += "; held for the " + std::to_string(rows) + " voxels written of " +
                   std::to_string(scene.storedVoxels) + " stored";
        plan.decisions.push_back({"SH order " + std::to_string(plan.shOrder), why, -1, shBytes});
    }
    plan.binsPerFace = s.binsPerFace;
    if (s.binsPerFace >= 0) return;
    // Bins must nest the direction texels (b divides n), or a direction straddling a bin
    // edge is given to one side and the scattered light is skewed. Even n: 2x2 per face;
    // n = 1 or 3: one bin per direction; larger odd n: 1 per face, which is coarse for
    // forward scattering (measured in docs/accuracy.md).
    const int n = s.directionsPerFace;
    plan.binsPerFace = plan.gPropagation == 0.0 ? 0 : (n % 2 == 0 ? 2 : (n <= 3 ? n : 1));
    const int b = plan.binsPerFace;
    plan.decisions.push_back(plan.gPropagation == 0.0 ? PlanDecision{"one isotropic unshot bin", "g = 0"}
                                                      : PlanDecision{std::to_string(b) + "x" + std::to_string(b) +
                                                                         " unshot bins per cube face",
                                                                     format("g = %.4g", plan.gPropagation)});
}

/// With unshot bins (g != 0) a linear source holds 4 moments in every bin of its two fine
/// sources (it has no separable form): 2 x bins x 48 B a stored voxel, 3.3 GiB on a 1M
/// plume at g = 0.6, with 6-10x the constant source's time, for the same image
/// (docs/performance.md, "Session 44"). Returns why the auto choice keeps the constant
/// source (those sources over the memory line of issue 9's target 5, 300 B a written voxel
/// + 200 MiB), or "" where the linear source fits.
std::string linearSourceTooLarge(const SceneSummary& scene, const SolvePlan& plan) {
    const double bins = plan.binsPerFace == 0 ? 1 : 6.0 * plan.binsPerFace * plan.binsPerFace;
    const double N = double(scene.storedVoxels), wanted = double(scene.wantedVoxels ? scene.wantedVoxels : N);
    const double sourceBytes = 2 * N * bins * 4 * 3 * sizeof(float);
    const double line = kMemoryLinePerVoxel * wanted + kMemoryLineBase;
    if (bins == 1 || sourceBytes <= line) return "";
    constexpr double MiB = 1024.0 * 1024.0;
    return format(
        ", but a linear source would hold 4 moments in each of %.0f unshot bins: %.0f MiB of sources over "
        "the memory line of %.0f MiB (%.0f B a written voxel + %.0f MiB), at 6-10x the time (--source "
        "linear forces it)",
        bins, sourceBytes / MiB, line / MiB, kMemoryLinePerVoxel, kMemoryLineBase / MiB);
}

/// Why auto chose the source shape: the voxels' optical depth and, with one unshot bin at
/// albedo diffusionTailAlbedo and above, the medium's depth in diffusion lengths.
std::string sourceShapeReason(const SceneSummary& scene, const LpmSettings& s, bool thick, bool deep, bool deepApplies,
                              double diffusive) {
    if (thick) return format("largest voxel optical depth %.3g > %.3g", scene.maxVoxelTau, s.linearSourceAbove);
    const std::string voxels =
        format("largest voxel optical depth %.3g <= %.3g", scene.maxVoxelTau, s.linearSourceAbove);
    if (!deepApplies || scene.opticalSize <= 0) return voxels;
    return voxels + format(deep ? ", but times the medium's %.3g diffusion lengths across %.3g >= %g: the voxel-"
                                  "constant source's error compounds with depth"
                                : " and times the medium's %.3g diffusion lengths across %.3g < %g",
                           diffusive / std::max(scene.maxVoxelTau, 1e-30), diffusive, s.linearSourceDiffusive);
}

/// Source shape inside a voxel. A voxel-constant (step) source leaks light across
/// optically thick voxels (it is carried to the exit face undamped); a linear source with
/// deposited first moments follows the decay inside the voxel (docs/lpm_solver.md). Auto:
/// linear in voxels thicker than linearSourceAbove, or where the step source's error
/// compounds with depth: nearly conservative media (albedo from diffusionTailAlbedo, one
/// unshot bin) whose voxel depth times their size in diffusion lengths reaches
/// linearSourceDiffusive, where light reaches the inside by diffusing through many voxels
/// (docs/accuracy.md, "Large media": a 1M cumulus at albedo 0.99, voxels up to 1.2, 133
/// optical depths across, was 24% per voxel from MC with the constant source, 5.9% with
/// the linear one).
void planSourceShape(const SceneSummary& scene, const LpmSettings& s, SolvePlan& plan) {
    const double tau = scene.maxVoxelTau;
    const double albedo = std::max({scene.albedo[0], scene.albedo[1], scene.albedo[2]});
    const double diffusive = tau * scene.opticalSize * std::sqrt(3.0 * std::max(0.0, 1.0 - albedo));
    // Measured with one unshot bin at albedo 0.99: with bins a linear source holds 4
    // moments in each (no separable form), 6-10x the time (linearSourceTooLarge).
    const bool deepApplies = plan.binsPerFace == 0 && albedo >= s.diffusionTailAlbedo;
    const bool thick = tau > s.linearSourceAbove, deep = deepApplies && diffusive >= s.linearSourceDiffusive;
    plan.linearSource = s.linearSource == 1 || (s.linearSource < 0 && (thick || deep));
    const std::string tooLarge = s.linearSource < 0 && plan.linearSource ? linearSourceTooLarge(scene, plan) : "";
    if (!tooLarge.empty()) plan.linearSource = false;
    const char* shape = plan.linearSource ? "linear source inside voxels" : "voxel-constant source inside voxels";
    // The fine plan names the linear source's price (docs/performance.md, "Session 42")
    // and the way around it.
    const char* price = plan.linearSource && !scene.continuation
                            ? "; it takes 3-5x the constant source's time (--source constant: faster, less "
                              "accurate in the thick voxels)"
                            : "";
    if (s.linearSource < 0)
        plan.decisions.push_back(
            {shape, sourceShapeReason(scene, s, thick, deep, deepApplies, diffusive) + price + tooLarge});
    else plan.decisions.push_back({std::string(shape) + " (requested)", ""});
    const double leakAbove = plan.linearSource ? s.linearSourceVoxelCap : 2.0;
    if (tau > leakAbove)
        plan.decisions.push_back(
            {"warning", format("voxels up to optical depth %.3g across; above ~%g light leaks through them (measured "
                               "in docs/accuracy.md): subdivide by %.0f to bring it near %g",
                               tau, leakAbove, std::ceil(tau / leakAbove), leakAbove)});
}

/// The light passes of pass 0: environment, emission, suns, hot pixels.
void planLights(const SceneSummary& scene, const LpmSettings& s, SolvePlan& plan) {
    if (scene.continuation) return;
    plan.environmentPass = scene.environment;
    plan.emissionPass = scene.emission;
    plan.sunPasses = scene.suns;
    plan.hotPixelPasses = scene.hotPixels;
    const int nd = 6 * s.directionsPerFace * s.directionsPerFace;
    if (scene.environment)
        plan.decisions.push_back({"environment pass", std::to_string(nd) + " directions through the boundary"});
    else plan.decisions.push_back({"no environment pass", "no environment light"});
    if (scene.hotPixels > 0)
        plan.decisions.push_back(
            {"environment",
             format("hot pixels (each >= %.3g of the power) with %.1f%% of its power swept as %.0f sun(s) in their "
                    "exact direction",
                    s.envHotShare, 100 * scene.hotShare, scene.hotPixels)});
    if (scene.emission)
        plan.decisions.push_back({"emission pass", "an emission grid: source sigma_a L_e swept along every direction"});
    else plan.decisions.push_back({"no emission source", "no emission grid"});
    if (scene.suns > 0)
        plan.decisions.push_back({"sun pass", std::to_string(scene.suns) + " sun(s) swept in their exact direction"});
}

/// Separable fine sources (core/separable_source.h, docs/multires.md): with unshot bins and
/// the two-grid solve, the fine passes hold each voxel's angular integral and take the
/// angular shape from its coarse parent, instead of 12 B per bin and voxel twice over.
void planSeparableSource(const SceneSummary& scene, const LpmSettings& s, SolvePlan& plan) {
    if (scene.continuation || plan.binsPerFace == 0 || s.separableSource == 0) return;
    std::string whyNot;
    if (plan.coarseFrom == 0) whyNot = "no two-grid solve";
    else if (plan.linearSource) whyNot = "the linear source keeps slopes per voxel and bin";
    else if (plan.coarseFrom > 4)
        whyNot = "more than 3 fine passes before the coarse grid (GMRES may run on the fine grid)";
    if (!whyNot.empty()) {
        if (s.separableSource == 1) plan.decisions.push_back({"full fine sources (separable requested)", whyNot});
        return;
    }
    plan.separableSource = true;
    const int nb = 6 * plan.binsPerFace * plan.binsPerFace;
    plan.decisions.push_back(
        {"separable fine sources",
         format("%.0f unshot bins: each fine voxel keeps its angular integral, its coarse parent the angular shape "
                "(%.0f B per voxel and buffer instead of %.0f)",
                nb, 12.0, 12.0 * nb) +
             (s.separableSource == 1 ? " (requested)" : "")});
}

/// How the two-grid cycle brings its coarse tail back (core/tail_shape.h): flat, each
/// child its parent's value, or shaped by the first residual the children hold, where a
/// coarse voxel may be thick enough for its children's light to differ (a coarse voxel is
/// at most twice as thick as the thickest fine one). Separable sources keep the flat tail;
/// the diffusion tail (planDiffusionTail, decided first) has no coarse tail to shape.
void planTailShape(const SceneSummary& scene, const LpmSettings& s, SolvePlan& plan) {
    if (plan.coarseFrom == 0 || plan.diffusionTail) return;
    const double coarseTau = 2.0 * scene.maxVoxelTau;
    if (plan.separableSource) {
        if (s.shapedCoarseTail == 1)
            plan.decisions.push_back({"flat two-grid tail (shaped requested)", "separable fine sources keep it flat"});
        return;
    }
    const bool thick = coarseTau > s.shapedTailAbove;
    plan.shapedTail = s.shapedCoarseTail == 1 || (s.shapedCoarseTail == -1 && thick);
    if (plan.shapedTail)
        plan.decisions.push_back(
            {"two-grid tail shaped inside coarse voxels",
             format("coarse voxels up to optical depth %.3g", coarseTau) +
                 (s.shapedCoarseTail == 1
                      ? " (requested)"
                      : format(" > %g: a flat tail would give their dim children the lit ones' mean",
                               s.shapedTailAbove))});
    else
        plan.decisions.push_back({"flat two-grid tail", s.shapedCoarseTail == 0
                                                            ? std::string("requested")
                                                            : format("coarse voxels up to optical depth %.3g <= %g",
                                                                     coarseTau, s.shapedTailAbove)});
}

/// Whether the two-grid cycle takes its tail from a diffusion solve on the fine grid
/// (core/diffusion_tail.h) instead of the coarse grid's transport: on request, or (auto)
/// where the scattering is nearly conservative and the coarse cycle would converge slowly:
/// in voxels thick enough (docs/multires.md, "Diffusion tail": at albedo 0.99 the coarse
/// cycle stopped at its cap on the 1M smoke and cumulus, the diffusion tail converged in
/// half the time; at 0.9, or in voxels of optical depth 0.6, the coarse cycle was faster),
/// or in a medium many mean free paths across whatever its voxels (the shaped coarse
/// cycle's passes grow with the medium's optical size: 1M cumulus at voxels up to 1.2, 133
/// across, 266 passes and 3.3x the diffusion tail's time). It needs one unshot bin or
/// separable fine sources (its isotropic tail added to every bin alike; at g = 0.6 the same
/// lines measured 1.28x faster and 5x closer at 116 across, 44x closer in voxels of depth
/// 3.5: docs/multires.md, "On separable sources"), and says why not where bins are held in full.
void planDiffusionTail(const SceneSummary& scene, const LpmSettings& s, SolvePlan& plan) {
    if (plan.coarseFrom == 0 || s.diffusionTail == 0) return;
    const double albedo = std::max({scene.albedo[0], scene.albedo[1], scene.albedo[2]});
    const bool bright = albedo >= s.diffusionTailAlbedo;
    const bool thickVoxels = scene.maxVoxelTau >= s.diffusionTailTau;
    const bool large = scene.opticalSize >= s.diffusionTailSize;
    if (s.diffusionTail != 1 && !(bright && (thickVoxels || large))) return;
    std::string whyNot;  // with unshot bins the cycle adds its isotropic tail to the separable form
    if (plan.binsPerFace != 0 && !plan.separableSource)
        whyNot = "unshot bins with full fine sources (the diffusion tail is added to separable ones)";
    plan.diffusionTail = whyNot.empty();
    const std::string why =
        s.diffusionTail == 1
            ? std::string("requested")
            : format("albedo up to %.3g >= %g and ", albedo, s.diffusionTailAlbedo) +
                  (thickVoxels ? format("voxels up to optical depth %.3g >= %g", scene.maxVoxelTau, s.diffusionTailTau)
                               : format("the medium's thickest region %.3g optical depths across >= %g",
                                        scene.opticalSize, s.diffusionTailSize));
    // Held during each solve: the operator (16 B a stored voxel), the CG's five vectors and
    // J (12 B each), the multigrid's first level (56 B a cell of the half-resolution block).
    const double bytes = double(scene.storedVoxels) * (16 + 6 * 12) + 56.0 * std::ceil(scene.dims[0] / 2.0) *
                                                                          std::ceil(scene.dims[1] / 2.0) *
                                                                          std::ceil(scene.dims[2] / 2.0);
    if (plan.diffusionTail)
        plan.decisions.push_back({"two-grid tail from a fine-grid diffusion solve",
                                  why + ": (sigma_t (1 - albedo) - div D grad) J = sigma_t r, the tail albedo J "
                                        "times a factor that follows the residual",
                                  -1, bytes});
    else
        plan.decisions.push_back({"two-grid tail from the coarse grid (diffusion " +
                                      std::string(s.diffusionTail == 1 ? "requested" : "would apply: " + why) + ")",
                                  whyNot});
}

/// The resolution schedule of the scattering orders: which run on the 2x coarser grid
/// (docs/multires.md), with how many directions and rays.
void planResolution(const SceneSummary& scene, const LpmSettings& s, SolvePlan& plan) {
    const size_t at = plan.decisions.size();  // the multi-resolution line, once the tail is known
    if (!scene.continuation && s.multires != 0) {
        const bool big = scene.storedVoxels >= size_t(s.multiresMinVoxels);
        const bool fits = scene.dims[0] >= 4 && scene.dims[1] >= 4 && scene.dims[2] >= 4;
        if (fits && (s.multires == 1 || big)) plan.coarseFrom = s.multiresAfter + 1;
        if (plan.coarseFrom == 0)
            plan.decisions.push_back(
                {"full resolution for every order", !fits ? "the block is under 4 voxels along an axis"
                                                          : std::to_string(scene.storedVoxels) + " stored voxels < " +
                                                                std::to_string(s.multiresMinVoxels)});
    }
    planSeparableSource(scene, s, plan);
    planDiffusionTail(scene, s, plan);
    planTailShape(scene, s, plan);
    if (plan.coarseFrom > 0)
        plan.decisions.insert(
            plan.decisions.begin() + std::ptrdiff_t(at),
            {"multi-resolution", "orders >= " + std::to_string(plan.coarseFrom) +
                                     (plan.diffusionTail ? " in two-grid cycles without a coarse grid (their tail from "
                                                           "the diffusion solve below; "
                                                         : " on a 2x coarser grid (") +
                                     std::to_string(scene.storedVoxels) + " stored voxels" +
                                     (s.multires == 1 ? ", requested)" : ")")});
    const int n = s.directionsPerFace, half = n / 2, b = plan.binsPerFace;
    plan.coarseDirectionsPerFace =
        s.multiresDirections > 0 ? s.multiresDirections : (half >= 2 && (b == 0 || half % b == 0) ? half : n);
    // Rays of the passes after the first. Auto: one per voxel when the two-grid solve runs:
    // there the fine passes after single scattering propagate sums of smooth higher orders
    // (band-0 error against MC unchanged on plume-1M, docs/multires.md).
    plan.raysSingle = s.raysPerVoxel;
    plan.raysHigher = s.raysHigherOrders > 0 ? s.raysHigherOrders : (plan.coarseFrom > 0 ? 1 : s.raysPerVoxel);
    if (plan.raysHigher != plan.raysSingle)
        plan.decisions.push_back({"multiple scattering with " + std::to_string(plan.raysHigher) + " ray(s) per voxel" +
                                      (s.raysHigherOrders > 0 ? " (requested)" : " (two-grid solve)"),
                                  s.raysHigherOrders > 0
                                      ? "single scattering with " + std::to_string(plan.raysSingle)
                                      : "the fine passes after single scattering propagate smooth sums of higher "
                                        "orders; single scattering with " +
                                            std::to_string(plan.raysSingle)});
}

void planAcceleration(const LpmSettings& s, SolvePlan& plan) {
    plan.krylov = s.krylov;
    plan.krylovAfter = s.krylovAfter;
    plan.decisions.push_back(
        s.krylov ? PlanDecision{"GMRES allowed",
                                "switches from source iteration when the energy ratio per pass predicts more than " +
                                    std::to_string(s.krylovAfter) + " further passes"}
                 : PlanDecision{"plain source iteration", "GMRES off (requested)"});
}

/// Predicted segments, seconds and bytes, attached to the decisions that cause them.
void planCost(const SceneSummary& scene, const LpmSettings& s, int threads, SolvePlan& plan) {
    const int n = s.directionsPerFace, nd = 6 * n * n, M = plan.linearSource ? 4 : 1;
    const int nb = plan.binsPerFace == 0 ? 1 : 6 * plan.binsPerFace * plan.binsPerFace, nc = shCount(plan.shOrder);
    const bool isotropicFold = nb == 1 && nc == 1;
    const double N = double(scene.storedVoxels),
                 perThread = isotropicFold ? (M == 4 ? kPlannedRateLinearBatched : kPlannedRateBatched)
                                           : (M == 4 ? kPlannedRateLinearSource : kPlannedRateGeneralFold);
    const double rate = perThread * std::max(1, threads);
    const double perSlice = segmentsPerSlice(n);
    plan.predictedSegmentsPerFinePass = nd * double(plan.raysHigher * plan.raysHigher) * N * perSlice;
    plan.predictedSecondsPerFinePass = plan.predictedSegmentsPerFinePass / rate;
    const double unshotBytes =
        plan.separableSource ? 2 * N * (1 + nb / 8.0) * 3 * sizeof(float) : 2 * N * nb * M * 3 * sizeof(float);
    // Deposit buffers: the isotropic fold's batches (the linear source's: one a thread, 30 B
    // a voxel with its first moments in bfloat16), 8 directions of the general fold (and
    // what it streams), or 4 and the bin's source with separable sources.
    const double linearBatchBytes = N * (3 * sizeof(float) + 9 * sizeof(std::uint16_t));
    const double floatBuffers = isotropicFold ? 6.0 : (plan.separableSource ? 5.0 : 16.0);
    const double foldBytes = isotropicFold && M == 4 ? double(std::max(1, threads)) * linearBatchBytes
                                                     : floatBuffers * N * 3 * M * sizeof(float);
    const double shBytes = N * nc * 3 * sizeof(float);
    plan.predictedBytes = unshotBytes + foldBytes + shBytes + N * sizeof(float) * (scene.emission ? 4 : 1);
    const double lightSweeps =
        (plan.environmentPass || plan.emissionPass ? nd : 0) + plan.sunPasses + plan.hotPixelPasses;
    for (PlanDecision& d : plan.decisions) {
        if (d.what == "environment pass" || d.what == "emission pass" || d.what == "sun pass")
            d.predictedSeconds = lightSweeps * double(plan.raysSingle * plan.raysSingle) * N * perSlice / rate;
        if (d.what.find("unshot bin") != std::string::npos || d.what == "separable fine sources")
            d.predictedBytes = unshotBytes + foldBytes;
        if (d.what == "multi-resolution" || d.what == "full resolution for every order")
            d.predictedSeconds = plan.predictedSecondsPerFinePass;
    }
    if (plan.coarseFrom > 0 && !plan.diffusionTail) {
        const int nc2 = plan.coarseDirectionsPerFace;
        const double coarse =
            6.0 * nc2 * nc2 * plan.raysHigher * plan.raysHigher * (N / 8) * segmentsPerSlice(nc2) / rate;
        plan.decisions.push_back({"coarse pass",
                                  format("%.0f directions per face on 1/8 of the voxels, %.3g of a fine pass", nc2,
                                         coarse / std::max(1e-30, plan.predictedSecondsPerFinePass)),
                                  coarse});
    }
}

/// GMRES's Krylov basis, one half-precision vector of the unshot source's size each, is the
/// largest buffer a full-resolution solve can add (a two-grid solve's coarse grid caps its
/// own: core/two_grid.cpp). It may take what issue 9's memory line leaves after the process
/// (kProcessBytes), the planned buffers and GMRES's two further float vectors (X and one
/// product), at most s.krylovBytes, and 4 vectors at least: the bundled fire at density 8,
/// g = 0.6, albedo 0.99 (24 bins in full, linear source) peaked at 549 MiB with 23 of 40
/// vectors in 6.8 s, at 266 MiB with 4 in 6.2-6.4 s and at 248 MiB with 3 in 7.0 s
/// (docs/performance.md, "Session 54").
void planKrylovBasis(const SceneSummary& scene, const LpmSettings& s, SolvePlan& plan) {
    plan.krylovBytes = s.krylovBytes;
    if (!plan.krylov || plan.coarseFrom > 0 || plan.separableSource || scene.continuation) return;
    const double bins = plan.binsPerFace == 0 ? 1 : 6.0 * plan.binsPerFace * plan.binsPerFace;
    const double N = double(scene.storedVoxels), wanted = double(scene.wantedVoxels ? scene.wantedVoxels : N);
    const double floats = N * bins * (plan.linearSource ? 4 : 1) * 3;  // one vector of the unshot source
    const double vectorBytes = floats * sizeof(std::uint16_t);
    const double line = kMemoryLinePerVoxel * wanted + kMemoryLineBase;
    const double left = line - kProcessBytes - plan.predictedBytes - 2 * floats * sizeof(float);
    if (std::min(s.krylovBytes, s.krylovRestart * vectorBytes) <= left) return;
    const double vectors = std::max(4.0, std::floor(left / vectorBytes));
    plan.krylovBytes = std::min(s.krylovBytes, vectors * vectorBytes);
    constexpr double MiB = 1024.0 * 1024.0;
    PlanDecision& gmres = *std::find_if(plan.decisions.begin(), plan.decisions.end(),
                                        [](const PlanDecision& d) { return d.what == "GMRES allowed"; });
    gmres.why += format(
        "; its basis holds %.0f Krylov vectors of %.3g MiB: the memory line of %.0f MiB leaves %.3g "
        "MiB after the solve's other buffers (4 at least)",
        vectors, vectorBytes / MiB, line / MiB, std::max(0.0, left) / MiB);
    gmres.predictedBytes = vectors * vectorBytes;
}

}  // namespace

SceneSummary summarizeScene(const Medium& m, const Lights& lights, const EnvBinning* binned, bool continuation) {
    SceneSummary sc;
    sc.dims[0] = m.nx;
    sc.dims[1] = m.ny;
    sc.dims[2] = m.nz;
    sc.storedVoxels = m.voxelCount();
    sc.wantedVoxels = m.wantedS.empty() ? sc.storedVoxels : 0;
    for (std::uint8_t w : m.wantedS) sc.wantedVoxels += w != 0;
    const double hmax = std::max(m.voxelSize.x, std::max(m.voxelSize.y, m.voxelSize.z));
    for (float sg : m.sigmaT) sc.maxVoxelTau = std::max(sc.maxVoxelTau, double(sg) * hmax);
    sc.g = m.g;
    sc.albedo = m.albedo;
    sc.continuation = continuation;
    if (continuation) return sc;
    sc.opticalSize = opticalSize(m);
    sc.emission = m.hasEmission();
    sc.environment = lights.env && lights.env->integral() > 0;
    for (const Sun& sun : lights.suns) sc.suns += sun.irradiance.isBlack() ? 0 : 1;
    if (binned && sc.environment) {
        for (const Sun& sun : binned->hotSuns) sc.hotPixels += sun.irradiance.isBlack() ? 0 : 1;
        sc.hotShare = binned->hotShare;
    }
    return sc;
}

std::string PlanDecision::text() const { return why.empty() ? what : what + ": " + why; }

std::string PlanDecision::textWithCost() const {
    std::string t = text();
    if (predictedSeconds >= 0 || predictedBytes >= 0) {
        t += " [predicted";
        if (predictedSeconds >= 0) t += format(" %.3g s", predictedSeconds);
        if (predictedBytes >= 0) t += format(" %.3g MiB", predictedBytes / (1 << 20));
        t += "]";
    }
    return t;
}

std::vector<std::string> SolvePlan::lines(bool withCost) const {
    std::vector<std::string> out;
    for (const PlanDecision& d : decisions) out.push_back(withCost ? d.textWithCost() : d.text());
    return out;
}

SolvePlan planSolve(const SceneSummary& input, const LpmSettings& s, int threads) {
    SceneSummary scene = input;
    SolvePlan plan;
    planSubdivision(scene, s, plan);
    planDeltaM(scene, s, plan);
    planAngular(scene, s, plan);
    planSourceShape(scene, s, plan);
    planLights(scene, s, plan);
    planResolution(scene, s, plan);
    planAcceleration(s, plan);
    planCost(scene, s, threads, plan);
    planKrylovBasis(scene, s, plan);
    return plan;
}

}  // namespace lpm

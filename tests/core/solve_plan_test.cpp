// The effect planner (core/solve_plan.h): for every decision, a scene that triggers it;
// and the cheap path it picks stays within the tolerance of forcing the expensive one.
#include "core/solve_plan.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "core/lpm_solver.h"
#include "test_scenes.h"

using namespace lpm;
using namespace lpm::test;

namespace {

SceneSummary smallScene() {
    SceneSummary sc;
    sc.dims[0] = sc.dims[1] = sc.dims[2] = 32;
    sc.storedVoxels = 32 * 32 * 32;
    sc.maxVoxelTau = 0.5;
    sc.g = 0.0;
    sc.albedo = RGB(0.9f);
    sc.environment = true;
    return sc;
}

/// The 1M cumulus at density scale 1.2: 160^3, voxels up to optical depth 1.2, 133
/// optical depths across, albedo 0.99.
SceneSummary largeCumulus() {
    SceneSummary sc = smallScene();
    sc.dims[0] = sc.dims[1] = sc.dims[2] = 160;
    sc.storedVoxels = 160 * 160 * 160;
    sc.maxVoxelTau = 1.2;
    sc.opticalSize = 133;
    sc.albedo = RGB(0.99f);
    return sc;
}

bool says(const SolvePlan& p, const std::string& what) {
    for (const std::string& l : p.lines())
        if (l.find(what) != std::string::npos) return true;
    return false;
}

/// Band-0 relative RMS difference between two results over voxels with S above 1% of the largest.
double band0Difference(const LpmResult& a, const LpmResult& b) {
    double peak = 0;
    for (size_t v = 0; v < a.sh.size() / (3 * a.coeffs); ++v) peak = std::max(peak, double(a.sh[v * 3 * a.coeffs]));
    double num = 0, den = 0;
    for (size_t v = 0; v < a.sh.size() / (3 * a.coeffs); ++v)
        for (int c = 0; c < 3; ++c) {
            const double x = a.sh[v * 3 * a.coeffs + c], y = b.sh[v * 3 * b.coeffs + c];
            if (x < 0.01 * peak) continue;
            num += (x - y) * (x - y);
            den += x * x;
        }
    return std::sqrt(num / den);
}

}  // namespace

TEST(SolvePlan, IsotropicPhaseGivesShOrderZeroAndOneBin) {
    const SolvePlan p = planSolve(smallScene(), LpmSettings{}, 2);
    EXPECT_EQ(p.shOrder, 0);
    EXPECT_EQ(p.binsPerFace, 0);
    EXPECT_TRUE(says(p, "SH order 0: the phase function is isotropic"));
    EXPECT_TRUE(says(p, "one isotropic unshot bin"));
    SceneSummary fwd = smallScene();
    fwd.g = 0.6;
    const SolvePlan q = planSolve(fwd, LpmSettings{}, 2);
    EXPECT_EQ(q.shOrder, 2);
    EXPECT_EQ(q.binsPerFace, 2);
    EXPECT_TRUE(says(q, "2x2 unshot bins per cube face"));
}

// Directional SH is held only for the voxels the caller reads (core/sh_rows.h): the plan
// says so and predicts that memory; the scene summary counts Medium::wantedS.
TEST(SolvePlan, ShRowsOnlyForTheWrittenVoxels) {
    SceneSummary fwd = smallScene();
    fwd.g = 0.6;
    fwd.wantedVoxels = 1000;
    const SolvePlan p = planSolve(fwd, LpmSettings{}, 2);
    EXPECT_TRUE(says(p, "held for the 1000 voxels written of 32768 stored"));
    const auto sh = std::find_if(p.decisions.begin(), p.decisions.end(),
                                 [](const PlanDecision& d) { return d.what == "SH order 2"; });
    ASSERT_NE(sh, p.decisions.end());
    EXPECT_EQ(sh->predictedBytes, 1000.0 * 9 * 3 * sizeof(float));
    fwd.wantedVoxels = fwd.storedVoxels;
    EXPECT_FALSE(says(planSolve(fwd, LpmSettings{}, 2), "voxels written"));

    Medium m = makeBox(16, 16, 16, 0.5);
    m.g = 0.6;
    EXPECT_EQ(summarizeScene(m, Lights{}, nullptr, false).wantedVoxels, m.voxelCount());
    m.wantedS.assign(m.voxelCount(), 0);
    for (size_t v = 0; v < m.voxelCount(); v += 3) m.wantedS[v] = 1;
    EXPECT_EQ(summarizeScene(m, Lights{}, nullptr, false).wantedVoxels, (m.voxelCount() + 2) / 3);
}

TEST(SolvePlan, LightPassesFollowTheLights) {
    SceneSummary sc = smallScene();
    SolvePlan p = planSolve(sc, LpmSettings{}, 2);
    EXPECT_TRUE(p.environmentPass);
    EXPECT_FALSE(p.emissionPass);
    EXPECT_EQ(p.sunPasses, 0);
    EXPECT_TRUE(says(p, "no emission source: no emission grid"));
    sc.environment = false;
    sc.emission = true;
    sc.suns = 2;
    sc.hotPixels = 1;
    sc.hotShare = 0.4;
    p = planSolve(sc, LpmSettings{}, 2);
    EXPECT_FALSE(p.environmentPass);
    EXPECT_TRUE(p.emissionPass);
    EXPECT_EQ(p.sunPasses, 2);
    EXPECT_EQ(p.hotPixelPasses, 1);
    EXPECT_TRUE(says(p, "no environment pass"));
    EXPECT_TRUE(says(p, "emission pass"));
    EXPECT_TRUE(says(p, "hot pixels"));
    EXPECT_TRUE(says(p, "2 sun(s) swept"));
}

TEST(SolvePlan, ThickVoxelsGetTheLinearSourceAndAWarning) {
    SceneSummary sc = smallScene();
    EXPECT_FALSE(planSolve(sc, LpmSettings{}, 2).linearSource);
    sc.maxVoxelTau = 3.0;
    const SolvePlan p = planSolve(sc, LpmSettings{}, 2);
    EXPECT_TRUE(p.linearSource);
    EXPECT_TRUE(says(p, "linear source inside voxels: largest voxel optical depth 3 > 2"));
    EXPECT_TRUE(says(p, "3-5x the constant source's time (--source constant")) << "the plan names the price";
    sc.maxVoxelTau = 20.0;
    EXPECT_TRUE(says(planSolve(sc, LpmSettings{}, 2), "subdivide by 3"));
    LpmSettings forced;
    forced.linearSource = 0;
    EXPECT_FALSE(planSolve(sc, forced, 2).linearSource);
}

// With unshot bins the linear source holds 4 moments in every bin (2 x 24 x 48 B a stored
// voxel): the auto choice keeps it while that fits the memory line (300 B a written voxel
// + 200 MiB), keeps the constant source above it and says why (with the leak warning),
// and --source linear still forces it. One isotropic bin (g = 0) holds 96 B: no limit.
TEST(SolvePlan, LinearSourceWithBinsOnlyUnderTheMemoryLine) {
    SceneSummary sc = smallScene();
    sc.g = 0.6;
    sc.maxVoxelTau = 3.5;
    EXPECT_TRUE(planSolve(sc, LpmSettings{}, 2).linearSource) << "32^3: 72 MiB of sources";
    sc.dims[0] = sc.dims[1] = sc.dims[2] = 100;
    sc.storedVoxels = 1000000;
    const SolvePlan large = planSolve(sc, LpmSettings{}, 2);
    EXPECT_FALSE(large.linearSource);
    EXPECT_TRUE(large.separableSource);
    EXPECT_TRUE(says(large, "voxel-constant source inside voxels: largest voxel optical depth"));
    EXPECT_TRUE(
        says(large, "4 moments in each of 24 unshot bins: 2197 MiB of sources over the memory line of 486 MiB"));
    EXPECT_TRUE(says(large, "light leaks through them"));
    EXPECT_LT(large.predictedBytes, 300.0 * 1e6 + 200.0 * 1024 * 1024);
    LpmSettings forced;
    forced.linearSource = 1;
    const SolvePlan linear = planSolve(sc, forced, 2);
    EXPECT_TRUE(linear.linearSource);
    EXPECT_GT(linear.predictedBytes, 8 * large.predictedBytes);
    sc.wantedVoxels = 100000;  // the line counts the voxels written
    EXPECT_TRUE(says(planSolve(sc, LpmSettings{}, 2), "over the memory line of 229 MiB"));
    sc.g = 0.0;
    EXPECT_TRUE(planSolve(sc, LpmSettings{}, 2).linearSource) << "one isotropic bin";
}

TEST(SolvePlan, FullResolutionKrylovBasisUnderTheMemoryLine) {
    SceneSummary sc = smallScene();
    const LpmSettings s;
    EXPECT_EQ(planSolve(sc, s, 2).krylovBytes, s.krylovBytes) << "g = 0: 40 vectors of 192 KiB fit";
    EXPECT_FALSE(says(planSolve(sc, s, 2), "Krylov vectors"));
    // 32^3 at g = 0.6: 24 bins, a vector of 4.5 MiB. The line (300 B a voxel + 200 MiB)
    // leaves 99.8 MiB after the process (64 MiB), the planned buffers (27.4 MiB) and
    // GMRES's two float vectors (18 MiB): 22 vectors.
    sc.g = 0.6;
    const double vector = 32768.0 * 24 * 3 * 2;
    const SolvePlan bins = planSolve(sc, s, 2);
    EXPECT_EQ(bins.krylovBytes, 22 * vector);
    EXPECT_TRUE(says(bins, "its basis holds 22 Krylov vectors of 4.5 MiB"));
    // With the linear source (voxels of optical depth 3.5) the rest is over the line: 4.
    sc.maxVoxelTau = 3.5;
    const SolvePlan linear = planSolve(sc, s, 2);
    ASSERT_TRUE(linear.linearSource);
    EXPECT_EQ(linear.krylovBytes, 4 * 4 * vector);
    EXPECT_TRUE(says(linear, "its basis holds 4 Krylov vectors of 18 MiB"));
    EXPECT_TRUE(says(linear, "leaves 0 MiB after the solve's other buffers (4 at least)"));
    LpmSettings smaller;
    smaller.krylovBytes = vector;  // the settings' cap is kept where it is tighter
    EXPECT_EQ(planSolve(sc, smaller, 2).krylovBytes, vector);
    LpmSettings noGmres;
    noGmres.krylov = false;
    EXPECT_FALSE(says(planSolve(sc, noGmres, 2), "Krylov vectors"));
    // A two-grid solve: its coarse grid caps its own basis (core/two_grid.cpp).
    EXPECT_EQ(planSolve(largeCumulus(), s, 2).krylovBytes, s.krylovBytes);
}

TEST(SolvePlan, DeltaMOnlyForwardAndGrey) {
    SceneSummary sc = smallScene();
    sc.g = 0.8;
    SolvePlan p = planSolve(sc, LpmSettings{}, 2);
    EXPECT_TRUE(p.deltaM);
    EXPECT_NEAR(p.deltaMFraction, std::pow(0.8, 4), 1e-12);
    EXPECT_NEAR(p.gPropagation, (0.8 - 0.4096) / (1 - 0.4096), 1e-12);
    EXPECT_EQ(p.gOut, 0.8);
    sc.albedo = RGB(0.9f, 0.8f, 0.7f);
    p = planSolve(sc, LpmSettings{}, 2);
    EXPECT_FALSE(p.deltaM);
    EXPECT_TRUE(says(p, "no delta-M: the albedo is not grey"));
    sc.albedo = RGB(0.9f);
    sc.g = -0.5;
    EXPECT_FALSE(planSolve(sc, LpmSettings{}, 2).deltaM);
}

TEST(SolvePlan, LargeBlocksIterateHigherOrdersOnTheCoarseGrid) {
    SceneSummary sc = smallScene();
    sc.dims[0] = sc.dims[1] = sc.dims[2] = 64;
    sc.storedVoxels = 64 * 64 * 64;
    const SolvePlan big = planSolve(sc, LpmSettings{}, 2);
    EXPECT_EQ(big.coarseFrom, 2);
    EXPECT_EQ(big.raysHigher, 1);
    EXPECT_EQ(big.coarseDirectionsPerFace, 2);
    EXPECT_TRUE(says(big, "multi-resolution: orders >= 2 on a 2x coarser grid"));
    EXPECT_TRUE(says(big, "multiple scattering with 1 ray(s) per voxel (two-grid solve)"));
    const SolvePlan small = planSolve(smallScene(), LpmSettings{}, 2);
    EXPECT_EQ(small.coarseFrom, 0);
    EXPECT_EQ(small.raysHigher, 2);
    EXPECT_TRUE(says(small, "full resolution for every order"));
    // The line sits just above 32^3, so the 32^3 MC comparison set measures full
    // resolution, and a block one tile larger (a radius-16 puff stores 49664) runs two grids.
    sc.dims[0] = sc.dims[1] = sc.dims[2] = 40;
    sc.storedVoxels = 32 * 32 * 32;
    EXPECT_EQ(planSolve(sc, LpmSettings{}, 2).coarseFrom, 0);
    sc.storedVoxels = 32 * 32 * 32 + 8 * 8 * 8;
    EXPECT_EQ(planSolve(sc, LpmSettings{}, 2).coarseFrom, 2);
    // The coarse grid of a two-grid solve plans no light passes, no SH, no delta-M.
    sc.continuation = true;
    sc.g = 0.8;
    const SolvePlan coarse = planSolve(sc, LpmSettings{}, 2);
    EXPECT_EQ(coarse.coarseFrom, 0);
    EXPECT_EQ(coarse.shOrder, 0);
    EXPECT_FALSE(coarse.deltaM);
    EXPECT_FALSE(coarse.environmentPass);
}

// Separable fine sources: with unshot bins (g != 0) and the two-grid solve, not with one
// isotropic bin, at full resolution or with the linear source; asked for where they
// cannot run, the plan says why.
TEST(SolvePlan, SeparableFineSourcesWithBinsOnTheTwoGridSolve) {
    SceneSummary sc = smallScene();
    sc.dims[0] = sc.dims[1] = sc.dims[2] = 64;
    sc.storedVoxels = 64 * 64 * 64;
    sc.g = 0.6;
    const SolvePlan aniso = planSolve(sc, LpmSettings{}, 2);
    EXPECT_TRUE(aniso.separableSource);
    EXPECT_TRUE(says(aniso, "separable fine sources: 24 unshot bins"));
    LpmSettings off;
    off.separableSource = 0;
    const SolvePlan full = planSolve(sc, off, 2);
    EXPECT_FALSE(full.separableSource);
    EXPECT_LT(aniso.predictedBytes, 0.5 * full.predictedBytes);
    sc.g = 0.0;
    EXPECT_FALSE(planSolve(sc, LpmSettings{}, 2).separableSource);  // one isotropic bin
    SceneSummary small = smallScene();
    small.g = 0.6;
    EXPECT_FALSE(planSolve(small, LpmSettings{}, 2).separableSource);  // full resolution
    LpmSettings asked;
    asked.separableSource = 1;
    const SolvePlan askedSmall = planSolve(small, asked, 2);
    EXPECT_FALSE(askedSmall.separableSource);
    EXPECT_TRUE(says(askedSmall, "full fine sources (separable requested): no two-grid solve"));
    sc.g = 0.6;
    sc.maxVoxelTau = 5;
    asked.linearSource = 1;  // at 64^3 the auto choice keeps the constant source (its bins' memory)
    const SolvePlan thick = planSolve(sc, asked, 2);
    EXPECT_TRUE(thick.linearSource);
    EXPECT_FALSE(thick.separableSource);
    EXPECT_TRUE(says(thick, "the linear source keeps slopes"));
}

// The two-grid tail is shaped where coarse voxels may be optically thicker than 2 (twice
// the thickest fine voxel), flat elsewhere and with separable sources; either can be asked
// for (the accuracy of each: tail_shape_test.cpp).
TEST(SolvePlan, TwoGridTailShapedWhereCoarseVoxelsAreThick) {
    SceneSummary sc = smallScene();
    sc.dims[0] = sc.dims[1] = sc.dims[2] = 64;
    sc.storedVoxels = 64 * 64 * 64;
    sc.maxVoxelTau = 0.6;
    const SolvePlan thick = planSolve(sc, LpmSettings{}, 2);
    EXPECT_TRUE(thick.shapedTail);
    EXPECT_TRUE(says(thick, "two-grid tail shaped inside coarse voxels: coarse voxels up to optical depth 1.2 > 1"));
    sc.maxVoxelTau = 0.45;
    const SolvePlan thin = planSolve(sc, LpmSettings{}, 2);
    EXPECT_FALSE(thin.shapedTail);
    EXPECT_TRUE(says(thin, "flat two-grid tail: coarse voxels up to optical depth 0.9 <= 1"));
    LpmSettings shaped;
    shaped.shapedCoarseTail = 1;
    EXPECT_TRUE(planSolve(sc, shaped, 2).shapedTail);
    EXPECT_TRUE(says(planSolve(sc, shaped, 2), "(requested)"));
    sc.maxVoxelTau = 1.5;
    LpmSettings flat;
    flat.shapedCoarseTail = 0;
    EXPECT_FALSE(planSolve(sc, flat, 2).shapedTail);
    sc.g = 0.6;  // separable fine sources
    const SolvePlan separable = planSolve(sc, shaped, 2);
    EXPECT_TRUE(separable.separableSource);
    EXPECT_FALSE(separable.shapedTail);
    EXPECT_TRUE(says(separable, "flat two-grid tail (shaped requested): separable fine sources keep it flat"));
    EXPECT_FALSE(planSolve(smallScene(), shaped, 2).shapedTail);  // full resolution: no tail
}

// The diffusion tail runs on request where the two-grid cycle has one unshot bin or
// separable fine sources (its isotropic tail added to them), and says why not with bins
// held in full (its accuracy: diffusion_tail_test.cpp).
TEST(SolvePlan, DiffusionTailOnRequestWithOneBinOrSeparableSources) {
    SceneSummary sc = smallScene();
    sc.dims[0] = sc.dims[1] = sc.dims[2] = 64;
    sc.storedVoxels = 64 * 64 * 64;
    LpmSettings on;
    on.diffusionTail = 1;
    EXPECT_FALSE(planSolve(sc, LpmSettings{}, 2).diffusionTail);
    const SolvePlan isotropic = planSolve(sc, on, 2);
    EXPECT_TRUE(isotropic.diffusionTail);
    EXPECT_TRUE(says(isotropic, "two-grid tail from a fine-grid diffusion solve: requested"));
    sc.g = 0.6;  // separable fine sources
    const SolvePlan separable = planSolve(sc, on, 2);
    EXPECT_TRUE(separable.separableSource);
    EXPECT_TRUE(separable.diffusionTail);
    EXPECT_TRUE(says(separable, "two-grid tail from a fine-grid diffusion solve: requested"));
    LpmSettings full = on;
    full.separableSource = 0;  // bins held in full
    const SolvePlan binsInFull = planSolve(sc, full, 2);
    EXPECT_FALSE(binsInFull.diffusionTail);
    EXPECT_TRUE(says(binsInFull,
                     "two-grid tail from the coarse grid (diffusion requested): unshot bins with full "
                     "fine sources"));
    EXPECT_FALSE(planSolve(smallScene(), on, 2).diffusionTail);  // full resolution: no cycle
}

// Auto: the diffusion tail where the albedo (largest channel) and the voxels' optical depth
// both reach their thresholds, the coarse tail otherwise; forced off, never.
TEST(SolvePlan, DiffusionTailAutoForThickNearlyConservativeMedia) {
    SceneSummary sc = smallScene();
    sc.dims[0] = sc.dims[1] = sc.dims[2] = 64;
    sc.storedVoxels = 64 * 64 * 64;
    sc.maxVoxelTau = 2.5;
    sc.albedo = RGB(0.5f, 0.6f, 0.99f);
    const SolvePlan thick = planSolve(sc, LpmSettings{}, 2);
    EXPECT_TRUE(thick.diffusionTail);
    int priced = 0;  // its memory: 88 B a stored voxel, 56 B a cell of the half-resolution block
    for (const PlanDecision& d : thick.decisions) {
        if (d.what == "two-grid tail from a fine-grid diffusion solve") {
            EXPECT_DOUBLE_EQ(d.predictedBytes, 88.0 * 64 * 64 * 64 + 56.0 * 32 * 32 * 32);
            ++priced;
        }
    }
    EXPECT_EQ(priced, 1);
    EXPECT_TRUE(says(thick,
                     "two-grid tail from a fine-grid diffusion solve: albedo up to 0.99 >= 0.97 and voxels "
                     "up to optical depth 2.5 >= 2"));
    // No coarse grid: the plan says one two-grid tail, not two, and prices no coarse pass.
    EXPECT_FALSE(thick.shapedTail);
    EXPECT_FALSE(says(thick, "two-grid tail shaped"));
    EXPECT_FALSE(says(thick, "coarse pass"));
    EXPECT_TRUE(says(thick, "multi-resolution: orders >= 2 in two-grid cycles without a coarse grid"));
    EXPECT_FALSE(says(thick, "2x coarser grid"));
    LpmSettings off;
    off.diffusionTail = 0;
    const SolvePlan coarse = planSolve(sc, off, 2);
    EXPECT_FALSE(coarse.diffusionTail);
    EXPECT_TRUE(coarse.shapedTail);  // coarse voxels up to optical depth 5
    EXPECT_TRUE(says(coarse, "multi-resolution: orders >= 2 on a 2x coarser grid"));
    EXPECT_TRUE(says(coarse, "coarse pass"));
    sc.maxVoxelTau = 0.6;  // the coarse cycle converges quickly in thinner voxels
    EXPECT_FALSE(planSolve(sc, LpmSettings{}, 2).diffusionTail);
    sc.maxVoxelTau = 2.5;
    sc.albedo = RGB(0.9f);
    EXPECT_FALSE(planSolve(sc, LpmSettings{}, 2).diffusionTail);
    sc.albedo = RGB(0.99f);
    sc.g = 0.6;  // separable fine sources take it by the same lines
    const SolvePlan separable = planSolve(sc, LpmSettings{}, 2);
    EXPECT_TRUE(separable.separableSource);
    EXPECT_TRUE(separable.diffusionTail);
    LpmSettings full;
    full.separableSource = 0;  // bins held in full: said, not done
    const SolvePlan binsInFull = planSolve(sc, full, 2);
    EXPECT_FALSE(binsInFull.diffusionTail);
    EXPECT_TRUE(says(binsInFull, "two-grid tail from the coarse grid (diffusion would apply: albedo up to 0.99"));
}

// A nearly conservative medium of thin voxels many mean free paths across (the 1M cumulus
// at density scale 1.2) takes two decisions by its size:
// - the diffusion tail: the shaped coarse cycle's passes grow with the medium's optical
//   size (docs/multires.md, "The medium's optical size"), the diffusion tail's do not;
// - the linear source under its depth-2 line: the voxel-constant source's error compounds
//   with depth in diffusion lengths (24% per voxel from MC against 5.9% linear;
//   docs/accuracy.md, "Large media").
TEST(SolvePlan, OpticallyLargeNearlyConservativeMediaTakeTheDiffusionTailAndLinearSource) {
    SceneSummary sc = largeCumulus();
    const SolvePlan large = planSolve(sc, LpmSettings{}, 2);
    EXPECT_TRUE(large.diffusionTail);
    EXPECT_TRUE(says(large,
                     "two-grid tail from a fine-grid diffusion solve: albedo up to 0.99 >= 0.97 and the medium's "
                     "thickest region 133 optical depths across >= 60"));
    EXPECT_TRUE(large.linearSource);
    EXPECT_TRUE(says(large,
                     "linear source inside voxels: largest voxel optical depth 1.2 <= 2, but times the "
                     "medium's 23 diffusion lengths across 27.6 >= 12"));
    struct Variant {
        double size;
        float albedo;
        double tailLine;
        bool tail, linear;
    };
    for (const Variant& v : {Variant{50, 0.99f, 60, false, false},  // coarse cycle faster; 1.2 x 8.7 lengths
                             Variant{133, 0.9f, 60, false, false},  // measured at 0.99 and 0.97-0.99
                             Variant{133, 0.99f, 200, false, true}})
    {  // the tail's line is a setting
        SceneSummary at = sc;
        at.opticalSize = v.size;
        at.albedo = RGB(v.albedo);
        LpmSettings s;
        s.diffusionTailSize = v.tailLine;
        const SolvePlan p = planSolve(at, s, 2);
        EXPECT_EQ(p.diffusionTail, v.tail) << v.size << " " << v.albedo;
        EXPECT_EQ(p.linearSource, v.linear) << v.size << " " << v.albedo;
    }
    sc.g = 0.6;  // unshot bins: a linear source holds 4 moments in each, 6-10x the time
    const SolvePlan binned = planSolve(sc, LpmSettings{}, 2);
    ASSERT_GT(binned.binsPerFace, 0);
    EXPECT_FALSE(binned.linearSource);
    EXPECT_TRUE(says(binned, "voxel-constant source inside voxels: largest voxel optical depth"));
    EXPECT_FALSE(says(binned, "diffusion lengths"));
    // The diffusion tail on separable sources, by the medium's size under delta-M (133 x 0.87);
    // measured on that cumulus at g = 0.6: 1.28x faster, 5x closer to the fixed point.
    EXPECT_TRUE(binned.separableSource);
    EXPECT_TRUE(binned.diffusionTail);
    EXPECT_TRUE(says(binned, "the medium's thickest region 116 optical depths across >= 60"));
}

TEST(SolvePlan, PredictedCostScalesWithVoxelsRaysAndThreads) {
    SceneSummary sc = smallScene();
    LpmSettings fullRes;  // at 2x the voxels the block would reach the two-grid threshold
    fullRes.multires = 0;
    const SolvePlan a = planSolve(sc, fullRes, 1);
    sc.storedVoxels *= 2;
    const SolvePlan b = planSolve(sc, fullRes, 1);
    const SolvePlan c = planSolve(sc, fullRes, 2);
    EXPECT_GT(a.predictedSegmentsPerFinePass, 0);
    EXPECT_NEAR(b.predictedSegmentsPerFinePass / a.predictedSegmentsPerFinePass, 2.0, 1e-9);
    EXPECT_NEAR(b.predictedSecondsPerFinePass / c.predictedSecondsPerFinePass, 2.0, 1e-9);
    // 96 directions, 4 rays per voxel, > 1 segment per voxel slice: at least 384 per voxel.
    EXPECT_GT(a.predictedSegmentsPerFinePass, 384.0 * 32 * 32 * 32);
    EXPECT_LT(a.predictedSegmentsPerFinePass, 3 * 384.0 * 32 * 32 * 32);
}

TEST(SolvePlan, SameInputsSamePlan) {
    const SolvePlan a = planSolve(smallScene(), LpmSettings{}, 2), b = planSolve(smallScene(), LpmSettings{}, 2);
    EXPECT_EQ(a.lines(), b.lines());
}

TEST(SolvePlan, SolveCarriesThePlanOutAndReportsIt) {
    const Medium m = makeVolume(VolumeKind::Cloud, 16, 2.0);
    const EnvMap sky = makeSky(64);
    Lights lights;
    lights.env = &sky;
    const SolvePlan plan = planLpm(m, lights, LpmSettings{});
    const LpmResult r = solveLpm(m, lights, LpmSettings{});
    EXPECT_EQ(r.plan.lines(), plan.lines());
    for (const std::string& line : plan.lines())
        EXPECT_NE(std::find(r.decisions.begin(), r.decisions.end(), line), r.decisions.end()) << line;
    EXPECT_EQ(r.shOrder, plan.shOrder);
}

TEST(SolvePlan, InvalidSettingsAreRefusedBeforePlanning) {
    const Medium m = makeBox(4, 4, 4, 0.5);
    LpmSettings s;
    s.raysPerVoxel = 0;
    EXPECT_THROW(planLpm(m, Lights{}, s), Error);
    s = LpmSettings{};
    s.binsPerFace = 3;  // does not divide 4 directions per face
    EXPECT_THROW(planLpm(m, Lights{}, s), Error);
}

// The shortcuts against the expensive path they replace, on a heterogeneous 16^3 cloud
// under a sky (measured: 2.7e-6 for bins and SH order, 1.0e-3 for the source shape, 1.8e-3
// for the rays of the higher orders, 0 for the emission pass): where the shortcut is exact
// the bound is float rounding's; where it changes the discretisation, 5e-3.
class ShortcutVsExpensive : public ::testing::Test {
protected:
    Medium m = makeVolume(VolumeKind::Cloud, 16, 2.0);
    EnvMap sky = makeSky(64);
    Lights lights;
    void SetUp() override { lights.env = &sky; }
};

TEST_F(ShortcutVsExpensive, OneIsotropicBinAgainstTwentyFourBins) {
    LpmSettings expensive;
    expensive.binsPerFace = 2;
    const LpmResult cheap = solveLpm(m, lights, LpmSettings{}), full = solveLpm(m, lights, expensive);
    EXPECT_EQ(cheap.binCount, 1);
    EXPECT_EQ(full.binCount, 24);
    const double d = band0Difference(full, cheap);
    std::printf("band-0 relative RMS, shortcut against the expensive path: %.3g\n", d);
    EXPECT_LT(d, 1e-4);
}

TEST_F(ShortcutVsExpensive, ShOrderZeroAgainstNearlyIsotropicShOrderTwo) {
    Medium nearIso = m;
    nearIso.g = 1e-6;  // takes the general path: SH order 2, 24 bins, delta-M on
    const LpmResult cheap = solveLpm(m, lights, LpmSettings{}), full = solveLpm(nearIso, lights, LpmSettings{});
    EXPECT_EQ(cheap.shOrder, 0);
    EXPECT_EQ(full.shOrder, 2);
    const double d = band0Difference(full, cheap);
    std::printf("band-0 relative RMS, shortcut against the expensive path: %.3g\n", d);
    EXPECT_LT(d, 1e-4);
    double higher = 0, band0 = 0;
    for (size_t v = 0; v < full.sh.size() / 27; ++v) {
        band0 = std::max(band0, std::fabs(double(full.sh[v * 27])));
        for (int k = 3; k < 27; ++k) higher = std::max(higher, std::fabs(double(full.sh[v * 27 + k])));
    }
    EXPECT_LT(higher, 1e-4 * band0) << "bands 1-2 of a g = 1e-6 medium are g^l times the radiance's";
}

TEST_F(ShortcutVsExpensive, VoxelConstantSourceAgainstLinearInThinVoxels) {
    Medium thin = makeVolume(VolumeKind::Cloud, 12, 2.0);
    float peak = 0;
    for (float s : thin.sigmaT) peak = std::max(peak, s);
    for (float& s : thin.sigmaT) s *= 0.5f / peak;  // voxel optical depths up to 0.5
    LpmSettings expensive;
    expensive.linearSource = 1;
    const LpmResult cheap = solveLpm(thin, lights, LpmSettings{}), full = solveLpm(thin, lights, expensive);
    EXPECT_FALSE(cheap.plan.linearSource);
    EXPECT_TRUE(full.plan.linearSource);
    // Voxel optical depths up to 0.5: the two source shapes differ by O(tau^2).
    const double d = band0Difference(full, cheap);
    std::printf("band-0 relative RMS, shortcut against the expensive path: %.3g\n", d);
    EXPECT_LT(d, 5e-3);
}

TEST_F(ShortcutVsExpensive, OneRayForHigherOrdersAgainstTwo) {
    LpmSettings cheapS;
    cheapS.raysHigherOrders = 1;
    const LpmResult cheap = solveLpm(m, lights, cheapS), full = solveLpm(m, lights, LpmSettings{});
    EXPECT_EQ(cheap.plan.raysHigher, 1);
    EXPECT_EQ(full.plan.raysHigher, 2);
    const double d = band0Difference(full, cheap);
    std::printf("band-0 relative RMS, shortcut against the expensive path: %.3g\n", d);
    EXPECT_LT(d, 5e-3);
}

TEST_F(ShortcutVsExpensive, NoEmissionPassWithoutEmission) {
    // A zero emission grid is the expensive path of "no emission grid": same result.
    Medium withGrid = m;
    withGrid.emission.assign(withGrid.voxelCount(), RGB(0.f));
    const LpmResult cheap = solveLpm(m, lights, LpmSettings{}), full = solveLpm(withGrid, lights, LpmSettings{});
    EXPECT_FALSE(cheap.plan.emissionPass);
    EXPECT_TRUE(full.plan.emissionPass);
    const double d = band0Difference(full, cheap);
    std::printf("band-0 relative RMS, shortcut against the expensive path: %.3g\n", d);
    EXPECT_LT(d, 1e-6);
}

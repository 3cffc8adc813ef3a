// The linear-source (linear characteristic) LPM scheme: energy balance, white furnace,
// the auto decision (thread-count determinism: LpmSolver's BitIdentical), and convergence on optically thick voxels
// against the Monte Carlo reference (where the voxel-constant source leaks light).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "core/mc_reference.h"
#include "lpm_vs_mc.h"

using namespace lpm;
using namespace lpm::test;

namespace {
LpmSettings linearSettings() {
    LpmSettings s;
    s.linearSource = 1;
    return s;
}
}  // namespace

TEST(LinearSource, EnergyBalanceEnvironmentAndSun) {
    Medium m = makeVolume(VolumeKind::Cloud, 20, 1.0);
    scaleToMaxOpticalDepth(m, 40.0);  // voxels up to optical depth ~3
    m.albedo = RGB(0.9f, 0.8f, 0.5f);
    m.g = 0.5;
    const EnvMap sky = makeSky(64);
    const Lights lights = skyAndSun(sky);
    LpmSettings s = linearSettings();
    s.tolerance = 1e-4;
    const LpmResult r = solveLpm(m, lights, s);
    ASSERT_TRUE(r.converged);
    EXPECT_TRUE(saidDecision(r, "linear source inside voxels"));
    EXPECT_NEAR((r.absorbed + r.escaped + r.unshot) / r.injected, 1.0, 1e-3);
    for (size_t k = 1; k < r.passes.size(); ++k) {
        if (r.passes[k].krylov || r.passes[k - 1].krylov) continue;
        EXPECT_NEAR(r.passes[k].injected, r.passes[k - 1].scattered, 1e-4 * r.passes[k - 1].scattered + 1e-12);
        EXPECT_LE(r.passes[k].scattered, r.passes[k - 1].scattered);
    }
    for (size_t v = 0; v < m.voxelCount(); ++v)
        for (int c = 0; c < 3; ++c) {
            ASSERT_TRUE(std::isfinite(r.coeff(v, 0)[c]));
            EXPECT_GE(r.coeff(v, 0)[c], 0.0f);
        }
}

class LinearFurnace : public ::testing::TestWithParam<double> {};

TEST_P(LinearFurnace, SEqualsL0Everywhere) {
    // Albedo 1 under a uniform environment: L = L0 is the exact solution, with zero
    // slopes; thin (line depth 5) and thick (voxels up to optical depth ~6) clouds.
    const double tau = GetParam();
    Medium m = furnaceCloud(tau);
    m.g = 0.7;
    const float L0 = 0.75f;
    const EnvMap env = EnvMap::constant(RGB(L0));
    Lights lights;
    lights.env = &env;
    LpmSettings s = linearSettings();
    s.tolerance = 1e-5;
    const LpmResult r = solveLpm(m, lights, s);
    ASSERT_TRUE(r.converged) << r.residual;
    const double worst = worstFurnaceError(m, r, L0);
    std::printf("[ furnace ] linear source, line depth %g: worst |S/L0 - 1| = %.5f, %zu passes\n", tau, worst,
                r.passes.size());
    EXPECT_LT(worst, 5e-3);
}
INSTANTIATE_TEST_SUITE_P(Tau, LinearFurnace, ::testing::Values(5.0, 50.0));

TEST(LinearSource, AutoDecisionFollowsVoxelOpticalDepth) {
    Medium m = makeVolume(VolumeKind::Cloud, 8, 1.0);
    Lights lights;
    const EnvMap sky = makeSky(16);
    lights.env = &sky;
    LpmSettings s;
    s.maxOrders = 1;
    scaleToMaxOpticalDepth(m, 4.0);  // voxels below optical depth 2: step source
    EXPECT_TRUE(
        saidDecision(solveLpm(m, lights, s), "voxel-constant source inside voxels: largest voxel optical depth"));
    scaleToMaxOpticalDepth(m, 40.0);
    EXPECT_TRUE(saidDecision(solveLpm(m, lights, s), "linear source inside voxels: largest voxel optical depth"));
    s.linearSource = 0;
    EXPECT_TRUE(saidDecision(solveLpm(m, lights, s), "voxel-constant source inside voxels (requested)"));
    s.linearSource = 2;
    EXPECT_THROW(solveLpm(m, lights, s), Error);
}

TEST(LinearSource, ThickVoxelsConvergeTowardMonteCarlo) {
    // Cloud of line optical depth 50 on 10^3 voxels (voxel optical depth up to ~8), albedo
    // 0.95, sky + sun: the voxel-constant source leaks light through the thick voxels;
    // the linear source removes most of that error. Both are measured against MC.
    Case c{"thick cloud", VolumeKind::Cloud, 0.5, 0.95, 50.0};
    Scene sc = makeScene(c, 10);
    sc.lights.env = &sc.sky;
    const auto mc = mcVoxelSH(sc.medium, sc.lights, sampleVoxels(sc.medium, 40), 20000, 0);
    LpmSettings step;
    step.linearSource = 0;
    const Comparison es = compare(solveLpm(sc.medium, sc.lights, step), mc);
    const Comparison el = compare(solveLpm(sc.medium, sc.lights, linearSettings()), mc);
    std::printf("[ thick ] band-0 RMS: step %.4f, linear %.4f (MC noise %.4f)\n", es.band0Rms, el.band0Rms,
                el.band0Noise);
    EXPECT_LT(el.band0Noise, 0.015);
    EXPECT_LT(el.band0Rms, 0.5 * es.band0Rms);
    EXPECT_LT(el.band0Rms, 0.12);
}

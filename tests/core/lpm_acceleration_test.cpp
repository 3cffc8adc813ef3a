// GMRES acceleration of the scattering-order iteration: white furnaces of optical depth
// 50 and 500 (albedo 1, where plain source iteration needs hundreds to tens of thousands
// of passes) reach S = L0 within 1% in a bounded number of passes.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "core/lpm_solver.h"
#include "lpm_vs_mc.h"

using namespace lpm;
using namespace lpm::test;

// A 12^3 plume of the given peak optical depth and albedo, under a generated sky (the
// lights point at the sky: not copied).
struct SkyPlume {
    Medium m = makeVolume(VolumeKind::Plume, 12, 1.0);
    EnvMap sky = makeSky(32);
    Lights lights;
    SkyPlume(double opticalDepth, RGB albedo) {
        scaleToMaxOpticalDepth(m, opticalDepth);
        m.albedo = albedo;
        lights.env = &sky;
    }
    SkyPlume(const SkyPlume&) = delete;
    SkyPlume& operator=(const SkyPlume&) = delete;
};

/// Plain source iteration run to tolerance 1e-5: the answer GMRES is held to.
LpmSettings longPlainIteration() {
    LpmSettings s;
    s.krylov = false;
    s.tolerance = 1e-5;
    s.maxOrders = 5000;
    return s;
}

class KrylovFurnace : public ::testing::TestWithParam<double> {};

TEST_P(KrylovFurnace, WithinOnePercent) {
    const double tau = GetParam();
    const Medium m = furnaceCloud(tau);
    const float L0 = 1.5f;
    const EnvMap env = EnvMap::constant(RGB(L0));
    Lights lights;
    lights.env = &env;
    LpmSettings s;
    s.maxOrders = 400;
    const LpmResult r = solveLpm(m, lights, s);
    const double worst = worstFurnaceError(m, r, L0);
    int krylovPasses = 0;
    for (const PassStats& p : r.passes) krylovPasses += p.krylov ? 1 : 0;
    std::printf("[ furnace ] tau %g: %zu passes (%d GMRES), %.2f s, worst |S/L0 - 1| = %.5f\n", tau, r.passes.size(),
                krylovPasses, r.seconds, worst);
    EXPECT_TRUE(r.converged);
    EXPECT_GT(krylovPasses, 0) << "the solver should have switched to GMRES";
    EXPECT_LT(worst, 0.01);
    EXPECT_NEAR((r.absorbed + r.escaped + r.unshot) / r.injected, 1.0, 2e-3);
    for (float v : r.sh) ASSERT_TRUE(std::isfinite(v));
}
INSTANTIATE_TEST_SUITE_P(Tau, KrylovFurnace, ::testing::Values(50.0, 500.0));

TEST(KrylovAcceleration, AgreesWithPlainIteration) {
    // Same answer as (long) plain source iteration on a moderately thick case.
    SkyPlume scene(20.0, RGB(0.98f, 0.95f, 0.9f));
    Medium& m = scene.m;
    m.g = 0.4;
    Lights& lights = scene.lights;
    lights.suns.push_back({normalize(Vec3{0.2, 1, -0.4}), RGB(4.0f), 0.5});
    const LpmSettings plain = longPlainIteration();
    LpmSettings fast;
    fast.tolerance = 1e-4;
    const LpmResult a = solveLpm(m, lights, plain), b = solveLpm(m, lights, fast);
    ASSERT_TRUE(a.converged);
    ASSERT_TRUE(b.converged);
    EXPECT_LT(b.passes.size() * 2, a.passes.size());
    double worst = 0;
    for (size_t v = 0; v < m.voxelCount(); ++v)
        if (m.sigmaT[v] > 0)
            for (int c = 0; c < 3; ++c)
                worst = std::max(worst, std::fabs(double(b.coeff(v, 0)[c]) / a.coeff(v, 0)[c] - 1));
    std::printf("[ krylov ] plain %zu passes %.2f s, GMRES %zu passes %.2f s, worst band-0 difference %.5f\n",
                a.passes.size(), a.seconds, b.passes.size(), b.seconds, worst);
    EXPECT_LT(worst, 2e-3);
}

TEST(KrylovAcceleration, TheSmallestBasisAgreesWithPlainIteration) {
    // Where the memory line leaves little, the planner caps GMRES's basis
    // (SolvePlan::krylovBytes; the solver keeps 3 vectors at least): restarted every 3
    // vectors, GMRES still reaches plain iteration's answer in fewer passes.
    SkyPlume scene(20.0, RGB(0.98f, 0.95f, 0.9f));
    scene.m.g = 0.4;
    const LpmSettings plain = longPlainIteration();
    LpmSettings capped;
    capped.tolerance = 1e-4;
    capped.krylovBytes = 1;
    const LpmResult a = solveLpm(scene.m, scene.lights, plain), b = solveLpm(scene.m, scene.lights, capped);
    ASSERT_TRUE(a.converged);
    ASSERT_TRUE(b.converged);
    EXPECT_TRUE(saidDecision(b, "(restart 3)"));
    EXPECT_LT(b.passes.size(), a.passes.size());
    const double apart = band0RelativeRms(scene.m, a, b);
    std::printf("[ krylov ] plain %zu passes, GMRES(3) %zu passes, band 0 apart %.2e\n", a.passes.size(),
                b.passes.size(), apart);
    EXPECT_LT(apart, 2e-3);
}

TEST(KrylovAcceleration, StopsAtTheSolvesOwnTolerance) {
    // GMRES on the fine grid stops on the solve's stop test (LpmSolve::gmresTarget): what
    // it leaves, grown by the passes that would still propagate it (at most 1 / (1 - c)),
    // is below tol * input. At albedo 0.9 the default tolerance's answer is then within
    // the tolerance's reach of one converged 1000x further, and its residual is below it.
    const SkyPlume scene(40.0, RGB(0.9f));
    const Medium& m = scene.m;
    const Lights& lights = scene.lights;
    LpmSettings loose, tight;
    tight.tolerance = loose.tolerance * 1e-3;
    const LpmResult a = solveLpm(m, lights, loose), b = solveLpm(m, lights, tight);
    ASSERT_TRUE(a.converged);
    ASSERT_TRUE(b.converged);
    ASSERT_TRUE(saidDecision(a, "GMRES:")) << "the case should run GMRES";
    const double apart = band0RelativeRms(m, a, b);
    std::printf("[ krylov ] tol %g: %zu passes, residual %.3g; tol %g: %zu passes; band 0 apart %.2e\n",
                loose.tolerance, a.passes.size(), a.residual, tight.tolerance, b.passes.size(), apart);
    EXPECT_LE(a.residual, loose.tolerance);
    EXPECT_LT(apart, loose.tolerance);
}

TEST(GeometricTail, OneGridSolveEndsWithTheSeriesWithinTheTolerance) {
    // A solve on one grid whose passes decay geometrically (albedo 0.8: rho near 0.7, under
    // GMRES's 0.8) ends with one pass of next / (1 - rho) (LpmSolve::finishWithGeometricTail)
    // instead of iterating to the stop test: fewer passes, the energy still balanced, and
    // band 0 closer to a solve converged 1000x further than plain iteration to the end is.
    const SkyPlume scene(20.0, RGB(0.8f));
    const Medium& m = scene.m;
    const Lights& lights = scene.lights;
    LpmSettings tail, plain, tight;
    plain.coarseTailExtrapolation = false;
    tight.tolerance = tail.tolerance * 1e-3;
    const LpmResult a = solveLpm(m, lights, tail), b = solveLpm(m, lights, plain), c = solveLpm(m, lights, tight);
    ASSERT_TRUE(a.converged && b.converged && c.converged);
    ASSERT_TRUE(saidDecision(a, "geometric tail")) << "the case should end with the series";
    const double tailApart = band0RelativeRms(m, a, c), plainApart = band0RelativeRms(m, b, c);
    std::printf("[ tail ] %zu passes (plain %zu), residual %.3g; band 0 from converged %.2e (plain %.2e)\n",
                a.passes.size(), b.passes.size(), a.residual, tailApart, plainApart);
    EXPECT_LT(a.passes.size(), b.passes.size());
    EXPECT_LE(a.residual, tail.tolerance);
    EXPECT_LT(tailApart, plainApart);
    EXPECT_NEAR((a.absorbed + a.escaped + a.unshot) / a.injected, 1.0, 2e-3);
}

// Stress suite for the solver: degenerate geometry, extreme optical depths, extreme
// phase functions, HDR lights, scale and rotation invariance. Every case also checks the
// invariants: finite output, non-increasing energy per order, scattered <= injected,
// non-negative band 0, and (environment-only scenes) S below the furnace bound.
#include <gtest/gtest.h>

#include <cmath>

#include <cstdio>
#include "core/lpm_solver.h"

#include "lpm_vs_mc.h"

using namespace lpm;
using namespace lpm::test;

namespace {

void checkInvariants(const Medium& m, const Lights& lights, const LpmResult& r, const char* name) {
    SCOPED_TRACE(name);
    for (float v : r.sh) ASSERT_TRUE(std::isfinite(v));
    double prev = INFINITY, scattered = 0;
    for (const PassStats& p : r.passes) {
        if (p.krylov) continue;
        EXPECT_TRUE(std::isfinite(p.scattered));
        scattered += p.scattered;
        if (p.pass > 0 && prev < INFINITY) {
            EXPECT_LE(p.scattered, prev * (1 + 1e-6) + 1e-30);
        }
        prev = p.scattered;
    }
    // Total scattered over all orders can exceed injected only by re-scattering the same
    // energy; each order's scattered power is bounded by what entered it.
    if (!r.passes.empty()) {
        EXPECT_LE(r.passes[0].scattered, r.injected * (1 + 1e-6) + 1e-30);
    }
    EXPECT_NEAR(r.absorbed + r.escaped + r.unshot, r.injected, 2e-3 * r.injected + 1e-30);
    float envMax = lights.env ? lights.env->maxValue() : 0.0f;
    for (size_t v = 0; v < m.voxelCount(); ++v) {
        for (int c = 0; c < 3; ++c) {
            const float b0 = r.coeff(v, 0)[c] * float(kY00);
            EXPECT_GE(b0, -1e-6f * (envMax + 1e-30f));
            if (lights.suns.empty() && !m.hasEmission()) {
                EXPECT_LE(b0, envMax * (1 + 2e-3f));
            }
        }
    }
}

// A sun of irradiance 1e6 (0.5 degrees) over the environment `dim`.
Lights hdrSun(const EnvMap& dim) {
    Lights l;
    l.env = &dim;
    l.suns.push_back({normalize(Vec3{0.3, 1, 0.2}), RGB(1e6f), 0.5});
    return l;
}

LpmResult solveChecked(const Medium& m, const Lights& lights, const LpmSettings& s, const char* name) {
    const LpmResult r = solveLpm(m, lights, s);
    checkInvariants(m, lights, r, name);
    return r;
}

}  // namespace

TEST(Stress, DegenerateGeometry) {
    const EnvMap sky = makeSky(32);
    Lights lights;
    lights.env = &sky;
    lights.suns.push_back({normalize(Vec3{1, 2, 0.5}), RGB(10.0f), 0.5});
    Medium vacuum = makeBox(6, 6, 6, 0.0);
    solveChecked(vacuum, lights, LpmSettings{}, "vacuum");
    Medium single = makeBox(1, 1, 1, 2.0);
    single.albedo = RGB(0.95f);
    single.g = 0.6;
    solveChecked(single, lights, LpmSettings{}, "single voxel");
    Medium slab = makeBox(12, 1, 12, 0.7);
    slab.albedo = RGB(0.9f);
    solveChecked(slab, lights, LpmSettings{}, "one-voxel slab");
}

TEST(Stress, OpticalDepthLimits) {
    const EnvMap env = EnvMap::constant(RGB(1.0f));
    Lights lights;
    lights.env = &env;
    // Thin: tau = 1e-8 per voxel. S is the incident radiance (the medium barely dims it).
    Medium thin = makeBox(8, 8, 8, 1e-8);
    thin.albedo = RGB(0.5f);
    const LpmResult a = solveChecked(thin, lights, LpmSettings{}, "thin");
    for (size_t v = 0; v < thin.voxelCount(); ++v) EXPECT_NEAR(a.coeff(v, 0)[0] * kY00, 1.0, 1e-6);
    // Opaque: tau = 1e4 per voxel. Surface voxels are lit, interior ones dark.
    Medium thick = makeBox(8, 8, 8, 1e4);
    thick.albedo = RGB(0.5f);
    const LpmResult b = solveChecked(thick, lights, LpmSettings{}, "opaque");
    const double surface = b.coeff(thick.index(0, 4, 4), 0)[0], inner = b.coeff(thick.index(4, 4, 4), 0)[0];
    EXPECT_GT(surface, 0);
    EXPECT_LT(inner, 1e-6 * surface);
}

class ExtremePhase : public ::testing::TestWithParam<double> {};
TEST_P(ExtremePhase, EnergyConserved) {
    Medium m = makeVolume(VolumeKind::Plume, 12, 4.0);
    m.albedo = RGB(0.95f);
    m.g = GetParam();
    const EnvMap sky = makeSky(32);
    Lights lights;
    lights.env = &sky;
    lights.suns.push_back({normalize(Vec3{-1, 1, 0}), RGB(5.0f), 0.0});
    solveChecked(m, lights, LpmSettings{}, "extreme g");
}
INSTANTIATE_TEST_SUITE_P(G, ExtremePhase, ::testing::Values(-0.99, 0.99));

TEST(Stress, HdrLights) {
    // A sun 1e9 times brighter than the sky, and a one-pixel hot spot of 1e5.
    Medium m = makeVolume(VolumeKind::Cloud, 12, 6.0);
    m.albedo = RGB(0.99f);
    m.g = 0.7;
    const EnvMap dim = EnvMap::constant(RGB(1e-3f));
    solveChecked(m, hdrSun(dim), LpmSettings{}, "HDR sun");
    std::vector<RGB> px(64 * 32, RGB(0.01f));
    px[10 * 64 + 20] = RGB(1e5f);
    const EnvMap spot(64, 32, px);
    Lights b;
    b.env = &spot;
    solveChecked(m, b, LpmSettings{}, "HDR pixel");
}

TEST(Stress, ScaleInvariance) {
    // Voxel sizes 1e-4 and 1e4 with extinction scaled to the same optical depth.
    const EnvMap sky = makeSky(32);
    Lights lights;
    lights.env = &sky;
    lights.suns.push_back({normalize(Vec3{0.4, 1, -0.2}), RGB(3.0f), 0.0});
    Medium ref = makeVolume(VolumeKind::Cloud, 10, 3.0);
    ref.albedo = RGB(0.8f);
    ref.g = 0.5;
    const LpmResult r0 = solveChecked(ref, lights, LpmSettings{}, "unit voxels");
    for (double h : {1e-4, 1e4}) {
        Medium m = ref;
        m.voxelSize = {h, h, h};
        for (float& s : m.sigmaT) s = float(s / h);
        const LpmResult r = solveChecked(m, lights, LpmSettings{}, "scaled voxels");
        for (size_t v = 0; v < m.voxelCount(); ++v)
            for (int k = 0; k < r.coeffs; ++k)
                EXPECT_NEAR(r.coeff(v, k)[0], r0.coeff(v, k)[0], 1e-4 * std::fabs(r0.coeff(v, 0)[0]) + 1e-12);
    }
}

TEST(Stress, NonCubicVoxelsAndRotatedFrame) {
    // Aspect 1:1:10 voxels; then the whole scene (volume frame, sun, environment) rotated
    // about +Y: band 0 is unchanged and band 1 rotates with the scene.
    Medium m = makeVolume(VolumeKind::Plume, 10, 3.0);
    m.voxelSize = {0.2, 0.2, 2.0};
    m.albedo = RGB(0.85f);
    m.g = 0.6;
    const double deg = 37.0;
    const EnvMap sky0 = makeSky(64);
    std::vector<RGB> px;
    for (int y = 0; y < sky0.height(); ++y)
        for (int x = 0; x < sky0.width(); ++x) px.push_back(sky0.pixel(x, y));
    const EnvMap sky1(sky0.width(), sky0.height(), px, deg);
    const Vec3 sun0 = normalize(Vec3{0.3, 1, -0.5});
    const Mat3 R = Mat3::rotation({0, 1, 0}, deg * kPi / 180);
    Lights a, b;
    a.env = &sky0;
    a.suns.push_back({sun0, RGB(4.0f), 0.0});
    b.env = &sky1;
    b.suns.push_back({R * sun0, RGB(4.0f), 0.0});
    Medium mr = m;
    mr.localToWorld = R;
    const LpmResult r0 = solveChecked(m, a, LpmSettings{}, "aspect 1:1:10");
    const LpmResult r1 = solveChecked(mr, b, LpmSettings{}, "rotated");
    double worst0 = 0, worst1 = 0;
    for (size_t v = 0; v < m.voxelCount(); ++v) {
        if (m.sigmaT[v] <= 0) continue;
        const double c0 = r0.coeff(v, 0)[0];
        worst0 = std::max(worst0, std::fabs(r1.coeff(v, 0)[0] / c0 - 1));
        // Band 1 (y, z, x order) as a vector in world space: rotate r0's by R.
        const Vec3 b0{r0.coeff(v, 3)[0], r0.coeff(v, 1)[0], r0.coeff(v, 2)[0]};
        const Vec3 b1{r1.coeff(v, 3)[0], r1.coeff(v, 1)[0], r1.coeff(v, 2)[0]};
        worst1 = std::max(worst1, length(b1 - R * b0) / c0);
    }
    // The environment's sub-pixels land in bins differently once rotated: small changes.
    EXPECT_LT(worst0, 5e-3);
    EXPECT_LT(worst1, 5e-3);
}

namespace {
// Band-0 relative errors of r against the MC estimates: RMS, worst voxel, MC noise (RMS).
struct Band0Errors {
    double rms = 0, worst = 0, noise = 0;
};
Band0Errors band0Errors(const LpmResult& r, const std::vector<McVoxelEstimate>& mc) {
    Band0Errors e;
    for (const auto& v : mc) {
        const double rel = (r.coeff(v.voxel, 0)[0] - v.mean[0]) / v.mean[0];
        e.rms += rel * rel / mc.size();
        e.noise += (v.stdErr[0] / v.mean[0]) * (v.stdErr[0] / v.mean[0]) / mc.size();
        e.worst = std::max(e.worst, std::fabs(rel));
    }
    e.rms = std::sqrt(e.rms);
    e.noise = std::sqrt(e.noise);
    return e;
}
}  // namespace

TEST(Stress, HdrHotSpotAgainstMonteCarlo) {
    // A one-pixel hot spot of 1e5 (99.97% of the environment's power) over a dim sky:
    // binned, its light would travel along its bin's directions and cast shifted shadows
    // (ray-effect streaks). The solver sweeps it like a sun in its exact direction.
    // Stated bound, against MC over 48 voxels: band-0 RMS below 2.5%, worst voxel below 6%
    // (measured 1.2% / 3.3%, MC noise 0.8%); binning the hot pixel instead gives 2.7% / 5.9%.
    Medium m = makeVolume(VolumeKind::Cloud, 16, 1.0, 11);
    scaleToMaxOpticalDepth(m, 8.0);
    m.albedo = RGB(0.9f);
    m.g = 0.5;
    std::vector<RGB> px(64 * 32, RGB(0.02f));
    px[9 * 64 + 23] = RGB(1e5f);
    const EnvMap spot(64, 32, px);
    Lights lights;
    lights.env = &spot;
    const auto vox = sampleVoxels(m, 48);
    const auto mc = mcVoxelSH(m, lights, vox, 40000, 0);
    LpmSettings binned;
    binned.envHotShare = 0;
    const LpmResult rs = solveChecked(m, lights, LpmSettings{}, "hot spot as a sun");
    const LpmResult rb = solveChecked(m, lights, binned, "hot spot binned");
    const Band0Errors es = band0Errors(rs, mc), eb = band0Errors(rb, mc);
    std::printf("[ hot spot ] band-0 vs MC: as a sun RMS %.4f worst %.4f; binned RMS %.4f worst %.4f (MC noise %.4f)\n",
                es.rms, es.worst, eb.rms, eb.worst, es.noise);
    EXPECT_TRUE(saidDecision(rs, "hot pixel"));
    EXPECT_LT(es.noise, 0.01);
    EXPECT_LT(es.rms, 0.025);
    EXPECT_LT(es.worst, 0.06);
    EXPECT_LT(es.rms, eb.rms);
}

TEST(Stress, HdrSunAgainstMonteCarlo) {
    // A sun of irradiance 1e6 over a sky of 1e-3 (ratio 1e9): the sun is swept in its
    // exact direction, so no streaks; stated bound against MC: band-0 RMS below 3%, worst
    // voxel below 8% (measured 2.0% / 5.2%, MC noise 0.8%; the worst voxels sit at the
    // cloud's lit edge, where r = 2 ray maps sample single scattering coarsely).
    Medium m = makeVolume(VolumeKind::Cloud, 16, 1.0, 11);
    scaleToMaxOpticalDepth(m, 8.0);
    m.albedo = RGB(0.9f);
    m.g = 0.5;
    const EnvMap dim = EnvMap::constant(RGB(1e-3f));
    const Lights lights = hdrSun(dim);
    const auto mc = mcVoxelSH(m, lights, sampleVoxels(m, 48), 20000, 0);
    const LpmResult r = solveChecked(m, lights, LpmSettings{}, "HDR sun vs MC");
    const Band0Errors e = band0Errors(r, mc);
    std::printf("[ HDR sun ] band-0 vs MC: RMS %.4f worst %.4f (MC noise %.4f)\n", e.rms, e.worst, e.noise);
    EXPECT_LT(e.noise, 0.01);
    EXPECT_LT(e.rms, 0.03);
    EXPECT_LT(e.worst, 0.08);
}

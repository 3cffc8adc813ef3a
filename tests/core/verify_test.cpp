// The bake's self-check (core/verify.h): the transmittance weights, the t quantile, and the
// estimate against the error measured over every voxel with the Monte Carlo reference.
#include "core/verify.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/error.h"
#include "core/lpm_solver.h"
#include "core/mc_reference.h"
#include "core/parallel.h"
#include "lpm_vs_mc.h"

using namespace lpm;
using namespace lpm::test;

TEST(Verify, StudentTQuantiles) {
    // Tables: t_{0.975, 7} = 2.3646, t_{0.975, 63} = 1.9983, t_{0.995, 10} = 3.1693,
    // t_{0.95, 30} = 1.6973.
    EXPECT_NEAR(studentT(0.95, 7), 2.3646, 2e-3);
    EXPECT_NEAR(studentT(0.95, 63), 1.9983, 1e-3);
    EXPECT_NEAR(studentT(0.99, 10), 3.1693, 1e-2);
    EXPECT_NEAR(studentT(0.90, 30), 1.6973, 1e-3);
}

TEST(Verify, AxisTransmittanceOfABox) {
    const double sigma = 0.3;
    const Medium m = makeBox(6, 9, 4, sigma, 0.5);
    const std::vector<float> t = axisTransmittance(m);
    for (int z = 0; z < m.nz; ++z)
        for (int y = 0; y < m.ny; ++y)
            for (int x = 0; x < m.nx; ++x) {
                double expect = 0;
                const int c[3] = {x, y, z}, n[3] = {m.nx, m.ny, m.nz};
                for (int a = 0; a < 3; ++a) {
                    const double before = (c[a] + 0.5) * 0.5, after = (n[a] - c[a] - 0.5) * 0.5;
                    expect += (std::exp(-sigma * before) + std::exp(-sigma * after)) / 6.0;
                }
                ASSERT_NEAR(t[m.index(x, y, z)], expect, 1e-6) << x << " " << y << " " << z;
            }
}

TEST(Verify, AxisTransmittanceSparseEqualsDense) {
    // Tiles left out of the sparse block are empty in the dense one: same transmittances.
    Medium dense = makeVolume(VolumeKind::Cloud, 24, 6.0);
    std::vector<std::uint8_t> active(27, 1);
    active[4] = active[13] = active[20] = 0;
    Medium sparse;
    sparse.voxelSize = dense.voxelSize;
    sparse.allocate(24, 24, 24, &active);
    for (int z = 0; z < 24; ++z)
        for (int y = 0; y < 24; ++y)
            for (int x = 0; x < 24; ++x) {
                const size_t s = sparse.index(x, y, z), d = dense.index(x, y, z);
                if (s == Medium::npos) dense.sigmaT[d] = 0.0f;
                else sparse.sigmaT[s] = dense.sigmaT[d];
            }
    ASSERT_TRUE(sparse.sparse());
    const std::vector<float> td = axisTransmittance(dense), ts = axisTransmittance(sparse);
    for (int z = 0; z < 24; ++z)
        for (int y = 0; y < 24; ++y)
            for (int x = 0; x < 24; ++x) {
                const size_t s = sparse.index(x, y, z);
                if (s != Medium::npos) {
                    ASSERT_NEAR(ts[s], td[dense.index(x, y, z)], 1e-6);
                }
            }
}

namespace {

struct VerifyScene {
    Scene scene;
    LpmResult coarse, fine;
};

VerifyScene verifyScene() {
    VerifyScene v{makeScene({"plume g0.5 a0.95", VolumeKind::Plume, 0.5, 0.95, 8.0}, 12), {}, {}};
    v.scene.lights.env = &v.scene.sky;
    LpmSettings coarse;
    coarse.directionsPerFace = 1;
    coarse.raysPerVoxel = 1;
    coarse.tolerance = 0.1;
    v.coarse = solveLpm(v.scene.medium, v.scene.lights, coarse);
    v.fine = solveLpm(v.scene.medium, v.scene.lights, LpmSettings{});
    return v;
}

/// The quantity verify estimates, over every voxel: sum_v p_v t_v with the Monte Carlo
/// reference at each voxel (its noise subtracted, as in the probes' terms).
double errorOverEveryVoxel(const Medium& m, const Lights& lights, const LpmResult& r, int paths) {
    const std::vector<float> t = axisTransmittance(m);
    std::vector<size_t> voxels;
    std::vector<double> w;
    for (size_t v = 0; v < m.voxelCount(); ++v) {
        const RGB s = r.coeff(v, 0);
        const double weight = t[v] * m.sigmaT[v] * (m.albedo.r * s.r + m.albedo.g * s.g + m.albedo.b * s.b);
        if (weight > 0) voxels.push_back(v), w.push_back(weight);
    }
    McSettings mc;
    mc.seed = 424242;
    const std::vector<McVoxelEstimate> est = mcVoxelSH(m, lights, voxels, paths, 0, mc);
    double sum = 0, total = 0;
    for (size_t i = 0; i < voxels.size(); ++i) {
        const RGB s = r.coeff(voxels[i], 0);
        const double mean = (double(s.r) + s.g + s.b) / 3.0;
        double term = 0;
        for (int c = 0; c < 3; ++c) {
            const double d = s[c] - est[i].mean[size_t(c)], se = est[i].stdErr[size_t(c)];
            term += d * d - se * se;
        }
        sum += w[i] * term / (3.0 * mean * mean);
        total += w[i];
    }
    return std::sqrt(std::max(0.0, sum / total));
}

}  // namespace

TEST(Verify, EstimateAgreesWithTheErrorOverEveryVoxel) {
    const VerifyScene v = verifyScene();
    VerifySettings s;
    s.probes = 64;
    s.pathsPerProbe = 2048;
    for (const LpmResult* r : {&v.coarse, &v.fine}) {
        const VerifyReport rep = verifyBake(v.scene.medium, v.scene.lights, r->sh, r->coeffs, s);
        const double truth = errorOverEveryVoxel(v.scene.medium, v.scene.lights, *r, 2048);
        ASSERT_EQ(rep.probes, 64);
        EXPECT_LE(rep.low, rep.error);
        EXPECT_GE(rep.high, rep.error);
        EXPECT_GE(truth, rep.low) << "estimate " << rep.error;
        EXPECT_LE(truth, rep.high) << "estimate " << rep.error;
        std::printf("verify: estimate %.4f [%.4f, %.4f], every voxel %.4f, MC noise %.4f, %.2f s\n", rep.error, rep.low,
                    rep.high, truth, rep.mcNoise, rep.seconds);
    }
    // The coarse bake is detectably worse than 2%, the default one is not.
    EXPECT_GT(verifyBake(v.scene.medium, v.scene.lights, v.coarse.sh, v.coarse.coeffs, s).low, 0.02);
    EXPECT_LT(verifyBake(v.scene.medium, v.scene.lights, v.fine.sh, v.fine.coeffs, s).low, 0.02);
}

TEST(Verify, IntervalCoversTheErrorOverEveryVoxel) {
    // Over 20 seeds a 95% interval should miss the truth about once; 5 misses or more has
    // probability 0.003 for a calibrated interval.
    const VerifyScene v = verifyScene();
    for (const LpmResult* r : {&v.coarse, &v.fine}) {
        const double truth = errorOverEveryVoxel(v.scene.medium, v.scene.lights, *r, 2048);
        int misses = 0;
        for (std::uint64_t seed = 1; seed <= 20; ++seed) {
            VerifySettings s;
            s.probes = 32;
            s.pathsPerProbe = 1024;
            s.seed = seed;
            const VerifyReport rep = verifyBake(v.scene.medium, v.scene.lights, r->sh, r->coeffs, s);
            misses += truth < rep.low || truth > rep.high;
        }
        EXPECT_LE(misses, 4) << "truth " << truth;
        std::printf("verify: truth %.4f, %d of 20 intervals miss it\n", truth, misses);
    }
}

TEST(Verify, SameForAnyThreadCount) {
    const VerifyScene v = verifyScene();
    VerifySettings s;
    s.probes = 16;
    s.pathsPerProbe = 256;
    VerifyReport one, two;
    {
        ThreadLimit limit(1);
        one = verifyBake(v.scene.medium, v.scene.lights, v.coarse.sh, v.coarse.coeffs, s);
    }
    {
        ThreadLimit limit(2);
        two = verifyBake(v.scene.medium, v.scene.lights, v.coarse.sh, v.coarse.coeffs, s);
    }
    EXPECT_EQ(one.error, two.error);
    EXPECT_EQ(one.low, two.low);
    ASSERT_EQ(one.probeList.size(), two.probeList.size());
    for (size_t i = 0; i < one.probeList.size(); ++i) EXPECT_EQ(one.probeList[i].mc, two.probeList[i].mc);
    // Repeated voxels are independent probes.
    for (size_t i = 1; i < one.probeList.size(); ++i)
        if (one.probeList[i].voxel == one.probeList[i - 1].voxel) {
            EXPECT_NE(one.probeList[i].mc, one.probeList[i - 1].mc);
        }
}

TEST(Verify, NothingToSeeGivesNoProbes) {
    Medium m = makeBox(8, 8, 8, 0.0);
    const std::vector<float> sh(m.voxelCount() * 3, 0.0f);
    const VerifyReport rep = verifyBake(m, Lights{}, sh, 1, VerifySettings{});
    EXPECT_EQ(rep.probes, 0);
    EXPECT_EQ(rep.error, 0.0);
}

TEST(Verify, SettingsAreChecked) {
    VerifySettings s;
    s.probes = 4;
    EXPECT_THROW(s.validate(), SettingError);
    s = VerifySettings{};
    s.pathsPerProbe = 0;
    EXPECT_THROW(s.validate(), SettingError);
    s = VerifySettings{};
    s.confidence = 1.0;
    EXPECT_THROW(s.validate(), SettingError);
    const Medium m = makeBox(4, 4, 4, 1.0);
    EXPECT_THROW(verifyBake(m, Lights{}, std::vector<float>(5), 1, VerifySettings{}), Error);
}

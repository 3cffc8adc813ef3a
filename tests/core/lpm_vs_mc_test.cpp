// LPM against the Monte Carlo reference on heterogeneous procedural volumes (32^3),
// environment plus sun, default settings. The errors are reported and pinned at what the
// defaults reach (see docs/accuracy.md for the measured table): band 0 0.57-1.08% RMS
// with MC noise 0.43-0.60%, bands 1-2 1.3-3.4%, pinned with ~40% headroom.
#include <gtest/gtest.h>

#include <cstdio>

#include "lpm_vs_mc.h"

using namespace lpm;
using namespace lpm::test;

class LpmVsMc : public ::testing::TestWithParam<int> {};

TEST_P(LpmVsMc, DefaultSettingsWithinPinnedError) {
    const Case c = comparisonCases()[GetParam()];
    Scene s = makeScene(c);
    s.lights.env = &s.sky;
    LpmResult r;
    const double tLpm = secondsOf([&] { r = solveLpm(s.medium, s.lights, LpmSettings{}); });
    std::vector<McVoxelEstimate> mc;
    // Strongly forward phase functions make the reference noisier: more samples there.
    const int samples = c.g >= 0.7 ? 40000 : 12000;
    const double tMc = secondsOf([&] { mc = mcVoxelSH(s.medium, s.lights, sampleVoxels(s.medium, 48), samples, 2); });
    const Comparison e = compare(r, mc);
    std::printf(
        "[ case ] %-18s band0 rms %.4f (MC noise %.4f, corrected %.4f, bias %+.4f)  bands1-2 %.4f (noise %.4f)"
        "  LPM %.2f s, %d passes  MC %.2f s\n",
        c.name.c_str(), e.band0Rms, e.band0Noise, e.band0Corrected(), e.band0Bias, e.band12Rms, e.band12Noise, tLpm,
        int(r.passes.size()), tMc);
    RecordProperty("band0_rms", std::to_string(e.band0Rms));
    // The MC estimate is precise enough to resolve the pinned errors.
    EXPECT_LT(e.band0Noise, 0.008);
    EXPECT_LT(e.band0Rms, 0.015) << "the defaults reach 1.1% or better on every case";
    EXPECT_LT(e.band0Corrected(), 0.012);
    EXPECT_LT(std::fabs(e.band0Bias), 0.006);
    if (c.g != 0.0) {
        EXPECT_LT(e.band12Rms, 0.05);
    }
}

INSTANTIATE_TEST_SUITE_P(Cases, LpmVsMc, ::testing::Range(0, 6));

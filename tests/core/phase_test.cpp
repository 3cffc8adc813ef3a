// Henyey-Greenstein: normalisation, mean cosine, and the sampler against its density.
#include "core/phase.h"

#include <gtest/gtest.h>

#include "core/rng.h"

using namespace lpm;

class HenyeyGreensteinG : public ::testing::TestWithParam<double> {};

TEST_P(HenyeyGreensteinG, NormalisedWithMeanCosineG) {
    const double g = GetParam();
    // Integrate over mu with a fine midpoint rule: 2 pi Int p(mu) dmu = 1, <mu> = g.
    const int n = 400000;
    double total = 0, mean = 0;
    for (int i = 0; i < n; ++i) {
        const double mu = -1 + (i + 0.5) * 2.0 / n;
        const double p = henyeyGreenstein(mu, g) * 2 * kPi * 2.0 / n;
        total += p;
        mean += mu * p;
    }
    EXPECT_NEAR(total, 1.0, 1e-4);
    EXPECT_NEAR(mean, g, 1e-4);
}

TEST_P(HenyeyGreensteinG, SamplerMatchesDensity) {
    // Histogram of sampled cosines against the density integrated over each bin:
    // a chi-square statistic with 19 degrees of freedom stays below the 0.999 quantile.
    const double g = GetParam();
    const Vec3 wi = normalize(Vec3{0.3, -0.5, 0.8});
    Pcg32 rng(3, 5);
    const int bins = 20, n = 200000;
    std::vector<double> hist(bins, 0.0);
    double meanCos = 0;
    for (int i = 0; i < n; ++i) {
        const Vec3 w = sampleHenyeyGreenstein(wi, g, rng.uniform(), rng.uniform());
        EXPECT_NEAR(length(w), 1.0, 1e-9);
        const double mu = dot(w, wi);
        meanCos += mu / n;
        hist[std::min(bins - 1, int((mu + 1) / 2 * bins))] += 1;
    }
    double chi2 = 0;
    for (int b = 0; b < bins; ++b) {
        double expect = 0;
        const int sub = 2000;
        for (int k = 0; k < sub; ++k) {
            const double mu = -1 + (b + (k + 0.5) / sub) * 2.0 / bins;
            expect += henyeyGreenstein(mu, g) * 2 * kPi * (2.0 / bins) / sub;
        }
        expect *= n;
        if (expect > 5) chi2 += (hist[b] - expect) * (hist[b] - expect) / expect;
    }
    EXPECT_LT(chi2, 43.8);  // chi-square 0.999 quantile, 19 dof
    EXPECT_NEAR(meanCos, g, 5e-3);
}

INSTANTIATE_TEST_SUITE_P(G, HenyeyGreensteinG, ::testing::Values(-0.7, 0.0, 0.3, 0.85));

// Cube-map quadrature and form factors: weights sum to 4 pi, texel lookup inverts the
// centres, rows of F sum to 1, reciprocity, and the bin-averaged HG is right.
#include "core/quadrature.h"

#include <gtest/gtest.h>

#include "core/phase.h"

using namespace lpm;

TEST(CubeQuadrature, WeightsSumToFourPi) {
    for (int n : {1, 2, 3, 4, 7, 16}) {
        CubeQuadrature q(n);
        double sum = 0;
        for (int i = 0; i < q.count(); ++i) sum += q.weight(i);
        EXPECT_NEAR(sum, kFourPi, 1e-12) << n;
    }
}

TEST(CubeQuadrature, IndexOfInvertsCentresAndFaceMatchesAxis) {
    CubeQuadrature q(5);
    for (int i = 0; i < q.count(); ++i) {
        EXPECT_EQ(q.indexOf(q.dir(i)), i);
        const int f = q.face(i), a = CubeQuadrature::faceAxis(f);
        EXPECT_GT(q.dir(i)[a] * CubeQuadrature::faceSign(f), 0.0);
        for (int b = 0; b < 3; ++b) EXPECT_GE(std::fabs(q.dir(i)[a]) + 1e-12, std::fabs(q.dir(i)[b]));
    }
}

TEST(CubeQuadrature, SubdivisionPreservesSolidAngle) {
    CubeQuadrature q(3);
    std::vector<Vec3> d;
    std::vector<double> w;
    for (int i = 0; i < q.count(); ++i) {
        q.subdivide(i, 4, d, w);
        double s = 0;
        for (double x : w) s += x;
        EXPECT_NEAR(s, q.weight(i), 1e-12);
        for (const Vec3& v : d) EXPECT_EQ(q.indexOf(v), i);
    }
}

class FormFactorG : public ::testing::TestWithParam<double> {};

TEST_P(FormFactorG, RowsSumToOneAndReciprocity) {
    const double g = GetParam();
    CubeQuadrature dirs(4), bins(4);
    FormFactors ff(dirs, &bins, g);
    for (int i = 0; i < dirs.count(); ++i) {
        double s = 0;
        for (int d = 0; d < ff.binCount(); ++d) {
            EXPECT_GE(ff.row(i)[d], 0.0);
            s += ff.row(i)[d];
        }
        EXPECT_NEAR(s, 1.0, 1e-6);  // float precision of the stored result is far looser
    }
    // Same bins as directions: w_i F(i,j) = w_j F(j,i) (symmetric kernel), and the
    // column condition sum_i w_i F(i,d) = w_d that keeps a uniform field uniform.
    for (int i = 0; i < dirs.count(); i += 7)
        for (int j = 0; j < dirs.count(); j += 5)
            EXPECT_NEAR(dirs.weight(i) * ff.row(i)[j], dirs.weight(j) * ff.row(j)[i],
                        1e-2 * std::max(dirs.weight(i) * ff.row(i)[j], dirs.weight(j) * ff.row(j)[i]) + 1e-12);
    for (int d = 0; d < ff.binCount(); ++d) {
        double col = 0;
        for (int i = 0; i < dirs.count(); ++i) col += dirs.weight(i) * ff.row(i)[d];
        EXPECT_NEAR(col / ff.binWeight(d), 1.0, 0.02);
    }
}

TEST_P(FormFactorG, ForwardPeakStaysInOwnBin) {
    const double g = GetParam();
    CubeQuadrature dirs(4), bins(2);
    FormFactors ff(dirs, &bins, g);
    for (int i = 0; i < dirs.count(); ++i) {
        const int own = ff.binOfDirection(i);
        int best = 0;
        for (int d = 1; d < ff.binCount(); ++d)
            if (ff.row(i)[d] > ff.row(i)[best]) best = d;
        if (g > 0.3) {
            EXPECT_EQ(best, own);
        }
        if (g < -0.3) {
            EXPECT_EQ(best, bins.indexOf(-dirs.dir(i)));
        }
    }
}

INSTANTIATE_TEST_SUITE_P(G, FormFactorG, ::testing::Values(-0.7, 0.0, 0.5, 0.85));

TEST(FormFactors, IsotropicBinAndConeRow) {
    CubeQuadrature dirs(3), bins(2);
    FormFactors iso(dirs, nullptr, 0.5);
    EXPECT_EQ(iso.binCount(), 1);
    EXPECT_EQ(iso.row(5)[0], 1.0);
    FormFactors ff(dirs, &bins, 0.6);
    const std::vector<double> row = ff.rowForCone(normalize(Vec3{0.2, -1, 0.1}), 0.05);
    double s = 0;
    for (double v : row) s += v;
    EXPECT_NEAR(s, 1.0, 1e-9);
}

TEST(ConeDirections, InsideTheCone) {
    const Vec3 w = normalize(Vec3{1, 2, 3});
    for (const Vec3& d : coneDirections(w, 0.1, 64)) {
        EXPECT_NEAR(length(d), 1.0, 1e-9);
        EXPECT_GE(dot(d, w), std::cos(0.1) - 1e-12);
    }
}

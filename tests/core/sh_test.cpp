// SH basis: orthonormality, the documented constants, project/reconstruct round trip,
// and the cone (sun disc) band factors.
#include "core/sh.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "core/quadrature.h"

using namespace lpm;

namespace {
// Fine quadrature of the sphere: 6 * 48^2 cube texels with exact solid angles.
struct Sphere {
    std::vector<Vec3> d;
    std::vector<double> w;
    Sphere() {
        CubeQuadrature q(48);
        for (int i = 0; i < q.count(); ++i) {
            d.push_back(q.dir(i));
            w.push_back(q.weight(i));
        }
    }
};
const Sphere& sphere() {
    static Sphere s;
    return s;
}
}  // namespace

TEST(SphericalHarmonics, Orthonormal) {
    double gram[16][16] = {};
    double y[16];
    for (size_t i = 0; i < sphere().d.size(); ++i) {
        shEval(sphere().d[i], y);
        for (int a = 0; a < 16; ++a)
            for (int b = 0; b < 16; ++b) gram[a][b] += y[a] * y[b] * sphere().w[i];
    }
    for (int a = 0; a < 16; ++a)
        for (int b = 0; b < 16; ++b) EXPECT_NEAR(gram[a][b], a == b ? 1.0 : 0.0, 2e-3) << a << "," << b;
}

TEST(SphericalHarmonics, DocumentedConstants) {
    double y[16];
    shEval(Vec3{0, 0, 1}, y);
    EXPECT_NEAR(y[0], 0.282095, 1e-6);
    EXPECT_NEAR(y[2], 0.488603, 1e-6);
    EXPECT_NEAR(y[6], 0.315392 * 2, 1e-6);
    shEval(Vec3{0, 1, 0}, y);
    EXPECT_NEAR(y[1], 0.488603, 1e-6);
    EXPECT_NEAR(y[8], -0.546274, 1e-6);
    shEval(Vec3{1, 0, 0}, y);
    EXPECT_NEAR(y[3], 0.488603, 1e-6);
    EXPECT_NEAR(y[15], 0.590044, 1e-6);
    const double s = std::sqrt(0.5);
    shEval(Vec3{s, s, 0}, y);
    EXPECT_NEAR(y[4], 1.092548 * 0.5, 1e-6);
}

TEST(SphericalHarmonics, ProjectReconstructRoundTrip) {
    const double c[16] = {1.0, -0.3, 0.2, 0.5, 0.1, -0.2, 0.05, 0.3, -0.1, 0.07, -0.04, 0.02, 0.15, -0.08, 0.03, 0.01};
    double proj[16] = {};
    double y[16];
    for (size_t i = 0; i < sphere().d.size(); ++i) {
        shEval(sphere().d[i], y);
        double f = 0;
        for (int k = 0; k < 16; ++k) f += c[k] * y[k];
        for (int k = 0; k < 16; ++k) proj[k] += f * y[k] * sphere().w[i];
    }
    for (int k = 0; k < 16; ++k) EXPECT_NEAR(proj[k], c[k], 2e-3) << k;
}

TEST(SphericalHarmonics, CapBandFactorMatchesQuadrature) {
    // Zonal coefficient ratio of a normalised uniform cap about +Z: k_l = <P_l(cos)>_cap.
    for (double half : {0.01, 0.2, 0.8}) {
        const int n = 20000;
        double mean[4] = {0, 0, 0, 0};
        for (int i = 0; i < n; ++i) {
            const double c = 1 - (i + 0.5) / n * (1 - std::cos(half));  // uniform in solid angle
            const double p[4] = {1, c, 0.5 * (3 * c * c - 1), 0.5 * (5 * c * c * c - 3 * c)};
            for (int l = 0; l < 4; ++l) mean[l] += p[l] / n;
        }
        for (int l = 0; l < 4; ++l) EXPECT_NEAR(capBandFactor(l, half), mean[l], 1e-6) << l << " " << half;
    }
    EXPECT_EQ(capBandFactor(2, 0.0), 1.0);
}

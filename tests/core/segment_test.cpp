// The linear-source segment kernel (core/segment.h) against direct numerical integration.
#include "core/segment.h"

#include <gtest/gtest.h>

#include <cmath>

using namespace lpm;

namespace {

// phi_k(-tau) = Int_0^1 e^{-tau (1 - s)} s^(k-1) / (k-1)! ds by composite Simpson.
double phiQuadrature(int k, double tau) {
    if (k == 0) return std::exp(-tau);
    const int n = 20000;
    double fact = 1;
    for (int i = 2; i < k; ++i) fact *= i;
    auto f = [&](double s) { return std::exp(-tau * (1 - s)) * std::pow(s, k - 1) / fact; };
    double acc = f(0) + f(1);
    for (int i = 1; i < n; ++i) acc += f(double(i) / n) * (i % 2 ? 4 : 2);
    return acc / (3.0 * n);
}

}  // namespace

TEST(Segment, PhiFunctionsMatchTheirIntegrals) {
    for (double tau : {0.0, 1e-9, 1e-4, 0.3, 0.999999, 1.0, 1.000001, 2.5, 12.0, 60.0}) {
        double f[5];
        phiFunctions(tau, f);
        for (int k = 0; k <= 4; ++k) {
            const double ref = phiQuadrature(k, tau);
            EXPECT_NEAR(f[k], ref, 1e-10 + 1e-9 * ref) << "phi_" << k << "(-" << tau << ")";
        }
    }
    // Far into the opaque limit every value stays finite and phi_k -> 1 / ((k-1)! tau).
    double f[5];
    phiFunctions(1e6, f);
    for (double v : f) EXPECT_TRUE(std::isfinite(v));
    EXPECT_NEAR(f[1] * 1e6, 1.0, 1e-5);
    EXPECT_NEAR(f[3] * 1e6, 0.5, 1e-5);
}

TEST(Segment, PropagateMatchesTheTransportEquation) {
    // dL/dt = -sigma L + qa + qb t / l, integrated with classical RK4 in fine steps, with
    // the moments Int L dt and Int L t / l dt accumulated alongside.
    struct Case {
        double sigma, len, L0, qa, qb;
    };
    for (const Case& c : {Case{0.0, 1.0, 2.0, 0.0, 0.0}, Case{0.5, 1.0, 1.0, 0.3, 0.2}, Case{3.0, 0.7, 0.5, 2.0, -1.5},
                          Case{20.0, 1.3, 4.0, 10.0, 8.0}, Case{1e-7, 2.0, 1.0, 1e-7, 3e-7}})
    {
        const SegmentFactors sf(c.sigma * c.len, c.len);
        double M0, M1;
        const double Lout = sf.propagate(c.L0, c.qa, c.qb, M0, M1);
        const int n = 200000;
        const double h = c.len / n;
        auto rhs = [&](double t, double L) { return -c.sigma * L + c.qa + c.qb * t / c.len; };
        double L = c.L0, m0 = 0, m1 = 0;
        for (int i = 0; i < n; ++i) {
            const double t = i * h;
            const double k1 = rhs(t, L), k2 = rhs(t + h / 2, L + h / 2 * k1), k3 = rhs(t + h / 2, L + h / 2 * k2),
                         k4 = rhs(t + h, L + h * k3);
            const double Ln = L + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4);
            // Trapezoid on the moments (second order, ample at this step count).
            m0 += h / 2 * (L + Ln);
            m1 += h / 2 * (L * t + Ln * (t + h)) / c.len;
            L = Ln;
        }
        const double tol = 1e-7 * (std::fabs(c.L0) + std::fabs(c.qa) * c.len + std::fabs(c.qb) * c.len + 1e-12);
        EXPECT_NEAR(Lout, L, tol) << "sigma " << c.sigma;
        EXPECT_NEAR(M0, m0, tol * c.len) << "sigma " << c.sigma;
        EXPECT_NEAR(M1, m1, tol * c.len) << "sigma " << c.sigma;
        // Balance on the segment: what enters plus what is emitted leaves or is extinguished.
        EXPECT_NEAR(c.L0 + c.len * (c.qa + 0.5 * c.qb), Lout + c.sigma * M0, 1e-12 * (c.L0 + 1) + tol);
    }
}

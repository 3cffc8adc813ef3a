// Transport along one ray segment through a homogeneous voxel with a source that is
// linear along the segment: the kernel of the linear-source LPM sweep
// (docs/lpm_solver.md, "Linear source").
//
//   dL/dt = -sigma L + Q(t),  Q(t) = qa + qb t / l,  t in [0, l],  tau = sigma l
//   L(l)            = L0 phi0 + l (qa phi1 + qb phi2)
//   M0 = Int L dt   = l [L0 phi1 + l (qa phi2 + qb phi3)]
//   M1 = Int L t/l dt = l [L0 (phi1 - phi2) + l (qa (phi2 - phi3) + qb (phi3 - phi4))]
// with phi_k = phi_k(-tau), the exponential-integrator functions
//   phi_0(z) = e^z,  phi_{k+1}(z) = (phi_k(z) - 1/k!) / z,
//   phi_k(-tau) = Int_0^1 e^{-tau (1 - s)} s^(k-1) / (k-1)! ds   (k >= 1).
// Every expression is finite for tau >= 0, including tau = 0 (phi_k(0) = 1/k!).
#pragma once

#include <cmath>

namespace lpm {

/// phi_k(-tau), k = 0..4, tau >= 0. Below tau = 1: series for phi_4 and the downward
/// recurrence phi_k = 1/k! - tau phi_{k+1} (stable there); above: the upward recurrence.
inline void phiFunctions(double tau, double f[5]) {
    if (tau < 1.0) {
        // phi_4(-tau) = sum_j (-tau)^j / (j + 4)!, j <= 12: truncation < 1e-14.
        static const double c[13] = {1.0 / 24,
                                     1.0 / 120,
                                     1.0 / 720,
                                     1.0 / 5040,
                                     1.0 / 40320,
                                     1.0 / 362880,
                                     1.0 / 3628800,
                                     1.0 / 39916800,
                                     1.0 / 479001600,
                                     1.0 / 6227020800.0,
                                     1.0 / 87178291200.0,
                                     1.0 / 1307674368000.0,
                                     1.0 / 20922789888000.0};
        // Estrin's scheme in x = -tau: the same polynomial as Horner's rule with a chain of
        // 4 multiply-adds after the powers instead of 12 (the linear source's sweep waited
        // on that chain, docs/performance.md, "Session 41").
        const double x = -tau, x2 = x * x, x4 = x2 * x2, x8 = x4 * x4;
        const double a0 = c[0] + c[1] * x, a1 = c[2] + c[3] * x, a2 = c[4] + c[5] * x;
        const double a3 = c[6] + c[7] * x, a4 = c[8] + c[9] * x, a5 = c[10] + c[11] * x;
        const double b0 = a0 + a1 * x2, b1 = a2 + a3 * x2, b2 = a4 + a5 * x2;
        f[4] = (b0 + b1 * x4) + (b2 + c[12] * x4) * x8;
        f[3] = 1.0 / 6 - tau * f[4];
        f[2] = 0.5 - tau * f[3];
        f[1] = 1.0 - tau * f[2];
        f[0] = 1.0 - tau * f[1];
    } else {
        f[0] = std::exp(-tau);
        const double invFact[4] = {1.0, 1.0, 0.5, 1.0 / 6};
        for (int k = 0; k < 4; ++k) f[k + 1] = (invFact[k] - f[k]) / tau;
    }
}

/// The phi functions of one segment, shared by the three colour channels.
struct SegmentFactors {
    double len, f[5];
    SegmentFactors(double tau, double length) : len(length) { phiFunctions(tau, f); }
    /// Returns L(l) for entering radiance L0; M0 = Int L dt and M1 = Int L t/l dt.
    double propagate(double L0, double qa, double qb, double& M0, double& M1) const {
        M0 = len * (L0 * f[1] + len * (qa * f[2] + qb * f[3]));
        M1 = len * (L0 * (f[1] - f[2]) + len * (qa * (f[2] - f[3]) + qb * (f[3] - f[4])));
        return L0 * f[0] + len * (qa * f[1] + qb * f[2]);
    }
};

}  // namespace lpm

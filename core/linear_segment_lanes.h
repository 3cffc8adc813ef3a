// The fast sweep's segment for a source linear inside each voxel (docs/performance.md,
// "Session 42"): 8 rays (one chunk of a plane row) through 8 voxels,
// float32, the lane loop vectorised. The equations are core/segment.h's:
//   L(l) = L0 phi0 + l (qa phi1 + qb phi2)
//   M0   = l [L0 phi1 + l (qa phi2 + qb phi3)]
//   M1   = l [L0 (phi1 - phi2) + l (qa (phi2 - phi3) + qb (phi3 - phi4))]
// with phi_k = phi_k(-tau), tau = sigma l, and the source along the segment
// Q(t) = qa + qb t / l, qa = q0 + sum_k s_k xi0_k, qb = sum_k s_k dxi_k (q0, s_k: the
// voxel's mean and slopes times sigma and the job's scale; xi0, dxi: where the segment
// starts in the voxel and how far it moves, the same for every ray of a lattice class).
// Deposits: d0 += M0, d_k += a_k M0 + b_k M1 (times a batch's weight, dk) (a_k = scale_k xi0_k, b_k = scale_k dxi_k,
// the lattice-moment scales of core/lattice_moments.h).
#pragma once

#include "core/exp_neg.h"

namespace lpm {

/// Plane chunk of the linear source: 26 arrays of 8 floats (one lane per voxel of a tile
/// row): sigma, q0 (rgb), slopes [x, y, z][rgb], deposits [mean, x, y, z][rgb], 1/sigma.
struct LinearChunk {
    static constexpr int kLanes = 8;
    static constexpr int kSigma = 0, kQ0 = 1, kSlope = 4, kDeposit = 13, kInvSigma = 25, kArrays = 26;
    static constexpr int kFloats = kArrays * kLanes;
};

/// One segment event of a lattice class, the same for every ray of its row.
struct LinearSegmentGeometry {
    float len = 0, invLen = 0;
    float xi0[3] = {0, 0, 0}, dxi[3] = {0, 0, 0};  // x, y, z: start in the voxel, change along the segment
    float a[3] = {0, 0, 0}, b[3] = {0, 0, 0};      // deposit factors of M0 and M1 per axis
};

/// Which phi formulas a chunk needs: the series below tau = 1, the upward recurrence
/// (one exp) from 1 on, or both selected per lane.
enum class PhiRange { Series, Recurrence, Mixed };

/// phi_k(-tau), k = 0..4, in float. Below tau = 1: phi_4 by its series to (-tau)^8 / 12!
/// (truncation < 4e-9 relative) and the downward recurrence phi_k = 1/k! - tau phi_{k+1};
/// from 1 on: phi_0 = e^-tau (expNegInline) and phi_{k+1} = (1/k! - phi_k) / tau
/// (rtau = 1 / tau). Errors: a few float roundings, about 1e-5 relative at worst for
/// phi_4 at tau = 1, where the recurrence cancels most.
template <PhiRange R>
inline void phiLanes(float tau, float rtau, float f[5]) {
    float s[5] = {1, 1, 0.5f, 1.0f / 6, 1.0f / 24}, u[5] = {1, 1, 0.5f, 1.0f / 6, 1.0f / 24};
    if constexpr (R != PhiRange::Recurrence) {
        const float x = -tau;
        float p = 1.0f / 479001600;
        p = p * x + 1.0f / 39916800;
        p = p * x + 1.0f / 3628800;
        p = p * x + 1.0f / 362880;
        p = p * x + 1.0f / 40320;
        p = p * x + 1.0f / 5040;
        p = p * x + 1.0f / 720;
        p = p * x + 1.0f / 120;
        s[4] = p * x + 1.0f / 24;
        s[3] = 1.0f / 6 - tau * s[4];
        s[2] = 0.5f - tau * s[3];
        s[1] = 1.0f - tau * s[2];
        s[0] = 1.0f - tau * s[1];
    }
    if constexpr (R != PhiRange::Series) {
        u[0] = expNegInline(tau);
        u[1] = (1.0f - u[0]) * rtau;
        u[2] = (1.0f - u[1]) * rtau;
        u[3] = (0.5f - u[2]) * rtau;
        u[4] = (1.0f / 6 - u[3]) * rtau;
    }
    for (int k = 0; k < 5; ++k) {
        if constexpr (R == PhiRange::Series) f[k] = s[k];
        else if constexpr (R == PhiRange::Recurrence) f[k] = u[k];
        else f[k] = tau < 1.0f ? s[k] : u[k];
    }
}

/// One chunk: 8 rays (L0..L2, one per channel) over the chunk's 8 voxels (plane); the
/// deposits are added times dk (1 for a sweep of its own planes; the job's tally weight
/// when a batch shares them).
template <PhiRange R>
inline __attribute__((always_inline)) void linearSegmentLanes(const LinearSegmentGeometry& g, float dk,
                                                              float* __restrict plane, float* __restrict L0,
                                                              float* __restrict L1, float* __restrict L2) {
    constexpr int n = LinearChunk::kLanes;
    const float len = g.len;
    float* __restrict Ls[3] = {L0, L1, L2};
    for (int i = 0; i < n; ++i) {
        const float tau = plane[LinearChunk::kSigma * n + i] * len;
        float f[5];
        phiLanes<R>(tau, plane[LinearChunk::kInvSigma * n + i] * g.invLen, f);
        const float g12 = f[1] - f[2], g23 = f[2] - f[3], g34 = f[3] - f[4];
        for (int c = 0; c < 3; ++c) {
            const float sx = plane[(LinearChunk::kSlope + c) * n + i];
            const float sy = plane[(LinearChunk::kSlope + 3 + c) * n + i];
            const float sz = plane[(LinearChunk::kSlope + 6 + c) * n + i];
            const float qa = plane[(LinearChunk::kQ0 + c) * n + i] + sx * g.xi0[0] + sy * g.xi0[1] + sz * g.xi0[2];
            const float qb = sx * g.dxi[0] + sy * g.dxi[1] + sz * g.dxi[2];
            const float Lin = Ls[c][i];
            const float M0 = len * (Lin * f[1] + len * (qa * f[2] + qb * f[3]));
            const float M1 = len * (Lin * g12 + len * (qa * g23 + qb * g34));
            Ls[c][i] = Lin * f[0] + len * (qa * f[1] + qb * f[2]);
            const float m0 = dk * M0, m1 = dk * M1;
            float* __restrict d = plane + LinearChunk::kDeposit * n + i;
            d[c * n] += m0;
            for (int k = 0; k < 3; ++k) d[(3 + 3 * k + c) * n] += g.a[k] * m0 + g.b[k] * m1;
        }
    }
}

}  // namespace lpm

// The reference LPM sweep (one ray at a time, double-precision DDA): the definition the
// fast kernel (core/sweep.cpp) is tested against, and the kernel of the linear source.
// Equations: docs/lpm_solver.md.
#include <algorithm>
#include <cmath>
#include <limits>

#include "core/segment.h"
#include "core/sweep.h"

namespace lpm {

int dominantAxis(const Vec3& w) {
    int a = 0;
    if (std::fabs(w.y) > std::fabs(w[a])) a = 1;
    if (std::fabs(w.z) > std::fabs(w[a])) a = 2;
    return a;
}

// How the r x r ray lattice of one direction samples the lateral coordinate of the voxels
// of slice t. At depth s in [0, 1] of the slice the rays in any voxel sit at
// xi = delta(s) + (j - (r-1)/2) / r, j = 0..r-1, delta(s) = (frac(o + r d (t + s)) - 1/2) / r
// (o the lattice offset, d the lateral shift per slice in voxels), the same for every
// voxel of the slice. Their centroid over the slice is Int delta ds, their spread about it
// (r^2 - 1) / (12 r^2) + Int delta^2 ds - centroid^2; the uniform values are 0 and 1/12.
struct LatticeMoments {
    double centroid = 0, scale = 1;  // scale = (1/12) / spread
    LatticeMoments() = default;
    LatticeMoments(double o, double d, int r, int t) {
        // Antiderivatives of frac(x) - 1/2 and (frac(x) - 1/2)^2.
        auto G1 = [](double x) { const double f = x - std::floor(x); return 0.5 * f * f - 0.5 * f; };
        auto G2 = [](double x) {
            const double fl = std::floor(x), f = x - fl, h = f - 0.5;
            return fl / 12 + (h * h * h + 0.125) / 3;
        };
        const double x0 = o + r * d * t, D = r * d;
        double m1, m2;
        if (std::fabs(D) < 1e-7) {
            const double g = (x0 + 0.5 * D) - std::floor(x0 + 0.5 * D) - 0.5;
            m1 = g;
            m2 = g * g;
        } else {
            // G1 is periodic (frac - 1/2 integrates to zero over a period).
            m1 = (G1(x0 + D) - G1(x0)) / D;
            m2 = (G2(x0 + D) - G2(x0)) / D;
        }
        centroid = m1 / r;
        const double spread = (double(r) * r - 1) / (12.0 * r * r) + std::max(0.0, m2 - m1 * m1) / (double(r) * r);
        scale = spread > 0 ? (1.0 / 12) / spread : 1.0;
    }
};

// Sweeps one direction through the grid slice by slice (Fattal 2009 sec. 4): rays start
// on the entry face on an r x r lattice per voxel, keep sub-voxel positions, and re-enter
// at the opposite lateral face (carrying the boundary radiance again) when they leave
// through a lateral face. The lattice tiles every slice exactly, so the rays' summed
// A_perp * length in each voxel equals its volume.
//
// Linear = true: the linear-characteristic scheme (docs/lpm_solver.md): the source is
// linear inside each voxel, Q(x) = sigma c (U0 + sum_k U_k xi_k) with xi_k the position in
// the voxel in [-1/2, 1/2], and every segment also deposits the first moments
// Int L xi_k ds; phi then holds [voxel][mean, x, y, z][rgb].
template <bool Linear>
void sweepReference(const Medium& m, const Job& job, int r, float* phi, Tally& tally) {
    constexpr int M = Linear ? 4 : 1;
    const int a = job.axis, u = (a + 1) % 3, v = (a + 2) % 3;
    const int N[3] = {m.nx, m.ny, m.nz};
    const size_t stride[3] = {1, size_t(m.nx), size_t(m.nx) * m.ny};
    const bool dense = !m.sparse();
    const double h[3] = {m.voxelSize.x, m.voxelSize.y, m.voxelSize.z};
    const Vec3& w = job.w;
    const double wa = std::fabs(w[a]);
    const double du = w[u] / wa * h[a] / h[u];
    const double dv = w[v] / wa * h[a] / h[v];
    const double sliceLen = h[a] / wa;
    const double aPerp = (h[u] / r) * (h[v] / r) * wa;
    const int nu = N[u], nv = N[v];
    const size_t nRays = size_t(r) * nu * size_t(r) * nv;
    const double inf = std::numeric_limits<double>::infinity();
    const int su = du > 0 ? 1 : -1, sv = dv > 0 ? 1 : -1;
    const double stepU = du != 0 ? 1.0 / std::fabs(du) : inf;
    const double stepV = dv != 0 ? 1.0 / std::fabs(dv) : inf;
    const float* sigma = m.sigmaT.data();
    const float* src = job.src;
    const size_t srcStride = job.srcStride;
    const double scale[3] = {job.srcScale.r, job.srcScale.g, job.srcScale.b};
    const double alb[3] = {m.albedo.r, m.albedo.g, m.albedo.b};
    const double bnd[3] = {job.boundary.r, job.boundary.g, job.boundary.b};

    std::vector<double> pu(nRays), pv(nRays);
    std::vector<double> L(nRays * 3);
    double inj[3] = {0, 0, 0}, esc[3] = {0, 0, 0}, abs_[3] = {0, 0, 0}, sca[3] = {0, 0, 0};
    std::uint64_t segs = 0;
    for (size_t k = 0; k < nRays; ++k) {
        pu[k] = (double(k % (size_t(r) * nu)) + job.offsetU) / r;
        pv[k] = (double(k / (size_t(r) * nu)) + job.offsetV) / r;
        for (int c = 0; c < 3; ++c) {
            L[k * 3 + c] = bnd[c];
            inj[c] += bnd[c];
        }
    }
    const int na = N[a];
    for (int t = 0; t < na; ++t) {
        const int ia = job.sign > 0 ? t : na - 1 - t;
        const size_t base = size_t(ia) * stride[a];
        // Linear source: the ray lattice samples a voxel's lateral coordinates with a centroid
        // and spread that differ from the uniform ones (1/r-sized offsets). Positions are
        // taken relative to the sampled centroid and moments scaled by the sampled spread,
        // so the rays integrate every linear function exactly: sources inject exactly U0 V
        // and a uniform field deposits zero slope (docs/lpm_solver.md).
        LatticeMoments lu, lv;
        if constexpr (Linear) {
            lu = LatticeMoments(job.offsetU, du, r, t);
            lv = LatticeMoments(job.offsetV, dv, r, t);
        }
        for (size_t k = 0; k < nRays; ++k) {
            double* Lk = &L[k * 3];
            double p = pu[k], q = pv[k];
            int cu = std::clamp(int(std::floor(p)), 0, nu - 1);
            int cv = std::clamp(int(std::floor(q)), 0, nv - 1);
            double lamU = du > 0 ? (cu + 1 - p) * stepU : (du < 0 ? (p - cu) * stepU : inf);
            double lamV = dv > 0 ? (cv + 1 - q) * stepV : (dv < 0 ? (q - cv) * stepV : inf);
            double lam = 0;
            for (;;) {
                const double lamN = std::min(std::min(lamU, lamV), 1.0);
                const double len = (lamN - lam) * sliceLen;
                size_t vox = 0;
                if (len > 0) {
                    if (dense) {
                        vox = base + size_t(cu) * stride[u] + size_t(cv) * stride[v];
                    } else {
                        int c3[3];
                        c3[a] = ia;
                        c3[u] = cu;
                        c3[v] = cv;
                        vox = m.index(c3[0], c3[1], c3[2]);
                    }
                }
                if (len > 0 && vox != Medium::npos) {  // unallocated tiles are empty: nothing to do
                    const double s = sigma[vox];
                    const double tau = s * len;
                    float* ph = phi + vox * 3 * M;
                    ++segs;
                    if constexpr (Linear) {
                        // Position in the voxel at the segment start, and its change along it.
                        double xi0[3], dxi[3];
                        xi0[a] = job.sign > 0 ? lam - 0.5 : 0.5 - lam;
                        dxi[a] = job.sign > 0 ? lamN - lam : lam - lamN;
                        double xu = p + lam * du - (cu + 0.5), xv = q + lam * dv - (cv + 0.5);
                        xu -= nu * std::round(xu / nu);  // the ray may have wrapped at a lateral face
                        xv -= nv * std::round(xv / nv);
                        xi0[u] = xu - lu.centroid;
                        xi0[v] = xv - lv.centroid;
                        dxi[u] = (lamN - lam) * du;
                        dxi[v] = (lamN - lam) * dv;
                        const SegmentFactors f(tau, len);
                        double momentScale[3];
                        momentScale[a] = 1;
                        momentScale[u] = lu.scale;
                        momentScale[v] = lv.scale;
                        for (int c = 0; c < 3; ++c) {
                            // Q(t) = qa + qb t / len along the segment.
                            double qa = 0, qb = 0;
                            if (src) {
                                const float* sp = src + vox * srcStride + c;
                                const double k0 = s * scale[c];
                                qa = k0 * sp[0];
                                if (job.srcLinear)
                                    for (int ax = 0; ax < 3; ++ax) {
                                        qa += k0 * sp[3 * (ax + 1)] * xi0[ax];
                                        qb += k0 * sp[3 * (ax + 1)] * dxi[ax];
                                    }
                            }
                            double M0, M1;
                            Lk[c] = f.propagate(Lk[c], qa, qb, M0, M1);
                            ph[c] += float(aPerp * M0);
                            for (int ax = 0; ax < 3; ++ax)
                                ph[3 * (ax + 1) + c] += float(aPerp * momentScale[ax] * (xi0[ax] * M0 + dxi[ax] * M1));
                            sca[c] += s * alb[c] * M0;
                            abs_[c] += s * (1 - alb[c]) * M0;
                            inj[c] += len * (qa + 0.5 * qb);
                        }
                    } else if (tau == 0) {
                        for (int c = 0; c < 3; ++c) ph[c] += float(aPerp * Lk[c] * len);
                    } else {
                        const double em = std::expm1(-tau);  // T - 1
                        const double T = 1 + em;
                        const double e1 = tau < 1e-4 ? len * (1 - tau * (0.5 - tau / 6)) : len * (-em) / tau;
                        const double e2 = tau < 1e-3 ? len * len * (0.5 - tau * (1.0 / 6 - tau / 24))
                                                     : len * len * (tau + em) / (tau * tau);
                        for (int c = 0; c < 3; ++c) {
                            const double Q = src ? s * scale[c] * src[vox * srcStride + c] : 0.0;
                            const double I = Lk[c] * e1 + Q * e2;  // Int L ds over the segment
                            Lk[c] = Lk[c] * T + Q * e1;
                            ph[c] += float(aPerp * I);
                            sca[c] += s * alb[c] * I;
                            abs_[c] += s * (1 - alb[c]) * I;
                            inj[c] += Q * len;
                        }
                    }
                }
                lam = lamN;
                if (lamN >= 1.0) break;
                if (lamU <= lamV) {
                    cu += su;
                    lamU += stepU;
                    if (cu < 0 || cu >= nu) {  // left through a lateral face: re-enter opposite
                        cu = cu < 0 ? nu - 1 : 0;
                        for (int c = 0; c < 3; ++c) {
                            esc[c] += Lk[c];
                            Lk[c] = bnd[c];
                            inj[c] += bnd[c];
                        }
                    }
                } else {
                    cv += sv;
                    lamV += stepV;
                    if (cv < 0 || cv >= nv) {
                        cv = cv < 0 ? nv - 1 : 0;
                        for (int c = 0; c < 3; ++c) {
                            esc[c] += Lk[c];
                            Lk[c] = bnd[c];
                            inj[c] += bnd[c];
                        }
                    }
                }
            }
            p += du;
            q += dv;
            p -= std::floor(p / nu) * nu;
            q -= std::floor(q / nv) * nv;
            pu[k] = p;
            pv[k] = q;
        }
    }
    for (size_t k = 0; k < nRays; ++k)
        for (int c = 0; c < 3; ++c) esc[c] += L[k * 3 + c];
    // Boundary and escape terms were summed as radiance per ray; source terms as Q*len
    // per ray (radiance * length); interactions as sigma * Int L ds. All scale by A_perp * w_i.
    const double k = aPerp * job.weight;
    for (int c = 0; c < 3; ++c) {
        tally.injected[c] += inj[c] * k;
        tally.escaped[c] += esc[c] * k;
        tally.absorbed[c] += abs_[c] * k;
        tally.scattered[c] += sca[c] * k;
    }
    tally.segments += segs;
}

template void sweepReference<false>(const Medium&, const Job&, int, float*, Tally&);
template void sweepReference<true>(const Medium&, const Job&, int, float*, Tally&);

}  // namespace lpm

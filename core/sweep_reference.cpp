// The reference LPM sweep (one ray at a time, double-precision DDA): the definition the
// fast kernels (core/sweep.cpp: sweepStep, sweepStepLinear) are tested against.
// Equations: docs/lpm_solver.md.
#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "core/lattice_moments.h"
#include "core/segment.h"
#include "core/sweep.h"

namespace lpm {

int dominantAxis(const Vec3& w) {
    int a = 0;
    if (std::fabs(w.y) > std::fabs(w[a])) a = 1;
    if (std::fabs(w.z) > std::fabs(w[a])) a = 2;
    return a;
}

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
class ReferenceSweep {
public:
    static constexpr int M = Linear ? 4 : 1;

    ReferenceSweep(const Medium& m, const Job& job, int r, float* phi)
        : m_(m), job_(job), r_(r), phi_(phi), a_(job.axis), u_((a_ + 1) % 3), v_((a_ + 2) % 3) {
        const int N[3] = {m.nx, m.ny, m.nz};
        const double h[3] = {m.voxelSize.x, m.voxelSize.y, m.voxelSize.z};
        stride_[0] = 1, stride_[1] = size_t(m.nx), stride_[2] = size_t(m.nx) * m.ny;
        const Vec3& w = job.w;
        const double wa = std::fabs(w[a_]);
        du_ = w[u_] / wa * h[a_] / h[u_];
        dv_ = w[v_] / wa * h[a_] / h[v_];
        sliceLen_ = h[a_] / wa;
        aPerp_ = (h[u_] / r) * (h[v_] / r) * wa;
        nu_ = N[u_], nv_ = N[v_], na_ = N[a_];
        nRays_ = size_t(r) * nu_ * size_t(r) * nv_;
        su_ = du_ > 0 ? 1 : -1, sv_ = dv_ > 0 ? 1 : -1;
        stepU_ = du_ != 0 ? 1.0 / std::fabs(du_) : kInf;
        stepV_ = dv_ != 0 ? 1.0 / std::fabs(dv_) : kInf;
        const double scale[3] = {job.srcScale.r, job.srcScale.g, job.srcScale.b};
        const double alb[3] = {m.albedo.r, m.albedo.g, m.albedo.b};
        const double bnd[3] = {job.boundary.r, job.boundary.g, job.boundary.b};
        for (int c = 0; c < 3; ++c) scale_[c] = scale[c], alb_[c] = alb[c], bnd_[c] = bnd[c];
        pu_.resize(nRays_);
        pv_.resize(nRays_);
        L_.resize(nRays_ * 3);
        for (size_t k = 0; k < nRays_; ++k) {
            pu_[k] = (double(k % (size_t(r) * nu_)) + job.offsetU) / r;
            pv_[k] = (double(k / (size_t(r) * nu_)) + job.offsetV) / r;
            for (int c = 0; c < 3; ++c) {
                L_[k * 3 + c] = bnd_[c];
                inj_[c] += bnd_[c];
            }
        }
    }

    void run(Tally& tally) {
        for (int t = 0; t < na_; ++t) slice(t);
        finish(tally);
    }

private:
    static constexpr double kInf = std::numeric_limits<double>::infinity();

    // Slice t: every ray crosses it.
    void slice(int t) {
        ia_ = job_.sign > 0 ? t : na_ - 1 - t;
        base_ = size_t(ia_) * stride_[a_];
        // Linear source: the ray lattice samples a voxel's lateral coordinates with a centroid
        // and spread that differ from the uniform ones (1/r-sized offsets). Positions are
        // taken relative to the sampled centroid and moments scaled by the sampled spread,
        // so the rays integrate every linear function exactly: sources inject exactly U0 V
        // and a uniform field deposits zero slope (docs/lpm_solver.md).
        if constexpr (Linear) {
            lu_ = LatticeMoments(job_.offsetU, du_, r_, t);
            lv_ = LatticeMoments(job_.offsetV, dv_, r_, t);
        }
        for (size_t k = 0; k < nRays_; ++k) traceRay(k);
    }

    // Ray k through the current slice: a DDA over the voxel faces it crosses.
    void traceRay(size_t k) {
        double* Lk = &L_[k * 3];
        double p = pu_[k], q = pv_[k];
        int cu = std::clamp(int(std::floor(p)), 0, nu_ - 1);
        int cv = std::clamp(int(std::floor(q)), 0, nv_ - 1);
        double lamU = du_ > 0 ? (cu + 1 - p) * stepU_ : (du_ < 0 ? (p - cu) * stepU_ : kInf);
        double lamV = dv_ > 0 ? (cv + 1 - q) * stepV_ : (dv_ < 0 ? (q - cv) * stepV_ : kInf);
        double lam = 0;
        const int cu0 = cu, cv0 = cv;
        int stepsU = 0, stepsV = 0;  // face crossings of this slice, before wrapping
        for (;;) {
            const double lamN = std::min(std::min(lamU, lamV), 1.0);
            const double len = (lamN - lam) * sliceLen_;
            size_t vox = 0;
            if (len > 0) {
                if (!m_.sparse()) {
                    vox = base_ + size_t(cu) * stride_[u_] + size_t(cv) * stride_[v_];
                } else {
                    int c3[3];
                    c3[a_] = ia_;
                    c3[u_] = cu;
                    c3[v_] = cv;
                    vox = m_.index(c3[0], c3[1], c3[2]);
                }
            }
            if (len > 0 && vox != Medium::npos) {  // unallocated tiles are empty: nothing to do
                ++segs_;
                if constexpr (Linear) linearSegment(Lk, vox, len, p, q, cu, cv, lam, lamN);
                else constantSegment(Lk, vox, len);
            }
            lam = lamN;
            if (lamN >= 1.0) break;
            if (lamU <= lamV) {
                cu += su_;
                ++stepsU;
                lamU += stepU_;
                if (cu < 0 || cu >= nu_) {  // left through a lateral face: re-enter opposite
                    cu = cu < 0 ? nu_ - 1 : 0;
                    reenter(Lk);
                }
            } else {
                cv += sv_;
                ++stepsV;
                lamV += stepV_;
                if (cv < 0 || cv >= nv_) {
                    cv = cv < 0 ? nv_ - 1 : 0;
                    reenter(Lk);
                }
            }
        }
        pu_[k] = nextPosition(p + du_, cu0 + su_ * stepsU, nu_);
        pv_[k] = nextPosition(q + dv_, cv0 + sv_ * stepsV, nv_);
    }

    // The ray's position for the next slice: inside the cell the DDA's crossings put it in
    // (unwrapped index cell), so a ray that reaches a face exactly at the slice's end (or
    // past it by rounding) crosses it, re-entering at a lateral face, in the next slice's
    // DDA, never by the wrap alone; then wrapped into [0, n).
    // (The clamp written out, so nextafter runs only when p reaches the next cell.)
    static double nextPosition(double p, int cell, int n) {
        if (p < double(cell)) p = double(cell);
        else if (p >= double(cell + 1)) p = std::nextafter(double(cell + 1), double(cell));
        const double wrapped = p - std::floor(p / n) * n;
        return wrapped < n ? wrapped : std::nextafter(double(n), 0.0);
    }

    void reenter(double* Lk) {
        for (int c = 0; c < 3; ++c) {
            esc_[c] += Lk[c];
            Lk[c] = bnd_[c];
            inj_[c] += bnd_[c];
        }
    }

    // A segment of length len in voxel vox with a voxel-constant source.
    void constantSegment(double* Lk, size_t vox, double len) {
        const double s = m_.sigmaT[vox];
        const double tau = s * len;
        float* ph = phi_ + vox * 3 * M;
        const float* src = job_.src;
        if (tau == 0) {
            for (int c = 0; c < 3; ++c) ph[c] += float(aPerp_ * Lk[c] * len);
            return;
        }
        const double em = std::expm1(-tau);  // T - 1
        const double T = 1 + em;
        const double e1 = tau < 1e-4 ? len * (1 - tau * (0.5 - tau / 6)) : len * (-em) / tau;
        const double e2 =
            tau < 1e-3 ? len * len * (0.5 - tau * (1.0 / 6 - tau / 24)) : len * len * (tau + em) / (tau * tau);
        for (int c = 0; c < 3; ++c) {
            const double Q = src ? s * scale_[c] * src[vox * job_.srcStride + c] : 0.0;
            const double I = Lk[c] * e1 + Q * e2;  // Int L ds over the segment
            Lk[c] = Lk[c] * T + Q * e1;
            ph[c] += float(aPerp_ * I);
            sca_[c] += s * alb_[c] * I;
            abs_[c] += s * (1 - alb_[c]) * I;
            inj_[c] += Q * len;
        }
    }

    // A segment with a linear source: the ray enters voxel (cu, cv) of the slice at lam
    // and leaves at lamN (fractions of the slice); deposits the mean and first moments.
    void linearSegment(double* Lk, size_t vox, double len, double p, double q, int cu, int cv, double lam,
                       double lamN) {
        const double s = m_.sigmaT[vox];
        const double tau = s * len;
        float* ph = phi_ + vox * 3 * M;
        // Position in the voxel at the segment start, and its change along it.
        double xi0[3], dxi[3];
        xi0[a_] = job_.sign > 0 ? lam - 0.5 : 0.5 - lam;
        dxi[a_] = job_.sign > 0 ? lamN - lam : lam - lamN;
        double xu = p + lam * du_ - (cu + 0.5), xv = q + lam * dv_ - (cv + 0.5);
        unwrap(xu, nu_);  // the ray may have wrapped at a lateral face
        unwrap(xv, nv_);
        xi0[u_] = xu - lu_.centroid;
        xi0[v_] = xv - lv_.centroid;
        dxi[u_] = (lamN - lam) * du_;
        dxi[v_] = (lamN - lam) * dv_;
        const SegmentFactors f(tau, len);
        double momentScale[3];
        momentScale[a_] = 1;
        momentScale[u_] = lu_.scale;
        momentScale[v_] = lv_.scale;
        for (int c = 0; c < 3; ++c) {
            // Q(t) = qa + qb t / len along the segment.
            double qa = 0, qb = 0;
            if (job_.src) {
                const float* sp = job_.src + vox * job_.srcStride + c;
                const double k0 = s * scale_[c];
                qa = k0 * sp[0];
                if (job_.srcLinear)
                    for (int ax = 0; ax < 3; ++ax) {
                        qa += k0 * sp[3 * (ax + 1)] * xi0[ax];
                        qb += k0 * sp[3 * (ax + 1)] * dxi[ax];
                    }
            }
            double M0, M1;
            Lk[c] = f.propagate(Lk[c], qa, qb, M0, M1);
            ph[c] += float(aPerp_ * M0);
            for (int ax = 0; ax < 3; ++ax)
                ph[3 * (ax + 1) + c] += float(aPerp_ * momentScale[ax] * (xi0[ax] * M0 + dxi[ax] * M1));
            sca_[c] += s * alb_[c] * M0;
            abs_[c] += s * (1 - alb_[c]) * M0;
            inj_[c] += len * (qa + 0.5 * qb);
        }
    }

    // x -= n round(x / n): the offset from a voxel centre of a ray that wrapped at a
    // lateral face; round (a library call) only when it is not 0.
    static void unwrap(double& x, int n) {
        const double q = x / n;
        if (std::fabs(q) >= 0.5) x -= n * std::round(q);
    }

    // The rays still in the block escape. Boundary and escape terms were summed as
    // radiance per ray; source terms as Q*len per ray (radiance * length); interactions as
    // sigma * Int L ds. All scale by A_perp * w_i.
    void finish(Tally& tally) {
        for (size_t k = 0; k < nRays_; ++k)
            for (int c = 0; c < 3; ++c) esc_[c] += L_[k * 3 + c];
        const double k = aPerp_ * job_.weight;
        for (int c = 0; c < 3; ++c) {
            tally.injected[c] += inj_[c] * k;
            tally.escaped[c] += esc_[c] * k;
            tally.absorbed[c] += abs_[c] * k;
            tally.scattered[c] += sca_[c] * k;
        }
        tally.segments += segs_;
    }

    const Medium& m_;
    const Job& job_;
    const int r_;
    float* phi_;
    const int a_, u_, v_;
    size_t stride_[3];
    double du_, dv_, sliceLen_, aPerp_, stepU_, stepV_;
    int nu_, nv_, na_, su_, sv_;
    size_t nRays_;
    double scale_[3], alb_[3], bnd_[3];
    std::vector<double> pu_, pv_, L_;  // per ray: lateral position (voxels), radiance
    double inj_[3] = {0, 0, 0}, esc_[3] = {0, 0, 0}, abs_[3] = {0, 0, 0}, sca_[3] = {0, 0, 0};
    std::uint64_t segs_ = 0;
    int ia_ = 0;              // the current slice's index along the sweep axis
    size_t base_ = 0;         // its storage offset (dense media)
    LatticeMoments lu_, lv_;  // the current slice's lattice moments (linear source)
};

template <bool Linear>
void sweepReference(const Medium& m, const Job& job, int r, float* phi, Tally& tally) {
    if (job.srcBf16) throw Error("LPM", "the reference kernel reads a float source, not a bfloat16 one");
    ReferenceSweep<Linear>(m, job, r, phi).run(tally);
}

template void sweepReference<false>(const Medium&, const Job&, int, float*, Tally&);
template void sweepReference<true>(const Medium&, const Job&, int, float*, Tally&);

}  // namespace lpm

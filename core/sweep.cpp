// The fast LPM sweep for a voxel-constant source (docs/performance.md, "The sweep kernel").
//
// The r x r ray lattice of a direction moves rigidly: after t slices every ray has shifted
// by (t du, t dv) voxels. A ray's lattice index along u is k = r cell + j; its position in
// slice t is cell + (j + o)/r + t du, so all rays of lattice class j share the fraction f_j
// of their position in a voxel and its whole path through the slice: the same segment
// lengths and the same face crossings, in voxels shifted by their cell. Per slice and
// class the sweep is therefore a few events (segments, u and v face crossings) applied to
// whole rows of rays, each segment a loop over contiguous rays and contiguous voxels of a
// dense plane holding the slice's extinction and source (gathered from the 8^3 tiles).
// Crossing a lateral face of the block re-enters a ray at the opposite face with the
// boundary radiance (Fattal's reinjection): one ray per row for a u crossing, a whole row
// for a v crossing. Voxel rows of a slice that lie in unallocated tiles are skipped: rays
// cross empty space unchanged.
//
// Segment (tau = sigma l, T = e^-tau, constant source Q):
//   L_out = L T + Q e1,  Int L ds = L e1 + Q e2,
//   e1 = l (1 - T)/tau,  e2 = l (l - e1)/tau   (series below tau = 1/4: no cancellation)
// Tallies: scattered/absorbed = albedo or (1 - albedo) times sum_voxels sigma Int L ds,
// injected source = sum_voxels Q V / A_perp (the lattice covers each voxel exactly).
#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

#include "core/sweep.h"

#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && !defined(LPM_NO_CLONES)
// One binary, the best of AVX-512 / AVX2+FMA / SSE2 chosen at load time (GCC ifunc).
#define LPM_SIMD_CLONES __attribute__((target_clones("avx512f", "avx2", "default")))
#else
#define LPM_SIMD_CLONES
#endif

namespace lpm {

namespace {

// exp(-x), x >= 0: Cody-Waite reduction x = n ln2 - r, |r| <= ln2/2, Cephes' degree-6
// polynomial, 2^n by exponent bits. Above 87 (where e^-x is denormal) exactly 0.
inline float expNegInline(float x) {
    const float xc = x < 87.0f ? x : 87.0f;  // selects, not std::min: keeps the loop branch-free
    const float y = -xc;
    // Round to nearest by adding 1.5 * 2^23 (no libm call, vectorises without SSE4.1).
    const float n = (y * 1.44269504088896341f + 12582912.0f) - 12582912.0f;
    float r = y - n * 0.693359375f;
    r = r + n * 2.12194440e-4f;
    float p = 1.9875691500e-4f;
    p = p * r + 1.3981999507e-3f;
    p = p * r + 8.3334519073e-3f;
    p = p * r + 4.1665795894e-2f;
    p = p * r + 1.6666665459e-1f;
    p = p * r + 5.0000001201e-1f;
    p = p * r * r + r + 1.0f;
    const std::int32_t e = std::int32_t(n) + 127;  // >= 1 for x <= 87
    const std::int32_t bits = e << 23;
    float scale;
    std::memcpy(&scale, &bits, sizeof scale);
    const float value = p * scale;  // computed unconditionally: a select, not a branch, under -ftrapping-math
    return x < 87.0f ? value : 0.0f;
}

struct Planes {  // one slice of the block, dense, index cu + nu * cv
    std::vector<float> sigma, q[3], dep[3];
    std::vector<int> spanLo, spanHi;  // per voxel row: columns in allocated tiles (tile-granular)
};

// One segment of length len for n rays (radiance L) over n voxels of a plane row.
template <bool Source>
LPM_SIMD_CLONES void segmentRun(int n, float len, const float* __restrict sig, const float* __restrict q0,
                                const float* __restrict q1, const float* __restrict q2, float* __restrict L0,
                                float* __restrict L1, float* __restrict L2, float* __restrict d0,
                                float* __restrict d1, float* __restrict d2) {
    const float len2 = len * len;
    for (int i = 0; i < n; ++i) {
        const float tau = sig[i] * len;
        const float T = expNegInline(tau);
        const float inv = 1.0f / (tau > 1e-30f ? tau : 1e-30f);
        const float e1l = len * (1.0f - T) * inv;
        const float e2l = len * (len - e1l) * inv;
        // Series of (1 - e^-t)/t and (t - 1 + e^-t)/t^2, truncation < 2e-9 below 1/4.
        const float e1s =
            len * (1.0f - tau * (0.5f - tau * (1.0f / 6 - tau * (1.0f / 24 - tau * (1.0f / 120 - tau * (1.0f / 720))))));
        const float e2s =
            len2 * (0.5f - tau * (1.0f / 6 - tau * (1.0f / 24 - tau * (1.0f / 120 - tau * (1.0f / 720 - tau * (1.0f / 5040))))));
        const bool small = tau < 0.25f;
        const float e1 = small ? e1s : e1l, e2 = small ? e2s : e2l;
        if (Source) {
            const float I0 = L0[i] * e1 + q0[i] * e2, I1 = L1[i] * e1 + q1[i] * e2, I2 = L2[i] * e1 + q2[i] * e2;
            L0[i] = L0[i] * T + q0[i] * e1;
            L1[i] = L1[i] * T + q1[i] * e1;
            L2[i] = L2[i] * T + q2[i] * e1;
            d0[i] += I0;
            d1[i] += I1;
            d2[i] += I2;
        } else {
            d0[i] += L0[i] * e1;
            d1[i] += L1[i] * e1;
            d2[i] += L2[i] * e1;
            L0[i] *= T;
            L1[i] *= T;
            L2[i] *= T;
        }
    }
}

inline int wrap(long long x, int n) {
    const long long m = x % n;
    return int(m < 0 ? m + n : m);
}

// The sweep's fixed geometry: axes, per-slice lateral shift, lattice, block and tiles.
struct Geometry {
    int a, u, v, nu, nv, na, r, su, sv;
    double du, dv, sliceLen, aPerp;
    size_t rays;  // r^2 nu nv
    Geometry(const Medium& m, const Job& job, int r_) : r(r_) {
        a = job.axis;
        u = (a + 1) % 3;
        v = (a + 2) % 3;
        const int N[3] = {m.nx, m.ny, m.nz};
        const double h[3] = {m.voxelSize.x, m.voxelSize.y, m.voxelSize.z};
        const double wa = std::fabs(job.w[a]);
        du = job.w[u] / wa * h[a] / h[u];
        dv = job.w[v] / wa * h[a] / h[v];
        sliceLen = h[a] / wa;
        aPerp = (h[u] / r) * (h[v] / r) * wa;
        nu = N[u];
        nv = N[v];
        na = N[a];
        su = du > 0 ? 1 : -1;
        sv = dv > 0 ? 1 : -1;
        rays = size_t(r) * r * nu * nv;
    }
};

// A lattice class's position along one lateral axis: start cell shift S and fraction f.
struct ClassState {
    long long S = 0;
    double f = 0;
};

// The face crossings of one class along one axis within a slice, as lambda in (0, 1],
// matching the reference DDA; advances the state to the next slice.
void crossings(ClassState& st, double d, std::vector<double>& lam) {
    lam.clear();
    if (d != 0) {
        const double step = 1.0 / std::fabs(d);
        double l = d > 0 ? (1 - st.f) * step : st.f * step;
        while (l < 1.0) {
            lam.push_back(l);
            l += step;
        }
    }
    const long long k = (long long)lam.size() * (d > 0 ? 1 : -1);
    st.S += k;
    st.f = st.f + d - double(k);
    // Rounding: keep f in [0, 1) so the next slice starts in the cell the events say.
    st.f = std::clamp(st.f, 0.0, std::nextafter(1.0, 0.0));
}

struct Event {
    double len;  // segment length (0 for a crossing)
    int kind;    // 0 segment, 1 u crossing, 2 v crossing
};

// Merges a class's u and v crossings into its ordered events (u first on ties, as the
// reference DDA); zero-length segments are dropped.
void mergeEvents(const std::vector<double>& lu, const std::vector<double>& lv, double sliceLen, std::vector<Event>& ev) {
    ev.clear();
    size_t i = 0, j = 0;
    double lam = 0;
    for (;;) {
        const double nu = i < lu.size() ? lu[i] : 2.0, nv = j < lv.size() ? lv[j] : 2.0;
        const double next = std::min(std::min(nu, nv), 1.0);
        if (next > lam) ev.push_back({(next - lam) * sliceLen, 0});
        lam = std::max(lam, next);
        if (next >= 1.0) break;
        if (nu <= nv) {
            ev.push_back({0, 1});
            ++i;
        } else {
            ev.push_back({0, 2});
            ++j;
        }
    }
}

// The state of one sweepStep call: rays, the current slice's planes and the tallies.
class StepSweep {
public:
    StepSweep(const Medium& m, const Job& job, int r) : m_(m), job_(job), g_(m, job, r) {
        const float bnd[3] = {job.boundary.r, job.boundary.g, job.boundary.b};
        for (int c = 0; c < 3; ++c) {
            bnd_[c] = bnd[c];
            L_[c].assign(g_.rays, bnd[c]);
            inj_[c] = double(bnd[c]) * double(g_.rays);
        }
        const size_t plane = size_t(g_.nu) * g_.nv;
        P_.sigma.assign(plane, 0.0f);
        for (int c = 0; c < 3; ++c) {
            P_.dep[c].assign(plane, 0.0f);
            if (job.src) P_.q[c].assign(plane, 0.0f);
        }
        P_.spanLo.assign(size_t(g_.nv), 0);
        P_.spanHi.assign(size_t(g_.nv), 0);
        stU_.resize(size_t(r));
        stV_.resize(size_t(r));
        for (int j = 0; j < r; ++j) {
            stU_[j].f = (j + job.offsetU) / r;
            stV_[j].f = (j + job.offsetV) / r;
        }
    }

    void run(float* phi, Tally& tally) {
        const int r = g_.r;
        std::vector<std::vector<double>> lamU(static_cast<size_t>(r)), lamV(static_cast<size_t>(r));
        std::vector<long long> SU(static_cast<size_t>(r)), SV(static_cast<size_t>(r));
        std::vector<Event> ev;
        for (int t = 0; t < g_.na; ++t) {
            const int ia = job_.sign > 0 ? t : g_.na - 1 - t;
            gather(ia);
            for (int j = 0; j < r; ++j) {
                SU[j] = stU_[j].S;
                SV[j] = stV_[j].S;
                crossings(stU_[j], g_.du, lamU[j]);
                crossings(stV_[j], g_.dv, lamV[j]);
            }
            for (int jv = 0; jv < r; ++jv)
                for (int ju = 0; ju < r; ++ju) {
                    mergeEvents(lamU[ju], lamV[jv], g_.sliceLen, ev);
                    const size_t cls = size_t(jv * r + ju) * g_.nv * g_.nu;
                    for (int cellV = 0; cellV < g_.nv; ++cellV)
                        processRow(cls + size_t(cellV) * g_.nu, cellV, SU[ju], SV[jv], ev);
                }
            scatter(ia, phi);
        }
        for (int c = 0; c < 3; ++c)
            for (float x : L_[c]) esc_[c] += x;
        const double k = g_.aPerp * job_.weight, V = m_.voxelVolume();
        const double alb[3] = {m_.albedo.r, m_.albedo.g, m_.albedo.b};
        for (int c = 0; c < 3; ++c) {
            tally.injected[c] += (inj_[c] + injSrc_[c] * V / g_.aPerp) * k;
            tally.escaped[c] += esc_[c] * k;
            tally.scattered[c] += alb[c] * sca_[c] * k;
            tally.absorbed[c] += (1 - alb[c]) * sca_[c] * k;
        }
        tally.segments += segs_;
    }

private:
    // Storage index of the voxel at (slice ia, column cu, row cv) inside tile slot `slot`.
    size_t voxelIndex(std::int32_t slot, int ia, int cu, int cv) const {
        int c3[3];
        c3[g_.a] = ia;
        c3[g_.u] = cu;
        c3[g_.v] = cv;
        if (slot < 0) return size_t(c3[0]) + size_t(m_.nx) * (size_t(c3[1]) + size_t(m_.ny) * c3[2]);
        const int K = Medium::kTile;
        return size_t(slot) * Medium::kTileVoxels + size_t(c3[0] % K) + K * (size_t(c3[1] % K) + K * size_t(c3[2] % K));
    }
    // Slot of tile (tu, tv) in the tile layer of slice ia: -1 dense, -2 unallocated.
    std::int32_t tileSlot(int ia, int tu, int tv) const {
        if (!m_.sparse()) return -1;
        const int K = Medium::kTile;
        int t3[3];
        t3[g_.a] = ia / K;
        t3[g_.u] = tu;
        t3[g_.v] = tv;
        const std::int32_t s =
            m_.tileSlot[size_t(t3[0]) + size_t(m_.tilesX()) * (size_t(t3[1]) + size_t(m_.tilesY()) * t3[2])];
        return s < 0 ? -2 : s;
    }

    // Fills the planes for slice ia over the span of allocated tiles of each tile row.
    void gather(int ia) {
        const int K = Medium::kTile, tnu = (g_.nu + K - 1) / K, tnv = (g_.nv + K - 1) / K;
        const double sc[3] = {job_.srcScale.r, job_.srcScale.g, job_.srcScale.b};
        for (int tv = 0; tv < tnv; ++tv) {
            int first = -1, last = -1;
            for (int tu = 0; tu < tnu; ++tu)
                if (tileSlot(ia, tu, tv) != -2) {
                    if (first < 0) first = tu;
                    last = tu;
                }
            const int lo = first < 0 ? 0 : first * K, hi = first < 0 ? 0 : std::min(g_.nu, (last + 1) * K);
            const int v1 = std::min(g_.nv, (tv + 1) * K);
            for (int cv = tv * K; cv < v1; ++cv) {
                P_.spanLo[cv] = lo;
                P_.spanHi[cv] = hi;
            }
            for (int tu = std::max(first, 0); first >= 0 && tu <= last; ++tu) {
                const std::int32_t slot = tileSlot(ia, tu, tv);
                const int u1 = std::min(g_.nu, (tu + 1) * K);
                for (int cv = tv * K; cv < v1; ++cv)
                    for (int cu = tu * K; cu < u1; ++cu) {
                        const size_t p = size_t(cv) * g_.nu + cu;
                        for (int c = 0; c < 3; ++c) P_.dep[c][p] = 0.0f;
                        if (slot == -2) {
                            P_.sigma[p] = 0.0f;
                            if (job_.src)
                                for (int c = 0; c < 3; ++c) P_.q[c][p] = 0.0f;
                            continue;
                        }
                        const size_t x = voxelIndex(slot, ia, cu, cv);
                        const float s = m_.sigmaT[x];
                        P_.sigma[p] = s;
                        if (job_.src)
                            for (int c = 0; c < 3; ++c)
                                P_.q[c][p] = float(double(s) * sc[c] * job_.src[x * job_.srcStride + c]);
                    }
            }
        }
    }

    // Adds the slice's deposits to phi (allocated voxels only) and tallies them.
    void scatter(int ia, float* phi) {
        const int K = Medium::kTile, tnu = (g_.nu + K - 1) / K, tnv = (g_.nv + K - 1) / K;
        const float aPerp = float(g_.aPerp);
        for (int tv = 0; tv < tnv; ++tv)
            for (int tu = 0; tu < tnu; ++tu) {
                const std::int32_t slot = tileSlot(ia, tu, tv);
                if (slot == -2) continue;
                const int u1 = std::min(g_.nu, (tu + 1) * K), v1 = std::min(g_.nv, (tv + 1) * K);
                for (int cv = tv * K; cv < v1; ++cv)
                    for (int cu = tu * K; cu < u1; ++cu) {
                        const size_t p = size_t(cv) * g_.nu + cu, x = voxelIndex(slot, ia, cu, cv);
                        const double s = P_.sigma[p];
                        for (int c = 0; c < 3; ++c) {
                            const float d = P_.dep[c][p];
                            phi[x * 3 + c] += aPerp * d;
                            sca_[c] += s * d;
                            if (job_.src) injSrc_[c] += P_.q[c][p];
                        }
                    }
            }
    }

    void resetRay(size_t i) {
        for (int c = 0; c < 3; ++c) {
            esc_[c] += L_[c][i];
            L_[c][i] = bnd_[c];
            inj_[c] += bnd_[c];
        }
    }

    // Applies one class's events in slice order to the nu rays of one row starting at ray
    // index `row` (lane = cell along u); SU, SV: the class's cell shifts at slice start.
    void processRow(size_t row, int cellV, long long SU, long long SV, const std::vector<Event>& ev) {
        const int nu = g_.nu, nv = g_.nv;
        long long offU = 0, offV = 0;
        for (const Event& e : ev) {
            if (e.kind == 1) {  // the ray in the boundary column leaves and re-enters opposite
                resetRay(row + size_t(wrap((g_.su > 0 ? nu - 1 : 0) - SU - offU, nu)));
                offU += g_.su;
                continue;
            }
            if (e.kind == 2) {  // the whole row leaves through a v face
                if (wrap(cellV + SV + offV, nv) == (g_.sv > 0 ? nv - 1 : 0))
                    for (int i = 0; i < nu; ++i) resetRay(row + size_t(i));
                offV += g_.sv;
                continue;
            }
            const int vr = wrap(cellV + SV + offV, nv);
            const int lo = P_.spanLo[vr], hi = P_.spanHi[vr];
            if (lo >= hi) continue;  // the voxel row lies in empty tiles: nothing changes
            const int B = wrap(SU + offU, nu);  // lane i sits in column (i + B) mod nu
            segment(e.len, vr, std::max(lo, B), hi, row + size_t(std::max(lo, B) - B));
            segment(e.len, vr, lo, std::min(hi, B), row + size_t(lo + nu - B));
        }
    }

    // One segment for the rays over columns [c0, c1) of voxel row vr, first ray `ray`.
    void segment(double len, int vr, int c0, int c1, size_t ray) {
        if (c1 <= c0) return;
        const size_t p = size_t(vr) * g_.nu + c0;
        float *L0 = &L_[0][ray], *L1 = &L_[1][ray], *L2 = &L_[2][ray];
        float *d0 = &P_.dep[0][p], *d1 = &P_.dep[1][p], *d2 = &P_.dep[2][p];
        if (job_.src)
            segmentRun<true>(c1 - c0, float(len), &P_.sigma[p], &P_.q[0][p], &P_.q[1][p], &P_.q[2][p], L0, L1, L2, d0,
                             d1, d2);
        else
            segmentRun<false>(c1 - c0, float(len), &P_.sigma[p], nullptr, nullptr, nullptr, L0, L1, L2, d0, d1, d2);
        segs_ += std::uint64_t(c1 - c0);
    }

    const Medium& m_;
    const Job& job_;
    const Geometry g_;
    std::vector<float> L_[3];
    Planes P_;
    std::vector<ClassState> stU_, stV_;
    float bnd_[3];
    double inj_[3] = {0, 0, 0}, esc_[3] = {0, 0, 0}, sca_[3] = {0, 0, 0}, injSrc_[3] = {0, 0, 0};
    std::uint64_t segs_ = 0;
};

}  // namespace

float expNeg(float x) { return expNegInline(x); }

void sweepStep(const Medium& m, const Job& job, int r, float* phi, Tally& tally) {
    if (job.srcLinear) throw Error("LPM", "sweepStep takes a voxel-constant source only");
    StepSweep(m, job, r).run(phi, tally);
}

}  // namespace lpm

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
// cross empty space unchanged; so are the chunks at either end of a row that hold no
// extinction and no voxel the caller reads (Medium::wantedS; "dead chunks"), and a slice
// without a live chunk costs only the lattice's crossings (no events; an empty tile layer
// no gather either).
//
// Segment (tau = sigma l, T = e^-tau, constant source Q):
//   L_out = L T + Q e1,  Int L ds = L e1 + Q e2,
//   e1 = l (1 - T)/tau,  e2 = l (l - e1)/tau   (below tau = 1/4 by series, no exp:
//   segmentFactors)
// Tallies: scattered/absorbed = albedo or (1 - albedo) times sum_voxels sigma Int L ds,
// injected source = sum_voxels Q V / A_perp (the lattice covers each voxel exactly).
#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <type_traits>

#include "core/sweep.h"

#include "core/exp_neg.h"
#include "core/lattice_moments.h"
#include "core/linear_segment_lanes.h"
#include "core/malloc_policy.h"
#include "core/scratch_pool.h"
#include "core/simd_clones.h"

namespace lpm {

namespace {

// Layout of a plane chunk: the 8 voxels of one tile along one voxel row, as 8 arrays of 8
// floats (sigma, source q0..q2, deposit d0..d2, 1/sigma or 0 where sigma = 0): 64 floats
// (one 256-byte block), chunks of a row contiguous.
constexpr int kLanes = 8, kChunk = 8 * kLanes;
// Layout of a ray row: 3 channels of nuPad floats each, contiguous.

// Which formulas a chunk's 8 segments need (optical depths tau = sigma l against 1/4).
enum class TauRange { Small, Large, Mixed };

// Segment factors T = e^-tau, e1 = l phi1(tau), e2 = l^2 phi2(tau), with
// phi1 = (1 - e^-t)/t, phi2 = (t - 1 + e^-t)/t^2 (docs/performance.md, "The sweep kernel").
// Below tau = 1/4: phi2 by its series (truncation < 2e-8 relative), then the identities
// phi1 = 1 - tau phi2 and T = 1 - tau phi1: no exp, no division, and sigma e1 = 1 - T holds
// to rounding. From 1/4 on: T by expNegInline, e1 = (1 - T)/sigma and e2 = (l - e1)/sigma
// with 1/sigma from the plane. Mixed chunks compute both and select per lane.
template <TauRange R>
inline void segmentFactors(float sig, float invSig, float len, float len2, float& T, float& e1, float& e2) {
    const float tau = sig * len;
    float Ts = 1.0f, e1s = len, e2s = 0.5f * len2;
    if constexpr (R != TauRange::Large) {
        const float p2 =
            0.5f - tau * (1.0f / 6 - tau * (1.0f / 24 - tau * (1.0f / 120 - tau * (1.0f / 720 - tau * (1.0f / 5040)))));
        const float p1 = 1.0f - tau * p2;
        Ts = 1.0f - tau * p1;
        e1s = len * p1;
        e2s = len2 * p2;
    }
    float Tl = 1.0f, e1l = len, e2l = 0.5f * len2;
    if constexpr (R != TauRange::Small) {
        Tl = expNegInline(tau);
        e1l = (1.0f - Tl) * invSig;
        e2l = (len - e1l) * invSig;
    }
    if constexpr (R == TauRange::Small) {
        T = Ts, e1 = e1s, e2 = e2s;
    } else if constexpr (R == TauRange::Large) {
        T = Tl, e1 = e1l, e2 = e2l;
    } else {
        const bool small = tau < 0.25f;
        T = small ? Ts : Tl;
        e1 = small ? e1s : e1l;
        e2 = small ? e2s : e2l;
    }
}

// One chunk: 8 rays (L0..L2, one per channel) over the chunk's 8 voxels (plane).
template <bool Source, TauRange R>
inline __attribute__((always_inline)) void segmentLanes(float len, float len2, float dk, float* __restrict plane,
                                                        float* __restrict L0, float* __restrict L1,
                                                        float* __restrict L2) {
    const float* __restrict sig = plane;
    const float* __restrict q = plane + kLanes;
    float* __restrict d = plane + 4 * kLanes;
    const float* __restrict invSig = plane + 7 * kLanes;
    for (int i = 0; i < kLanes; ++i) {
        float T, e1, e2;
        segmentFactors<R>(sig[i], invSig[i], len, len2, T, e1, e2);
        if (Source) {
            const float I0 = L0[i] * e1 + q[i] * e2, I1 = L1[i] * e1 + q[kLanes + i] * e2,
                        I2 = L2[i] * e1 + q[2 * kLanes + i] * e2;
            L0[i] = L0[i] * T + q[i] * e1;
            L1[i] = L1[i] * T + q[kLanes + i] * e1;
            L2[i] = L2[i] * T + q[2 * kLanes + i] * e1;
            d[i] += dk * I0;
            d[kLanes + i] += dk * I1;
            d[2 * kLanes + i] += dk * I2;
        } else {
            d[i] += dk * (L0[i] * e1);
            d[kLanes + i] += dk * (L1[i] * e1);
            d[2 * kLanes + i] += dk * (L2[i] * e1);
            L0[i] *= T;
            L1[i] *= T;
            L2[i] *= T;
        }
    }
}

// The formulas a chunk needs, from its smallest and largest sigma (kept beside the planes
// by the gather, gatherChunk). Rounding is monotonic: hi len < 1/4 exactly when every sigma len is.
inline TauRange chunkTauRange(const float* sigRange, float len) {
    if (sigRange[1] * len < 0.25f) return TauRange::Small;
    return sigRange[0] * len >= 0.25f ? TauRange::Large : TauRange::Mixed;
}

// One segment of length len for `chunks` x 8 rays (ray row L: channels nuPad apart) over
// as many voxels of a plane row (chunk layout above), each chunk with the formulas its
// optical depths need (thin media: no exp at all); sigRange: each chunk's smallest and
// largest sigma.
// Deposits are added times dk (1 for a sweep of its own planes; the job's tally weight
// when the planes are shared by a batch).
template <bool Source>
LPM_SIMD_CLONES void segmentChunks(int chunks, float len, float dk, float* __restrict plane,
                                   const float* __restrict sigRange, float* __restrict L, size_t nuPad) {
    const float len2 = len * len;
    float* __restrict L0 = L;
    float* __restrict L1 = L + nuPad;
    float* __restrict L2 = L + 2 * nuPad;
    for (int k = 0; k < chunks; ++k, plane += kChunk, sigRange += 2, L0 += kLanes, L1 += kLanes, L2 += kLanes) {
        switch (chunkTauRange(sigRange, len)) {
            case TauRange::Small:
                segmentLanes<Source, TauRange::Small>(len, len2, dk, plane, L0, L1, L2);
                break;
            case TauRange::Large:
                segmentLanes<Source, TauRange::Large>(len, len2, dk, plane, L0, L1, L2);
                break;
            case TauRange::Mixed:
                segmentLanes<Source, TauRange::Mixed>(len, len2, dk, plane, L0, L1, L2);
                break;
        }
    }
}

// The formulas of the phi functions a linear-source chunk needs (core/linear_segment_lanes.h).
inline PhiRange chunkPhiRange(const float* sigRange, float len) {
    if (sigRange[1] * len < 1.0f) return PhiRange::Series;
    return sigRange[0] * len >= 1.0f ? PhiRange::Recurrence : PhiRange::Mixed;
}

// segmentChunks for the linear source: one segment event g of a lattice class for
// `chunks` x 8 rays over as many chunks of the linear planes (LinearChunk).
LPM_SIMD_CLONES void segmentChunksLinear(int chunks, const LinearSegmentGeometry& g, float dk, float* __restrict plane,
                                         const float* __restrict sigRange, float* __restrict L, size_t nuPad) {
    float* __restrict L0 = L;
    float* __restrict L1 = L + nuPad;
    float* __restrict L2 = L + 2 * nuPad;
    for (int k = 0; k < chunks;
         ++k, plane += LinearChunk::kFloats, sigRange += 2, L0 += kLanes, L1 += kLanes, L2 += kLanes) {
        switch (chunkPhiRange(sigRange, g.len)) {
            case PhiRange::Series:
                linearSegmentLanes<PhiRange::Series>(g, dk, plane, L0, L1, L2);
                break;
            case PhiRange::Recurrence:
                linearSegmentLanes<PhiRange::Recurrence>(g, dk, plane, L0, L1, L2);
                break;
            case PhiRange::Mixed:
                linearSegmentLanes<PhiRange::Mixed>(g, dk, plane, L0, L1, L2);
                break;
        }
    }
}

inline int wrap(long long x, int n) {
    const long long m = x % n;
    return int(m < 0 ? m + n : m);
}

// wrap for x in (-n, 2n), without a division.
inline int wrapNear(int x, int n) { return x < 0 ? x + n : (x >= n ? x - n : x); }

// The sweep's fixed geometry: axes, per-slice lateral shift, lattice, block and tiles.
struct Geometry {
    int a, u, v, nu, nv, na, r, su, sv;
    double du, dv, sliceLen, aPerp;
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
    }
};

// The distance in slices between two crossings along an axis advancing d per slice.
inline double crossingStep(double d) { return d != 0 ? 1.0 / std::fabs(d) : 0.0; }

// A lattice class's position along one lateral axis: start cell shift S and fraction f.
struct ClassState {
    long long S = 0;
    double f = 0;
};

// The face crossings of one class along one axis within a slice, as lambda in (0, 1],
// matching the reference DDA; advances the state to the next slice.
// step: 1 / |d| (crossingStep), fixed for a sweep.
inline void crossings(ClassState& st, double d, double step, std::vector<double>& lam) {
    lam.clear();
    if (d != 0) {
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

// crossings() for a step of at most one face per slice (|d| <= 1, so step >= 1): the
// same arithmetic without a list; true with its lambda when the class crosses a face.
inline bool unitCrossing(ClassState& st, double d, double step, double& lam) {
    bool crossed = false;
    if (d != 0) {
        const double l = d > 0 ? (1 - st.f) * step : st.f * step;
        if (l < 1.0) lam = l, crossed = true;
    }
    const long long k = crossed ? (d > 0 ? 1 : -1) : 0;
    st.S += k;
    st.f = st.f + d - double(k);
    st.f = std::clamp(st.f, 0.0, std::nextafter(1.0, 0.0));
    return crossed;
}

struct Event {
    double len;                 // segment length (0 for a crossing)
    int kind;                   // 0 segment, 1 u crossing, 2 v crossing
    double lam0 = 0, lam1 = 0;  // a segment's start and end, fractions of the slice
};

// Merges a class's u and v crossings into its ordered events (u first on ties, as the
// reference DDA); zero-length segments are dropped.
void mergeEvents(const std::vector<double>& lu, const std::vector<double>& lv, double sliceLen,
                 std::vector<Event>& ev) {
    ev.clear();
    size_t i = 0, j = 0;
    double lam = 0;
    for (;;) {
        const double nu = i < lu.size() ? lu[i] : 2.0, nv = j < lv.size() ? lv[j] : 2.0;
        const double next = std::min(std::min(nu, nv), 1.0);
        if (next > lam) ev.push_back({(next - lam) * sliceLen, 0, lam, next});
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

// A block seen along sweep axis a: tile layers along a, tile rows tv along v, tiles tu
// along u, and where each tile lies in storage.
struct AxisFrame {
    static constexpr int K = Medium::kTile;
    const Medium& m;
    int a, u, v, nu, nv, na, tnu, tnv, tna;
    AxisFrame(const Medium& m_, int axis) : m(m_), a(axis), u((axis + 1) % 3), v((axis + 2) % 3) {
        const int N[3] = {m.nx, m.ny, m.nz};
        nu = N[u];
        nv = N[v];
        na = N[a];
        tnu = (nu + K - 1) / K;
        tnv = (nv + K - 1) / K;
        tna = (na + K - 1) / K;
    }
    // Slot of tile (tu, tv) of tile layer `layer`: -1 dense storage, -2 unallocated.
    std::int32_t tileSlot(int layer, int tu, int tv) const {
        if (!m.sparse()) return -1;
        int t3[3];
        t3[a] = layer;
        t3[u] = tu;
        t3[v] = tv;
        const std::int32_t s =
            m.tileSlot[size_t(t3[0]) + size_t(m.tilesX()) * (size_t(t3[1]) + size_t(m.tilesY()) * t3[2])];
        return s < 0 ? -2 : s;
    }
    // Where tile (layer, tu, tv) lies in storage: the storage index of its first voxel,
    // the strides along u, v and the sweep axis, and its extent inside the block.
    struct TileWalk {
        size_t base, sU, sV, sA;
        int nU, nV, nA;
    };
    TileWalk tileWalk(std::int32_t slot, int layer, int tu, int tv) const {
        int t3[3];
        t3[a] = layer;
        t3[u] = tu;
        t3[v] = tv;
        size_t stride[3];
        TileWalk w;
        if (slot >= 0) {
            stride[0] = 1, stride[1] = K, stride[2] = K * K;
            w.base = size_t(slot) * Medium::kTileVoxels;
        } else {
            stride[0] = 1, stride[1] = size_t(m.nx), stride[2] = size_t(m.nx) * m.ny;
            w.base = size_t(t3[0]) * K + stride[1] * size_t(t3[1] * K) + stride[2] * size_t(t3[2] * K);
        }
        w.sU = stride[u];
        w.sV = stride[v];
        w.sA = stride[a];
        w.nU = std::min(K, nu - tu * K);
        w.nV = std::min(K, nv - tv * K);
        w.nA = std::min(K, na - layer * K);
        return w;
    }
};

// First and last allocated tile along u of every tile row (layer, tv): built once from the
// stored tiles' list (O(stored tiles + rows), not O(tiles of the box)), so the planes'
// set-up, gathers and scatters cost nothing for the empty space of a large box.
class TileRowExtents {
public:
    explicit TileRowExtents(const AxisFrame& f) : tnv_(f.tnv) {
        const size_t rows = size_t(f.tna) * size_t(f.tnv);
        if (!f.m.sparse()) {
            first_.assign(rows, 0);
            last_.assign(rows, f.tnu - 1);
            layerAny_.assign(size_t(f.tna), 1);
            return;
        }
        first_.assign(rows, -1);
        last_.assign(rows, -1);
        layerAny_.assign(size_t(f.tna), 0);
        const size_t tx = size_t(f.m.tilesX()), ty = size_t(f.m.tilesY());
        for (const std::int32_t t : f.m.slotTile) {
            const int t3[3] = {int(size_t(t) % tx), int(size_t(t) / tx % ty), int(size_t(t) / (tx * ty))};
            const int layer = t3[f.a], tu = t3[f.u];
            const size_t row = size_t(layer) * size_t(f.tnv) + size_t(t3[f.v]);
            first_[row] = first_[row] < 0 ? tu : std::min(first_[row], tu);
            last_[row] = std::max(last_[row], tu);
            layerAny_[size_t(layer)] = 1;
        }
    }
    // First and last allocated tile of tile row tv in a layer (-1, -1 when none).
    void rowExtent(int layer, int tv, int& first, int& last) const {
        const size_t row = size_t(layer) * size_t(tnv_) + size_t(tv);
        first = first_[row];
        last = last_[row];
    }
    // Whether a tile layer holds any allocated tile.
    bool layerAny(int layer) const { return layerAny_[size_t(layer)] != 0; }

private:
    int tnv_;
    std::vector<int> first_, last_;       // per tile row (layer, tv)
    std::vector<std::uint8_t> layerAny_;  // per tile layer
};

// Plane storage of one tile row tv in one tile layer: the chunks of tiles first ..
// first + width - 1; voxel row (cv, slice s of the layer) holds one chunk per tile.
struct PlaneRow {
    size_t base = 0;
    int first = 0, width = 0;
};

// Plane offset of the sigma of (row cv, slice s of the layer, column cu); cu must lie in
// the row's span. All three are >= 0: unsigned division by the tile size is a shift.
// Chunk: floats of a plane chunk (kChunk, or LinearChunk::kFloats for the linear source).
template <int Chunk = kChunk>
inline size_t planeIndex(const PlaneRow* rows, int cv, int s, int cu) {
    constexpr unsigned K = Medium::kTile;
    const unsigned v = unsigned(cv), u = unsigned(cu);
    const PlaneRow& pr = rows[v / K];
    return pr.base +
           (size_t((v % K) * K + unsigned(s)) * unsigned(pr.width) + size_t(u / K - unsigned(pr.first))) * Chunk +
           size_t(u % K);
}

// What a gather reads: the medium's sigma, the job's source (q = sigma srcScale src) and
// the voxels whose deposits the caller reads (Medium::wantedS; null: every stored voxel).
struct GatherSource {
    const float* sigma;
    const float* src;
    const Bf16* srcBf16;
    const std::uint8_t* wanted;
    size_t stride;
    float scale[3];
    bool slopes;  // src holds the linear source's slopes after the mean (Job::srcLinear)
    GatherSource(const Medium& m, const Job& job)
        : sigma(m.sigmaT.data()), src(job.src), srcBf16(job.srcBf16),
          wanted(m.wantedS.empty() ? nullptr : m.wantedS.data()),
          stride(job.srcStride), scale{job.srcScale.r, job.srcScale.g, job.srcScale.b}, slopes(job.srcLinear) {}
};

// The source of voxel x (sigma sg) into lane q of a constant chunk: q = sigma scale src.
inline void gatherConstantSource(const GatherSource& g, size_t x, float sg, float* q) {
    if (g.src)
        for (int c = 0; c < 3; ++c) q[(1 + c) * kLanes] = sg * g.scale[c] * g.src[x * g.stride + c];
    else if (g.srcBf16)
        for (int c = 0; c < 3; ++c) q[(1 + c) * kLanes] = sg * g.scale[c] * floatFromBf16(g.srcBf16[x * g.stride + c]);
}

// The same into lane q of a linear chunk (LinearChunk): q0 and the slopes, each times
// sigma and the job's scale (0 without a source or slopes).
inline void gatherLinearSource(const GatherSource& g, size_t x, float sg, float* q) {
    constexpr int n = LinearChunk::kLanes;
    if (!g.src) return;
    const float* sp = g.src + x * g.stride;
    for (int c = 0; c < 3; ++c) {
        const float k0 = sg * g.scale[c];
        q[(LinearChunk::kQ0 + c) * n] = k0 * sp[c];
        if (g.slopes)
            for (int ax = 0; ax < 3; ++ax) q[(LinearChunk::kSlope + 3 * ax + c) * n] = k0 * sp[3 * (ax + 1) + c];
    }
}

// One chunk (the nU voxels of a tile row segment from storage index x0, stride sU) into
// the planes at q: sigma, the source, deposits zeroed, 1/sigma; its smallest and largest
// sigma into range. empty: an unallocated tile inside a span (reads as empty). Returns
// whether the chunk is live: it holds extinction or a voxel whose deposit is read. Rays
// cross a dead chunk unchanged and nothing reads its deposits (no sigma to scatter them,
// no caller), so the sweep may skip it (docs/performance.md, "Dead chunks"). Linear: the
// linear source's chunk (LinearChunk; sigma and q0 lie where the constant chunk has them).
template <bool Linear>
inline bool gatherChunk(const GatherSource& g, bool empty, size_t x0, size_t sU, int nU, float* q, float* range) {
    constexpr int floats = Linear ? LinearChunk::kFloats : kChunk, invSigma = Linear ? LinearChunk::kInvSigma : 7;
    std::fill_n(q, floats, 0.0f);
    range[0] = range[1] = 0.0f;
    if (empty) return false;
    bool wanted = !g.wanted;
    for (int lu = 0; lu < nU; ++lu) {
        const size_t x = x0 + size_t(lu) * sU;
        if (g.wanted) wanted = wanted || g.wanted[x];
        const float sg = g.sigma[x];
        q[lu] = sg;
        if constexpr (Linear) gatherLinearSource(g, x, sg, q + lu);
        else gatherConstantSource(g, x, sg, q + lu);
    }
    // 1/sigma over the whole chunk at once: one vector division (padding lanes are 0).
    for (int i = 0; i < kLanes; ++i) q[invSigma * kLanes + i] = q[i] > 0 ? 1.0f / q[i] : 0.0f;
    range[0] = *std::min_element(q, q + kLanes);
    range[1] = *std::max_element(q, q + kLanes);
    return wanted || range[1] > 0;
}

// The columns a sweep crosses in each (voxel row, slice) of a tile layer: from the first
// live chunk to the last (tile-aligned start; the end clipped to the block), lo = hi when
// none is live. Index: voxel row cv times the tile size plus the slice within the layer.
struct LiveSpans {
    int* lo;
    int* hi;
};

// Tiles first..last of tile row tv into the planes (and each chunk's sigma range into R,
// 2 floats a chunk), in plane order (voxel row, slice, tile), so the writes stream through
// consecutive chunks; the tiles' reads (a few KB each) stay in cache across the row. Sets
// the live spans of the row's (voxel row, slice) pairs. linear: the planes hold the linear
// source's chunks (LinearChunk).
LPM_SIMD_CLONES
void gatherTileRow(const AxisFrame& f, const GatherSource& g, const PlaneRow* rows, float* P, float* R, int layer,
                   int tv, int first, int last, std::vector<AxisFrame::TileWalk>& walks,
                   std::vector<std::uint8_t>& empty, LiveSpans spans, bool linear) {
    constexpr int K = Medium::kTile;
    const int n = last - first + 1;
    walks.resize(size_t(n));
    empty.resize(size_t(n));
    for (int i = 0; i < n; ++i) {
        const std::int32_t slot = f.tileSlot(layer, first + i, tv);
        empty[size_t(i)] = slot == -2;
        walks[size_t(i)] = f.tileWalk(slot == -2 ? -1 : slot, layer, first + i, tv);
    }
    const int nV = walks[0].nV, nA = walks[0].nA;  // the same for every tile of the row
    for (int lv = 0; lv < nV; ++lv)
        for (int s = 0; s < nA; ++s) {
            const size_t chunkFloats = linear ? size_t(LinearChunk::kFloats) : size_t(kChunk);
            const size_t at = linear ? planeIndex<LinearChunk::kFloats>(rows, tv * K + lv, s, first * K)
                                     : planeIndex(rows, tv * K + lv, s, first * K);
            int liveFirst = -1, liveLast = -1;
            for (int i = 0; i < n; ++i) {
                const AxisFrame::TileWalk& w = walks[size_t(i)];
                const size_t chunk = at / chunkFloats + size_t(i);
                const size_t x0 = w.base + size_t(s) * w.sA + size_t(lv) * w.sV;
                float* q = &P[chunk * chunkFloats];
                const bool live = linear ? gatherChunk<true>(g, empty[size_t(i)], x0, w.sU, w.nU, q, &R[2 * chunk])
                                         : gatherChunk<false>(g, empty[size_t(i)], x0, w.sU, w.nU, q, &R[2 * chunk]);
                if (live) {
                    if (liveFirst < 0) liveFirst = i;
                    liveLast = i;
                }
            }
            const size_t at2 = size_t(tv * K + lv) * K + size_t(s);
            spans.lo[at2] = liveFirst < 0 ? 0 : (first + liveFirst) * K;
            spans.hi[at2] = liveFirst < 0 ? 0 : std::min(f.nu, (first + liveLast + 1) * K);
        }
}

// The chunks of allocated tile (tu, tv) of a tile layer in the planes (Chunk floats each),
// one per voxel row of the tile: row(q, x0, w) with the chunk, the storage index of its
// first voxel and the tile's walk (w.nU voxels, w.sU apart). Nothing for an unallocated tile.
template <int Chunk, class Row>
inline void forTileChunks(const AxisFrame& f, const PlaneRow* rows, float* P, int layer, int tu, int tv, Row&& row) {
    constexpr int K = Medium::kTile;
    const std::int32_t slot = f.tileSlot(layer, tu, tv);
    if (slot == -2) return;
    const AxisFrame::TileWalk w = f.tileWalk(slot, layer, tu, tv);
    for (int s = 0; s < w.nA; ++s)
        for (int lv = 0; lv < w.nV; ++lv)
            row(&P[planeIndex<Chunk>(rows, tv * K + lv, s, tu * K)], w.base + size_t(s) * w.sA + size_t(lv) * w.sV, w);
}

// One allocated tile's deposits times k into phi (added, or assigned: phi's earlier values
// there are overwritten; a bfloat16 phi, core/bf16.h, only assigned); sums sigma d (sca)
// and q (src), from the float deposits. clear: the deposits read are zeroed (planes shared
// by a group, each sweep scattering its own).
template <bool Assign, class Out>
void scatterTile(const AxisFrame& f, const PlaneRow* rows, float* P, int layer, int tu, int tv, float k, Out* phi,
                 double sca[3], double src[3], bool clear) {
    static_assert(Assign || std::is_same_v<Out, float>, "bfloat16 deposits are assigned, never added to");
    float ts[3] = {0, 0, 0}, tq[3] = {0, 0, 0};
    forTileChunks<kChunk>(f, rows, P, layer, tu, tv, [&](float* q, size_t x0, const AxisFrame::TileWalk& w) {
        // bfloat16: the chunk's values rounded at once (contiguous lanes: vector code),
        // then stored at the voxels' strided places.
        std::uint16_t rounded[3][kLanes];
        if constexpr (std::is_same_v<Out, Bf16>)
            for (int c = 0; c < 3; ++c)
                for (int lu = 0; lu < kLanes; ++lu) rounded[c][lu] = bf16FromFloat(k * q[(4 + c) * kLanes + lu]).bits;
        for (int lu = 0; lu < w.nU; ++lu) {
            Out* ph = &phi[(x0 + size_t(lu) * w.sU) * 3];
            for (int c = 0; c < 3; ++c) {
                const float d = q[(4 + c) * kLanes + lu];
                if constexpr (std::is_same_v<Out, Bf16>) ph[c].bits = rounded[c][lu];
                else if constexpr (Assign) ph[c] = k * d;
                else ph[c] += k * d;
                ts[c] += q[lu] * d;
                tq[c] += q[(1 + c) * kLanes + lu];
            }
        }
        if (clear)
            for (int c = 0; c < 3; ++c) std::fill_n(&q[(4 + c) * kLanes], w.nU, 0.0f);
    });
    for (int c = 0; c < 3; ++c) {
        sca[c] += ts[c];
        src[c] += tq[c];
    }
}

// One voxel's 12 deposits times k into a whole linear buffer, phi [stored voxel][mean, x,
// y, z][rgb] (= when Assign, else +=).
template <bool Assign>
inline void putLinearVoxel(float* phi, size_t x, const float* q, int lu, float k) {
    constexpr int n = LinearChunk::kLanes;
    float* ph = &phi[x * 12];
    for (int j = 0; j < 12; ++j) {
        const float d = k * q[(LinearChunk::kDeposit + j) * n + lu];
        if constexpr (Assign) ph[j] = d;
        else ph[j] += d;
    }
}

// The same into a batch's split deposits: the mean in float, the first moments rounded to
// bfloat16 (slopes: the chunk's first moments times k, rounded at once when Assign).
template <bool Assign>
inline void putLinearVoxel(LinearBatchDeposits out, size_t x, const float* q, int lu, float k,
                           const std::uint16_t (*slopes)[LinearChunk::kLanes]) {
    constexpr int n = LinearChunk::kLanes;
    if (out.whole) return putLinearVoxel<Assign>(out.whole, x, q, lu, k);
    for (int c = 0; c < 3; ++c) {
        const float d = k * q[(LinearChunk::kDeposit + c) * n + lu];
        if constexpr (Assign) out.mean[x * 3 + size_t(c)] = d;
        else out.mean[x * 3 + size_t(c)] += d;
    }
    Bf16* s = &out.slopes[x * 9];
    for (int j = 0; j < 9; ++j) {
        if constexpr (Assign) s[j].bits = slopes[j][lu];
        else s[j] = bf16FromFloat(floatFromBf16(s[j]) + k * q[(LinearChunk::kDeposit + 3 + j) * n + lu]);
    }
}

// scatterTile for the linear source's chunks (LinearChunk): the deposits times k into
// phi (a float* buffer [stored voxel][mean, x, y, z][rgb], or a batch's
// LinearBatchDeposits), assigned when Assign, else added; sums sigma d_mean (sca) and q0
// (src). clear: the deposits read are zeroed (a group's planes).
template <bool Assign, class Target>
void scatterTileLinear(const AxisFrame& f, const PlaneRow* rows, float* P, int layer, int tu, int tv, float k,
                       Target phi, double sca[3], double src[3], bool clear) {
    constexpr int n = LinearChunk::kLanes;
    float ts[3] = {0, 0, 0}, tq[3] = {0, 0, 0};
    forTileChunks<LinearChunk::kFloats>(
        f, rows, P, layer, tu, tv, [&](float* q, size_t x0, const AxisFrame::TileWalk& w) {
            std::uint16_t slopes[9][n];  // contiguous lanes: vector code
            if constexpr (Assign && std::is_same_v<Target, LinearBatchDeposits>)
                for (int j = 0; j < 9 && !phi.whole; ++j)
                    for (int lu = 0; lu < n; ++lu)
                        slopes[j][lu] = bf16FromFloat(k * q[(LinearChunk::kDeposit + 3 + j) * n + lu]).bits;
            for (int lu = 0; lu < w.nU; ++lu) {
                const size_t x = x0 + size_t(lu) * w.sU;
                if constexpr (std::is_same_v<Target, float*>) putLinearVoxel<Assign>(phi, x, q, lu, k);
                else putLinearVoxel<Assign>(phi, x, q, lu, k, slopes);
                for (int c = 0; c < 3; ++c) {
                    ts[c] += q[LinearChunk::kSigma * n + lu] * q[(LinearChunk::kDeposit + c) * n + lu];
                    tq[c] += q[(LinearChunk::kQ0 + c) * n + lu];
                }
            }
            if (clear) std::fill_n(&q[LinearChunk::kDeposit * n], 12 * n, 0.0f);
        });
    for (int c = 0; c < 3; ++c) {
        sca[c] += ts[c];
        src[c] += tq[c];
    }
}

// The planes of one tile layer for a sweep axis: per tile row tv the chunks of the tiles
// between the first and the last allocated one over all layers (so a sparse volume in a
// large box costs no plane memory for its empty space), filled one layer at a time with
// sigma, 1/sigma and the source and zeroed deposits, and scattered back after the layer.
// One sweep owns one; a batch of sweeps of the same axis, sign and source shares one, each
// sweep adding its deposits times its weight (sweepStepBatch).
class LayerPlanes {
public:
    static constexpr int K = Medium::kTile;

    // linear: chunks of the linear source (LinearChunk), scattered by scatterLinear.
    LayerPlanes(const Medium& m, int axis, bool linear = false)
        : f_(m, axis), ext_(f_), linear_(linear), chunk_(linear ? LinearChunk::kFloats : kChunk) {
        rows_.assign(size_t(f_.tnv), PlaneRow{});
        size_t total = 0;
        for (int tv = 0; tv < f_.tnv; ++tv) {
            int first = f_.tnu, last = -1;
            for (int layer = 0; layer < f_.tna; ++layer) {
                int lf, ll;
                ext_.rowExtent(layer, tv, lf, ll);
                if (lf < 0) continue;
                first = std::min(first, lf);
                last = std::max(last, ll);
            }
            PlaneRow& pr = rows_[size_t(tv)];
            pr.first = last < 0 ? 0 : first;
            pr.width = last < 0 ? 0 : last - first + 1;
            pr.base = total;
            total += size_t(pr.width) * K * K * size_t(chunk_);
        }
        assignZeroed(P_, total);
        assignZeroed(range_, 2 * (total / size_t(chunk_)));
        spanLo_.assign(size_t(f_.nv) * K, 0);
        spanHi_.assign(size_t(f_.nv) * K, 0);
    }

    // Fills the layer's planes over the span of allocated tiles of each tile row and sets
    // the voxel rows' spans (tile-granular); returns whether the layer holds any allocated tile.
    bool gather(int layer, const Job& srcJob) {
        for (std::vector<int>& rows : occupied_) rows.clear();
        for (int tv : spanRows_) {  // the tile rows the last gather gave spans
            const int cv0 = tv * K, cv1 = std::min(f_.nv, (tv + 1) * K);
            std::fill(spanLo_.begin() + cv0 * K, spanLo_.begin() + cv1 * K, 0);
            std::fill(spanHi_.begin() + cv0 * K, spanHi_.begin() + cv1 * K, 0);
        }
        spanRows_.clear();
        if (!ext_.layerAny(layer)) return false;
        for (int tv = 0; tv < f_.tnv; ++tv) {
            int first, last;
            ext_.rowExtent(layer, tv, first, last);
            if (first < 0) continue;
            const int cv0 = tv * K, cv1 = std::min(f_.nv, (tv + 1) * K);
            spanRows_.push_back(tv);
            gatherTileRow(f_, GatherSource(f_.m, srcJob), rows_.data(), P_.data(), range_.data(), layer, tv, first,
                          last, walks_, empty_, LiveSpans{spanLo_.data(), spanHi_.data()}, linear_);
            for (int cv = cv0; cv < cv1; ++cv)
                for (int s = 0; s < K; ++s)
                    if (spanLo_[size_t(cv) * K + s] < spanHi_[size_t(cv) * K + s]) occupied_[s].push_back(cv);
        }
        return true;
    }

    // phi += k * the layer's deposits (allocated voxels only), or phi = when Assign (each
    // tile lies in one layer, so a sweep writes each of the block's stored voxels once);
    // sums sigma d and q. clear: those deposits are zeroed for the next sweep of a group
    // (sweepStepGroup).
    template <bool Assign = false, class Out = float>
    void scatter(int layer, float k, Out* phi, double sca[3], double src[3], bool clear = false) {
        for (int tv = 0; tv < f_.tnv; ++tv) {
            int first, last;
            ext_.rowExtent(layer, tv, first, last);
            for (int tu = std::max(first, 0); tu <= last; ++tu)
                scatterTile<Assign>(f_, rows_.data(), P_.data(), layer, tu, tv, k, phi, sca, src, clear);
        }
    }

    // The linear source's phi (scatterTileLinear's targets) += k * the layer's deposits
    // (= when Assign); clear as scatter's.
    template <bool Assign = false, class Target = float*>
    void scatterLinear(int layer, float k, Target phi, double sca[3], double src[3], bool clear = false) {
        for (int tv = 0; tv < f_.tnv; ++tv) {
            int first, last;
            ext_.rowExtent(layer, tv, first, last);
            for (int tu = std::max(first, 0); tu <= last; ++tu)
                scatterTileLinear<Assign>(f_, rows_.data(), P_.data(), layer, tu, tv, k, phi, sca, src, clear);
        }
    }

    const PlaneRow* rows() const { return rows_.data(); }
    float* data() { return P_.data(); }
    /// Per chunk of data(): its smallest and largest sigma.
    const float* sigRanges() const { return range_.data(); }
    /// Per (voxel row, slice of the layer), index cv K + s: the live columns [lo, hi)
    /// (LiveSpans); lo is tile-aligned.
    const int* spanLo() const { return spanLo_.data(); }
    const int* spanHi() const { return spanHi_.data(); }
    /// The voxel rows with live columns in slice `slice` of this layer, in increasing order.
    const std::vector<int>& occupied(int slice) const { return occupied_[size_t(slice)]; }

private:
    AxisFrame f_;
    TileRowExtents ext_;
    bool linear_ = false;                       // the linear source's chunks
    int chunk_ = kChunk;                        // floats of a chunk
    std::vector<PlaneRow> rows_;                // per tile row, over all layers
    std::vector<float> P_;                      // the current tile layer
    std::vector<float> range_;                  // per chunk of P_: smallest and largest sigma
    std::vector<int> spanLo_, spanHi_;          // per (voxel row, slice): its live columns (LiveSpans)
    std::array<std::vector<int>, K> occupied_;  // per slice of the layer: voxel rows with live columns
    std::vector<int> spanRows_;                 // tile rows whose spans the last gather set
    std::vector<AxisFrame::TileWalk> walks_;    // gather scratch: one tile row's tiles
    std::vector<std::uint8_t> empty_;
};

// The state of one sweep: rays, the planes of the current tile layer (its own, or a
// batch's) and the tallies. Rays: ray row (cell v, class) is row index cellV r^2 + class;
// a pristine row has no storage of its own (every ray holds the boundary radiance). A
// written row keeps only the columns the kernel has touched (vlo .. vhi - 1; the other
// rays hold the boundary radiance) in a window of cap columns starting at column org, 3
// channels of cap lanes: a u crossing moves the window with the rays instead of moving
// data. Storage, by how full the block is:
// - dense: every row has a slot of C = nuPad + slack lanes per channel in one arena, in
//   row order (rows are walked in that order: the prefetcher follows); the window is
//   re-centred within the slot when the kernel needs columns outside it (about once every
//   slack crossings);
// - sparse (a few puffs in a large box): a written row gets a block of its own (a power of
//   two of columns), replaced by a larger one when the kernel needs columns
//   outside it, so a row costs what the density it meets is wide, not what the block is.
// Columns >= nu are padding.
class StepSweep {
public:
    static constexpr int K = Medium::kTile;

    // shared: the batch's planes (the deposits are then added there times the job's
    // weight A_perp w, and scattered by the batch); null: the sweep's own. ownDeposits:
    // shared planes (a group's) whose deposits this sweep scatters itself (scatterOwn),
    // exactly as with planes of its own.
    // linear: the linear source's sweep (planes of LinearChunk, its own or shared; phi
    // holds 4 moments).
    StepSweep(const Medium& m, const Job& job, int r, float depositScale, LayerPlanes* shared = nullptr,
              bool ownDeposits = false, bool linear = false)
        : m_(m), job_(job), g_(m, job, r), f_(m, job.axis), depositScale_(depositScale), linear_(linear) {
        rows_count_ = size_t(r) * r * g_.nv;
        // A ray row gets storage only when it first meets allocated voxels (pristine_), so
        // the rays of empty space cost neither memory traffic nor pages.
        // Dense enough blocks keep every row's slot in one arena in row order; sparse ones
        // give each written row a block of its own, sized to the columns it touched.
        const size_t tiles = size_t(m.tilesX()) * m.tilesY() * m.tilesZ();
        dense_ = !m.sparse() || m.storedTiles * kSparseBlockRatio >= tiles;
        // Slack: a quarter of the row's width, 8 to 64 columns (re-centring every slack
        // crossings moves only the touched columns; more slack widens every slot).
        slack_ = std::clamp((f_.tnu * K / 4) & ~7, 8, kMaxSlack);
        C_ = f_.tnu * K + slack_;
        // The arena (attachArena) is uninitialised: a row's slot is written only when the row
        // first meets allocated voxels, so the rows of empty space cost no memory traffic.
        // A row's state is set when it first becomes a candidate (touch) or is written
        // (materialize, grow): most rows of a sparse block never are, so a sweep's set-up
        // fills only the flags below.
        block_.reset(new float*[rows_count_]);
        cap_.reset(new int[rows_count_]);
        org_.reset(new int[rows_count_]);
        vlo_.reset(new int[rows_count_]);
        vhi_.reset(new int[rows_count_]);
        padFilled_.reset(new std::uint8_t[rows_count_]);
        pending_.reset(new int[rows_count_]);
        seenU_.reset(new int[rows_count_]);
        pristine_.assign(rows_count_, 1);
        mark_.assign(rows_count_, 0);
        touched_.assign((rows_count_ + 63) / 64, 0);
        classU_.assign(size_t(r) * r, 0);
        cellBits_.assign(size_t(g_.nv + 63) / 64, 0);
        uCount_.assign(size_t(r) * r, 0);
        for (int c = 0; c < 3; ++c) bnd_[c] = job.boundary[c];
        unitSteps_ = std::fabs(g_.du) <= 1 && std::fabs(g_.dv) <= 1;
        // Every ray of the lattice starts holding the boundary radiance (padding lanes excluded).
        bndIn_ = std::uint64_t(r) * std::uint64_t(r) * std::uint64_t(g_.nu) * std::uint64_t(g_.nv);
        dk_ = shared && !ownDeposits ? float(g_.aPerp * job.weight) : 1.0f;
        if (!shared) own_ = std::make_unique<LayerPlanes>(m, job.axis, linear);
        planes_ = shared ? shared : own_.get();
        stU_.resize(size_t(r));
        stV_.resize(size_t(r));
        for (int j = 0; j < r; ++j) {
            stU_[j].f = (j + job.offsetU) / r;
            stV_[j].f = (j + job.offsetV) / r;
        }
    }

    ~StepSweep() = default;
    StepSweep(const StepSweep&) = delete;
    StepSweep& operator=(const StepSweep&) = delete;

    // Floats of the dense arena of ray-row slots (0 when sparse).
    size_t arenaFloats() const { return dense_ ? rows_count_ * 3 * size_t(C_) : 0; }
    // Storage for arenaFloats() floats, uninitialised (core/scratch_pool.h); before sweeping.
    void attachArena(float* arena) { arena_ = arena; }

    // A sweep with its own planes: every layer gathered, swept and scattered to phi.
    void run(float* phi, Tally& tally) {
        const ScratchBlock arena(arenaFloats());
        attachArena(arena.data());
        const float k = float(g_.aPerp) * depositScale_;
        for (int l = 0; l < f_.tna; ++l) {
            const int layer = layerAt(l);
            const bool any = planes_->gather(layer, job_);
            sweepLayer(layer, any);
            if (any && linear_) planes_->scatterLinear(layer, k, phi, sca_, injSrc_);
            else if (any) planes_->scatter(layer, k, phi, sca_, injSrc_);
        }
        finish(tally);
    }

    // After sweepLayer on a group's planes: phi = this sweep's deposits of the layer,
    // which are zeroed for the next sweep of the group.
    template <class Out>
    void scatterOwn(int layer, Out* phi) {
        if constexpr (std::is_same_v<Out, float>)
            if (linear_)
                return planes_->scatterLinear<true>(layer, float(g_.aPerp) * depositScale_, phi, sca_, injSrc_, true);
        planes_->scatter<true>(layer, float(g_.aPerp) * depositScale_, phi, sca_, injSrc_, true);
    }

    // The l-th tile layer this sweep crosses (its direction's order along the axis).
    int layerAt(int l) const { return job_.sign > 0 ? l : f_.tna - 1 - l; }

    // The slices of one tile layer, whose planes have been gathered; any: it holds
    // allocated tiles.
    void sweepLayer(int layer, bool any) {
        const int s0 = layer * K, s1 = std::min(g_.na, s0 + K);
        if (!any && unitSteps_) {  // an empty tile layer: joins the run of empty slices
            emptyRun_ += s1 - s0;
            return;
        }
        for (int k = 0; k < s1 - s0; ++k) sweepSlice(job_.sign > 0 ? s0 + k : s1 - 1 - k, any);
    }

    // The number of slices of one tile layer, and its k-th in sweep order (sweepLayer's
    // slices one at a time, for sweeps that interleave theirs over a layer of live planes).
    int slicesOf(int layer) const { return std::min(g_.na, (layer + 1) * K) - layer * K; }
    void sweepLayerSlice(int layer, int k) {
        const int s0 = layer * K, s1 = std::min(g_.na, s0 + K);
        sweepSlice(job_.sign > 0 ? s0 + k : s1 - 1 - k, true);
    }

    // After the last layer: the rays still in the block escape; adds this sweep's tally.
    void finish(Tally& tally) {
        crossEmptyRun();
        // A pristine row's rays all hold the boundary radiance: its pending shifts move k
        // of them out and k in, and all nu escape now (applyShift, tallyRowEscape), counted
        // without touching its state. An untouched row has no shifts of its own: its
        // pending ones are its class's u crossings. Written rows are touched; they leave in
        // row order.
        const size_t rr = uCount_.size();
        std::uint64_t pristineRows = rows_count_;
        std::int64_t pristineShifts = 0;
        for (size_t cls = 0; cls < rr; ++cls) pristineShifts += std::int64_t(classU_[cls]) * g_.nv;
        for (size_t w = 0; w < touched_.size(); ++w)
            for (std::uint64_t bits = touched_[w]; bits; bits &= bits - 1) {
                const size_t row = w * 64 + size_t(__builtin_ctzll(bits)), cls = row % rr;
                if (pristine_[row]) {
                    pristineShifts += pending_[row] - seenU_[row];
                    continue;
                }
                --pristineRows;
                pristineShifts -= classU_[cls];
                syncPending(row, int(cls), 0);
                applyShift(row);
                tallyRowEscape(row);
            }
        bndOut_ += pristineRows * std::uint64_t(g_.nu) + std::uint64_t(pristineShifts);
        bndIn_ += std::uint64_t(pristineShifts);
        const double k = g_.aPerp * job_.weight, V = m_.voxelVolume();
        const double alb[3] = {m_.albedo.r, m_.albedo.g, m_.albedo.b};
        for (int c = 0; c < 3; ++c) {
            const double inj = double(bnd_[c]) * double(bndIn_), esc = esc_[c] + double(bnd_[c]) * double(bndOut_);
            tally.injected[c] += (inj + injSrc_[c] * V / g_.aPerp) * k;
            tally.escaped[c] += esc * k;
            tally.scattered[c] += alb[c] * sca_[c] * k;
            tally.absorbed[c] += (1 - alb[c]) * sca_[c] * k;
        }
        tally.segments += segs_;
    }

private:
    // One slice: every ray row, every lattice class in it (rows outer, so the plane rows a
    // row of rays touches stay in L1 across the r^2 classes).
    void sweepSlice(int ia, bool any) {
        const int r = g_.r;
        slice_ = ia % K;
        // No live chunk in the slice (an empty layer, or a slice of a puff's edge tile
        // beyond the puff): every ray crosses it unchanged.
        const bool empty = !any || planes_->occupied(slice_).empty();
        if (empty && unitSteps_) {
            ++emptyRun_;
            return;
        }
        crossEmptyRun();
        for (int j = 0; j < r; ++j) {
            fU0_[j] = stU_[j].f;
            fV0_[j] = stV_[j].f;
            SV_[j] = wrap(stV_[j].S, g_.nv);
            crossings(stU_[j], g_.du, stepU_, lamU_[j]);
            crossings(stV_[j], g_.dv, stepV_, lamV_[j]);
        }
        if (empty) return crossEmptySlice();
        for (int jv = 0; jv < r; ++jv)
            for (int ju = 0; ju < r; ++ju) mergeEvents(lamU_[ju], lamV_[jv], g_.sliceLen, ev_[size_t(jv * r + ju)]);
        const int rr = r * r;
        if (linear_) linearGeometry(job_.sign > 0 ? ia : g_.na - 1 - ia);
        for (int cls = 0; cls < rr; ++cls) {
            uCount_[cls] = 0;
            for (const Event& e : ev_[size_t(cls)]) uCount_[cls] += e.kind == 1;
        }
        ++stamp_;
        sweepOccupiedRows();
        for (int cls = 0; cls < rr; ++cls) crossUntouchedRows(cls, SV_[cls / r], ev_[size_t(cls)]);
        for (int cls = 0; cls < rr; ++cls) classU_[cls] += uCount_[cls];
    }

    // The ray rows that meet allocated voxel rows in this slice, in row order (cell v
    // outer, class inner, as a sweep over every row would take them: the deposits add up
    // in the same order): a row is such a candidate when one of the voxel rows it lies in
    // during the slice (its start row and the ones its v crossings take it to) is occupied.
    void sweepOccupiedRows() {
        const int r = g_.r, rr = r * r, nv = g_.nv;
        if (planes_->occupied(slice_).size() * 4 >= size_t(nv) * 3) {  // most voxel rows occupied: every row
            for (size_t row = 0; row < rows_count_; ++row) mark_[row] = stamp_;
            for (int cellV = 0; cellV < nv; ++cellV)
                for (int cls = 0; cls < rr; ++cls) sweepCandidate(size_t(cellV) * rr + size_t(cls), cellV, cls);
            return;
        }
        // Candidates marked (mark_), their cells v in a bit set: walked in row order
        // without a sort.
        std::fill(cellBits_.begin(), cellBits_.end(), 0);
        for (int cls = 0; cls < rr; ++cls) {
            int shift = SV_[cls / r];
            int shifts[8], ns = 0;
            shifts[ns++] = shift;
            for (const Event& e : ev_[size_t(cls)])
                if (e.kind == 2 && ns < 8) shifts[ns++] = shift = wrapNear(shift + g_.sv, nv);
            for (int vr : planes_->occupied(slice_))
                for (int k = 0; k < ns; ++k) {
                    const int cellV = wrapNear(vr - shifts[k], nv);
                    const size_t row = size_t(cellV) * rr + size_t(cls);
                    if (mark_[row] != stamp_) {
                        mark_[row] = stamp_;
                        cellBits_[size_t(cellV) / 64] |= std::uint64_t(1) << (cellV % 64);
                    }
                }
        }
        for (size_t w = 0; w < cellBits_.size(); ++w)
            for (std::uint64_t bits = cellBits_[w]; bits; bits &= bits - 1) {
                const int cellV = int(w * 64) + __builtin_ctzll(bits);
                for (int cls = 0; cls < rr; ++cls) {
                    const size_t row = size_t(cellV) * rr + size_t(cls);
                    if (mark_[row] == stamp_) sweepCandidate(row, cellV, cls);
                }
            }
    }

    // One candidate row through the slice (processRow), its class's u crossings of the
    // slice applied with it.
    void sweepCandidate(size_t row, int cellV, int cls) {
        touch(row);
        syncPending(row, cls, 0);
        processRow(row, cellV, SV_[cls / g_.r], ev_[size_t(cls)], true, linear_ ? geo_[size_t(cls)].data() : nullptr);
        seenU_[row] = classU_[cls] + uCount_[cls];
    }

    // The rows of a class that meet no allocated voxels in this slice (every row of an
    // empty layer): rays cross unchanged, so only the bookkeeping is left, done for the
    // whole class at once, in event order: a u crossing adds to the class's count of
    // pending column shifts (each row takes its share lazily, syncPending); a v crossing
    // moves every row one voxel row on, and the one row at the block's edge leaves it (its
    // rays re-enter with the boundary radiance). SV: the class's row shift at slice start.
    void crossUntouchedRows(int cls, int SV, const std::vector<Event>& ev) {
        const int nv = g_.nv, rr = g_.r * g_.r;
        const int edge = g_.sv > 0 ? nv - 1 : 0;
        int shift = SV, uSoFar = 0;  // row cellV lies in voxel row (cellV + shift) mod nv
        for (const Event& e : ev) {
            if (e.kind == 1) {
                ++uSoFar;
            } else if (e.kind == 2) {
                const size_t row = size_t(wrapNear(edge - shift, nv)) * rr + size_t(cls);
                if (mark_[row] != stamp_) leaveAtEdge(row, cls, uSoFar);  // a candidate left in processRow
                shift = wrapNear(shift + g_.sv, nv);
            }
        }
    }

    // A slice without a live chunk (an empty tile layer's, or one beyond a medium's edge):
    // every row crosses it unchanged, so only the bookkeeping of crossUntouchedRows is
    // left, taken from the crossings directly (no merged events): a class's u crossings
    // before each of its v crossings (u first on ties, as mergeEvents orders them).
    void crossEmptySlice() {
        const int r = g_.r, nv = g_.nv, rr = r * r;
        const int edge = g_.sv > 0 ? nv - 1 : 0;
        ++stamp_;  // no row is a candidate of this slice
        for (int cls = 0; cls < rr; ++cls) {
            const std::vector<double>& lu = lamU_[cls % r];
            const std::vector<double>& lv = lamV_[cls / r];
            uCount_[cls] = int(lu.size());
            int shift = SV_[cls / r];
            size_t uSoFar = 0;
            for (const double l : lv) {
                const size_t row = size_t(wrapNear(edge - shift, nv)) * rr + size_t(cls);
                while (uSoFar < lu.size() && lu[uSoFar] <= l) ++uSoFar;
                leaveAtEdge(row, cls, int(uSoFar));
                shift = wrapNear(shift + g_.sv, nv);
            }
        }
        for (int cls = 0; cls < rr; ++cls) classU_[cls] += uCount_[cls];
    }

    // The run of empty slices since the last occupied one (unit steps), crossed at once
    // before the next occupied slice or the sweep's end: the same crossings, in order.
    void crossEmptyRun() {
        if (emptyRun_ == 0) return;
        crossEmptySlicesUnit(emptyRun_);
        emptyRun_ = 0;
    }

    // crossEmptySlice for a run of n slices, when no class crosses more than one face per
    // axis and slice (unitSteps_: every sweep of cubic voxels): the crossings taken
    // without lists or merged events, so a slice of empty space costs a few operations
    // per class. Per slice, rows leave in class order, as crossEmptySlice takes them (the
    // escape sums add in order). A class's u crossings depend on its u index alone; they
    // join classU_ at the run's end, and a written row leaving before that takes the
    // run's so far (uRun) with it. R: the lattice's r when fixed at compile time (the
    // default 2, loops unrolled), 0 for any.
    void crossEmptySlicesUnit(int n) {
        if (g_.r == 2) return crossEmptySlicesUnit<2>(n);
        crossEmptySlicesUnit<0>(n);
    }
    template <int R>
    [[gnu::noinline]] void crossEmptySlicesUnit(int n) {  // kept apart: processRow's inlining stays as it was
        const int r = R > 0 ? R : g_.r, nv = g_.nv, rr = r * r;
        const int edge = g_.sv > 0 ? nv - 1 : 0;
        int uRun[16] = {}, edgeCell[16];  // edgeCell: per v index, the cell of the row at the edge
        for (int jv = 0; jv < r; ++jv) edgeCell[jv] = wrap(edge - stV_[jv].S, nv);
        std::uint64_t pristineLeaves = 0;
        // The directions in locals (not reloaded after each store to a class state).
        const double du = g_.du, dv = g_.dv, stepU = stepU_, stepV = stepV_;
        for (int k = 0; k < n; ++k) {
            double lamU[16], lamV = 0;
            bool crossU[16];
            for (int ju = 0; ju < r; ++ju) crossU[ju] = unitCrossing(stU_[ju], du, stepU, lamU[ju]);
            for (int jv = 0; jv < r; ++jv) {
                if (!unitCrossing(stV_[jv], dv, stepV, lamV)) continue;
                const size_t cell = size_t(edgeCell[jv]);  // the row at the edge leaves
                edgeCell[jv] = wrapNear(edgeCell[jv] - g_.sv, nv);
                for (int ju = 0; ju < r; ++ju) {
                    const size_t row = cell * rr + size_t(jv * r + ju);
                    if (pristine_[row]) ++pristineLeaves;  // counted once, below
                    else leaveAtEdge(row, jv * r + ju, uRun[ju] + (crossU[ju] && lamU[ju] <= lamV ? 1 : 0));
                }
            }
            for (int ju = 0; ju < r; ++ju) uRun[ju] += crossU[ju];
        }
        leavePristineRows(pristineLeaves);
        for (int cls = 0; cls < rr; ++cls) classU_[size_t(cls)] += uRun[cls % r];
    }

    // A row of an empty crossing reaches the block's v edge and leaves: a pristine one is
    // only counted; a written one first takes the uSoFar u crossings of this slice that
    // came before its v crossing.
    void leaveAtEdge(size_t row, int cls, int uSoFar) {
        if (pristine_[row]) return leavePristineRows(1);
        syncPending(row, cls, uSoFar);
        leaveRow(row);
    }

    // A row's first time as a candidate: its state set (until then it is pristine, with
    // no shifts of its own and no storage).
    void touch(size_t row) {
        std::uint64_t& word = touched_[row / 64];
        const std::uint64_t bit = std::uint64_t(1) << (row % 64);
        if (word & bit) return;
        word |= bit;
        block_[row] = nullptr;
        pending_[row] = seenU_[row] = 0;
    }

    // Brings a row's pending column shifts up to date: the u crossings its class made
    // since the row last took its share, plus `extra` of the current slice.
    void syncPending(size_t row, int cls, int extra) {
        const int now = classU_[cls] + extra;
        pending_[row] += now - seenU_[row];
        seenU_[row] = now;
    }

    // Channel c, column col of a written ray row (col inside its window).
    float* at(size_t row, int c, int col) {
        return block_[row] + size_t(c) * size_t(cap_[row]) + size_t(col - org_[row]);
    }

    // Radiance of a written row's rays in columns [a, b) of channel c: its valid columns
    // read, the rest the boundary radiance (one product): O(valid columns), not O(b - a).
    double sumColumns(size_t row, int c, int a, int b) {
        const int lo = std::clamp(vlo_[row], a, b), hi = std::clamp(vhi_[row], lo, b);
        double sum = double(bnd_[c]) * double((b - a) - (hi - lo));
        const int n = hi - lo;
        // The sums below for no valid column and for one (a u shift's leaving ray, the
        // common case), written out: the same additions, in the same order.
        if (n <= 0) return sum + 0.0;
        const float* x = at(row, c, lo);
        if (n == 1) return sum + (0.0 + double(x[0]));
        double part[4] = {0, 0, 0, 0};  // four sums in turn (a tally: the order is fixed, not the grids')
        int i = 0;
        for (; i + 4 <= n; i += 4)
            for (int j = 0; j < 4; ++j) part[j] += double(x[i + j]);
        for (; i < n; ++i) part[0] += double(x[i]);
        return sum + ((part[0] + part[1]) + (part[2] + part[3]));
    }

    // Escaped radiance of every ray of a row (pristine: nu bnd).
    void tallyRowEscape(size_t row) {
        if (pristine_[row]) bndOut_ += std::uint64_t(g_.nu);
        else
            for (int c = 0; c < 3; ++c) esc_[c] += sumColumns(row, c, 0, g_.nu);
    }

    // A pristine ray row (every ray holding the boundary radiance, never written) becomes
    // written before it meets allocated voxels; its valid columns start empty.
    void materialize(size_t row) {
        std::uint8_t& p = pristine_[row];
        if (!p) return;
        vlo_[row] = vhi_[row] = 0;
        padFilled_[row] = 0;
        if (dense_) {
            block_[row] = arena_ + row * 3 * size_t(C_);
            cap_[row] = C_;
            org_[row] = g_.su > 0 ? -slack_ : 0;  // the slack lies on the side the window moves to
        }
        p = 0;
    }

    // Makes lanes [lo, end) of a written row hold its rays, for the kernel: the row's
    // window is re-centred when they lie outside it (its valid columns moved within the
    // row's slot), columns outside the valid ones get the boundary radiance and join them;
    // padding columns (>= nu) get it too.
    void prepareColumns(size_t row, int lo, int end) {
        int& a = vlo_[row];
        int& b = vhi_[row];
        const int needLo = a >= b ? lo : std::min(a, lo), needHi = a >= b ? end : std::max(b, end);
        if (!block_[row]) grow(row, needLo, needHi);
        else if (needLo < org_[row] || needHi > org_[row] + cap_[row]) {
            if (dense_) recentre(row, needLo, needHi);
            else grow(row, needLo, needHi);
        }
        const int hi = std::min(end, g_.nu);
        if (a >= b) fillBoundary(row, lo, hi);
        else {
            fillBoundary(row, lo, a);
            fillBoundary(row, b, hi);
        }
        fillPadding(row, end);
        if (a >= b) a = lo, b = hi;
        else a = std::min(a, lo), b = std::max(b, hi);
    }

    // The padding lanes [nu, end) of a written row (end > nu: the last chunk's) hold the
    // boundary radiance, so the kernel's padding lanes compute on normal, finite numbers:
    // nothing reads their results (without the fill, outputs are bit-identical and
    // memcheck is clean), but a slot's stale bits can be denormal or NaN patterns, which
    // slow the whole vector instruction on some CPUs. Filled once and kept: the kernel
    // leaves them as they are (sigma and the source are 0 there: T = 1 and q e1 = 0
    // exactly); each move of the window (a u shift, recentre, grow) or a new slot
    // (materialize) puts other memory there and clears the row's flag.
    void fillPadding(size_t row, int end) {
        if (end <= g_.nu || padFilled_[row]) return;
        fillBoundary(row, g_.nu, end);
        padFilled_[row] = 1;
    }

    // Columns [from, to) of a written row's three channels take the boundary radiance.
    void fillBoundary(size_t row, int from, int to) {
        if (from >= to) return;
        float* p = at(row, 0, from);
        const size_t channelStride = size_t(cap_[row]);
        const int n = to - from;
        for (int c = 0; c < 3; ++c, p += channelStride) {
            const float v = bnd_[c];
            int i = 0;
            for (; i + 4 <= n; i += 4) p[i] = p[i + 1] = p[i + 2] = p[i + 3] = v;  // one vector store
            for (; i < n; ++i) p[i] = v;
        }
    }

    // Dense blocks: moves the window so it holds columns [needLo, needHi) with all the slack
    // on the side it moves to (up for su > 0), 8-aligned; the valid columns move within the slot.
    void recentre(size_t row, int needLo, int needHi) {
        const int to = g_.su > 0 ? (needHi - C_ + 7) & ~7 : needLo & ~7;
        const int a = vlo_[row], b = vhi_[row], from = org_[row];
        for (int c = 0; c < 3 && a < b; ++c) {
            float* slot = block_[row] + size_t(c) * size_t(C_);
            std::memmove(slot + (a - to), slot + (a - from), size_t(b - a) * sizeof(float));
        }
        org_[row] = to;
        padFilled_[row] = 0;
    }

    // Sparse blocks: a new block (a power of two of columns) whose window holds columns
    // [needLo, needHi), the valid columns copied over.
    void grow(size_t row, int needLo, int needHi) {
        int cap = 64;
        while (cap < needHi - needLo) cap *= 2;
        // The spare columns on the side the window moves to (as recentre): a u shift moves
        // the window by su, so for su > 0 it ends at needHi and the spare lies below.
        const int org = g_.su > 0 ? needHi - cap : needLo;
        float* nb = takeBlock(cap);
        const int a = vlo_[row], b = vhi_[row];
        for (int c = 0; c < 3 && a < b; ++c)
            std::memcpy(nb + size_t(c) * cap + (a - org), at(row, c, a), size_t(b - a) * sizeof(float));
        if (block_[row]) giveBlock(block_[row], cap_[row]);
        block_[row] = nb;
        cap_[row] = cap;
        org_[row] = org;
        padFilled_[row] = 0;
    }

    // `rows` pristine rows leave (leaveRow): each one's nu rays escape holding the boundary
    // radiance and as many re-enter. Their pending column shifts (each one ray out, one in)
    // stay pending and are counted when next synced: integer counts, the same totals.
    void leavePristineRows(std::uint64_t rows) {
        bndOut_ += rows * std::uint64_t(g_.nu);
        bndIn_ += rows * std::uint64_t(g_.nu);
    }

    // Sparse blocks: storage for 3 channels of cap columns (a power of two, >= 64): one
    // a row that left gave back, else carved from the sweep's slabs of 64 KiB (under
    // malloc's mmap threshold, so the heap reuses them already mapped), freed with the
    // sweep: hundreds of rows come and go in every sweep, and malloc per block took about
    // 3% of the r = 8 puffs' pair's samples.
    float* takeBlock(int cap) {
        const size_t bin = size_t(__builtin_ctz(unsigned(cap / 64)));
        if (bin < freeBlocks_.size() && !freeBlocks_[bin].empty()) {
            float* b = freeBlocks_[bin].back();
            freeBlocks_[bin].pop_back();
            return b;
        }
        const size_t need = 3 * size_t(cap);
        if (slabUsed_ + need > slabSize_) {
            slabSize_ = std::max(kSlabFloats, need);
            slabs_.emplace_back(new float[slabSize_]);  // uninitialised: written before read
            slabUsed_ = 0;
        }
        float* b = slabs_.back().get() + slabUsed_;
        slabUsed_ += need;
        return b;
    }
    void giveBlock(float* block, int cap) {
        if (!block) return;
        const size_t bin = size_t(__builtin_ctz(unsigned(cap / 64)));
        if (bin >= freeBlocks_.size()) freeBlocks_.resize(bin + 1);
        freeBlocks_[bin].push_back(block);
    }

    // The whole row leaves the block through a v face: every ray is tallied as escaped and
    // re-enters with the boundary radiance, which leaves the row pristine (sparse blocks:
    // its block is freed).
    void leaveRow(size_t row) {
        applyShift(row);
        tallyRowEscape(row);
        bndIn_ += std::uint64_t(g_.nu);
        if (!dense_) {
            giveBlock(block_[row], cap_[row]);
            block_[row] = nullptr;
        }
        pristine_[row] = 1;
    }

    // The u crossings of a row of rays, applied lazily: every ray moves `pending` columns
    // (sign of du), the ones leaving the block are tallied as escaped and re-enter at the
    // opposite face with the boundary radiance. Deferred while the row crosses empty voxel
    // rows (nothing else changes its rays there), so empty space costs no data movement;
    // a shift moves the row's window and valid columns, not its data, and the entering
    // rays hold the boundary radiance by lying outside the valid columns: O(crossings).
    void applyShift(size_t row) {
        int& k = pending_[row];
        if (k > 0 && pristine_[row]) {  // every ray holds bnd: k leave, k re-enter
            bndOut_ += std::uint64_t(k);
            bndIn_ += std::uint64_t(k);
            k = 0;
        }
        const int nu = g_.nu;
        while (k > 0) {
            const int step = std::min(k, nu);
            // The leaving rays: columns [nu - step, nu) or [0, step). Only the valid ones are
            // read; the others hold the boundary radiance, added as one product (the row's
            // length is the block's, a stray voxel's row would cost O(nu) per shift).
            const int a = g_.su > 0 ? nu - step : 0;
            for (int c = 0; c < 3; ++c) esc_[c] += sumColumns(row, c, a, a + step);
            bndIn_ += std::uint64_t(step);  // as many enter at the opposite face
            int& lo = vlo_[row];
            int& hi = vhi_[row];
            if (g_.su > 0) {  // column c is now column c + step
                org_[row] += step;
                padFilled_[row] = 0;
                lo = std::min(lo + step, nu);
                hi = std::min(hi + step, nu);
            } else {  // column c is now column c - step
                org_[row] -= step;
                padFilled_[row] = 0;
                lo = std::max(lo - step, 0);
                hi = std::max(hi - step, 0);
            }
            k -= step;
        }
    }

    // Applies one class's events in slice order to one ray row; SV: the class's row shift
    // at slice start, in [0, nv). geo: the linear source's segment geometry per event
    // (linearGeometry), null for a voxel-constant source.
    void processRow(size_t row, int cellV, int SV, const std::vector<Event>& ev, bool any,
                    const LinearSegmentGeometry* geo) {
        const int nv = g_.nv;
        int vr = cellV + SV;  // the voxel row the rays are in
        if (vr >= nv) vr -= nv;
        for (size_t i = 0; i < ev.size(); ++i) {
            const Event& e = ev[i];
            if (e.kind == 1) {
                ++pending_[row];
                continue;
            }
            if (e.kind == 2) {  // the whole row moves to the next voxel row, or leaves the block
                if (vr == (g_.sv > 0 ? nv - 1 : 0)) leaveRow(row);
                vr += g_.sv;
                vr = vr < 0 ? nv - 1 : (vr >= nv ? 0 : vr);
                continue;
            }
            if (!any) continue;  // the slice lies in empty tiles: rays cross it unchanged
            const size_t span = size_t(vr) * K + size_t(slice_);
            const int lo = planes_->spanLo()[span], hi = planes_->spanHi()[span];
            if (lo >= hi) continue;  // the voxel row holds no live chunk in this slice
            applyShift(row);
            materialize(row);
            // lo is tile-aligned; hi rounds up into the padding columns (sigma = 0 there).
            const int chunks = (hi - lo + K - 1) / K;
            prepareColumns(row, lo, lo + chunks * K);
            segs_ += std::uint64_t(hi - lo);
            if (geo) {
                const size_t first = planeIndex<LinearChunk::kFloats>(planes_->rows(), vr, slice_, lo);
                const float* range = &planes_->sigRanges()[2 * (first / LinearChunk::kFloats)];
                segmentChunksLinear(chunks, geo[i], dk_, &planes_->data()[first], range, at(row, 0, lo),
                                    size_t(cap_[row]));
                continue;
            }
            const size_t first = planeIndex(planes_->rows(), vr, slice_, lo);  // lo tile-aligned: a whole chunk
            float* plane = &planes_->data()[first];
            const float* range = &planes_->sigRanges()[2 * (first / kChunk)];
            if (job_.hasSource())
                segmentChunks<true>(chunks, float(e.len), dk_, plane, range, at(row, 0, lo), size_t(cap_[row]));
            else segmentChunks<false>(chunks, float(e.len), dk_, plane, range, at(row, 0, lo), size_t(cap_[row]));
        }
    }

    // The linear source's segment geometry of every class's events in slice t (in sweep
    // order), as the reference kernel computes it per ray (core/sweep_reference.cpp): the
    // start in the voxel relative to the lattice's centroid, the change along the segment,
    // and the deposit factors with the lattice-moment scales (core/lattice_moments.h). A
    // class's position in its voxel is its fraction at slice start plus lambda d, less the
    // faces it crossed so far.
    void linearGeometry(int t) {
        const int r = g_.r, a = g_.a, u = g_.u, v = g_.v;
        const LatticeMoments lu(job_.offsetU, g_.du, r, t), lv(job_.offsetV, g_.dv, r, t);
        double scale[3];
        scale[a] = 1, scale[u] = lu.scale, scale[v] = lv.scale;
        for (int cls = 0; cls < r * r; ++cls) {
            const std::vector<Event>& ev = ev_[size_t(cls)];
            std::vector<LinearSegmentGeometry>& geo = geo_[size_t(cls)];
            geo.resize(ev.size());
            int crossedU = 0, crossedV = 0;
            for (size_t i = 0; i < ev.size(); ++i) {
                const Event& e = ev[i];
                crossedU += e.kind == 1;
                crossedV += e.kind == 2;
                if (e.kind != 0) continue;
                const double lam = e.lam0, dl = e.lam1 - e.lam0;
                double xi0[3], dxi[3];
                xi0[a] = job_.sign > 0 ? lam - 0.5 : 0.5 - lam;
                dxi[a] = job_.sign > 0 ? dl : -dl;
                xi0[u] = fU0_[cls % r] + lam * g_.du - g_.su * crossedU - 0.5 - lu.centroid;
                xi0[v] = fV0_[cls / r] + lam * g_.dv - g_.sv * crossedV - 0.5 - lv.centroid;
                dxi[u] = dl * g_.du;
                dxi[v] = dl * g_.dv;
                LinearSegmentGeometry& G = geo[i];
                G.len = float(e.len);
                G.invLen = float(1.0 / e.len);
                for (int k = 0; k < 3; ++k) {
                    G.xi0[k] = float(xi0[k]);
                    G.dxi[k] = float(dxi[k]);
                    G.a[k] = float(scale[k] * xi0[k]);
                    G.b[k] = float(scale[k] * dxi[k]);
                }
            }
        }
    }

    const Medium& m_;
    const Job& job_;
    const Geometry g_;
    const AxisFrame f_;
    const float depositScale_;
    const bool linear_;                 // the linear source's sweep (sweepStepLinear)
    std::unique_ptr<LayerPlanes> own_;  // own planes, when not shared
    LayerPlanes* planes_ = nullptr;     // the planes swept through (own or a batch's)
    float dk_ = 1.0f;                   // deposit factor in the kernel
    int slice_ = 0;
    size_t rows_count_ = 0;  // ray rows
    static constexpr int kMaxSlack = 64;
    int slack_ = 8;                                  // dense: columns of a slot beyond the plane's width
    static constexpr size_t kSparseBlockRatio = 16;  // dense: at least 1/16 of the block's tiles stored
    bool dense_ = true;
    int C_ = 0;                                    // dense: columns of a row's slot, nu rounded up to tiles plus slack
    float* arena_ = nullptr;                       // dense: the rows' slots, 3 channels of C_ lanes each, in row order
    std::unique_ptr<float*[]> block_;              // per touched ray row: its storage (sparse: null until written)
    std::vector<std::vector<float*>> freeBlocks_;  // sparse: blocks of 64 << i columns no row holds
    std::vector<std::unique_ptr<float[]>> slabs_;  // sparse: where the blocks lie
    size_t slabSize_ = 0, slabUsed_ = 0;           // floats of the last slab, and carved from it
    static constexpr size_t kSlabFloats = 16384;
    // Per ray row; block_, pending_ and seenU_ are set at the row's touch, the window and
    // valid columns when it is written.
    std::unique_ptr<int[]> cap_, org_;  // per written ray row: its window holds columns org .. org + cap - 1
    std::unique_ptr<int[]> vlo_, vhi_;  // per written ray row: columns [vlo, vhi) hold its rays, the others bnd
    std::unique_ptr<std::uint8_t[]> padFilled_;  // per written ray row: its padding lanes hold bnd_ (fillPadding)
    std::vector<std::uint8_t> pristine_;         // per ray row: every ray holds bnd_ (no storage)
    std::vector<std::uint64_t> touched_;         // per ray row, one bit: has been a candidate (its state below is set)
    std::unique_ptr<int[]> pending_;   // per touched ray row: u crossings not yet applied (besides its class's)
    std::unique_ptr<int[]> seenU_;     // per touched ray row: its class's u-crossing count when it last synced
    std::vector<int> classU_;          // per class: u crossings before the current slice
    std::vector<int> uCount_;          // per class: u crossings in the current slice
    std::vector<std::uint32_t> mark_;  // per ray row: stamp_ when a candidate of the current slice
    std::uint32_t stamp_ = 0;
    std::vector<std::uint64_t> cellBits_;  // the current slice's candidates' cells v, one bit each
    std::vector<ClassState> stU_, stV_;
    const double stepU_ = crossingStep(g_.du), stepV_ = crossingStep(g_.dv);
    bool unitSteps_ = false;                   // at most one face crossed per axis and slice (|du|, |dv| <= 1)
    int emptyRun_ = 0;                         // unit steps: empty slices not yet crossed (crossEmptyRun)
    std::vector<double> lamU_[16], lamV_[16];  // this slice's crossings per class (r <= 16)
    int SV_[16] = {};
    double fU0_[16] = {}, fV0_[16] = {};  // per class index: its fraction in the voxel at slice start
    std::vector<Event> ev_[256];
    std::vector<LinearSegmentGeometry> geo_[256];  // linear source: per class, per event (linearGeometry)
    float bnd_[3];
    double esc_[3] = {0, 0, 0}, sca_[3] = {0, 0, 0}, injSrc_[3] = {0, 0, 0};
    // Rays entering, and rays leaving while they hold the boundary radiance (a pristine
    // row's), counted: their power is bnd_ times the count, added once in finish.
    std::uint64_t bndIn_ = 0, bndOut_ = 0;
    std::uint64_t segs_ = 0;
};

}  // namespace

float expNeg(float x) { return expNegInline(x); }

void sweepStep(const Medium& m, const Job& job, int r, float* phi, Tally& tally, float depositScale) {
    if (r < 1 || r > 16) throw Error("LPM", "rays per voxel must be in 1..16, got " + std::to_string(r));
    if (job.srcLinear) throw Error("LPM", "sweepStep takes a voxel-constant source only");
    StepSweep(m, job, r, depositScale).run(phi, tally);
}

void sweepStepLinear(const Medium& m, const Job& job, int r, float* phi, Tally& tally) {
    if (r < 1 || r > 16) throw Error("LPM", "rays per voxel must be in 1..16, got " + std::to_string(r));
    if (job.srcBf16) throw Error("LPM", "sweepStepLinear reads a float source, not a bfloat16 one");
    StepSweep(m, job, r, 1.0f, nullptr, false, true).run(phi, tally);
}

bool samePlanes(const Job& a, const Job& b) {
    return !a.srcLinear && !b.srcLinear && a.axis == b.axis && a.src == b.src && a.srcBf16 == b.srcBf16 &&
           a.srcStride == b.srcStride && a.srcScale.r == b.srcScale.r && a.srcScale.g == b.srcScale.g &&
           a.srcScale.b == b.srcScale.b;
}

bool sameLinearPlanes(const Job& a, const Job& b) {
    return a.srcLinear == b.srcLinear && a.axis == b.axis && a.src == b.src && a.srcBf16 == b.srcBf16 &&
           a.srcStride == b.srcStride && a.srcScale.r == b.srcScale.r && a.srcScale.g == b.srcScale.g &&
           a.srcScale.b == b.srcScale.b;
}

namespace {

// Tile layers along a sweep axis.
int tileLayers(const Medium& m, int axis) {
    return (std::array<int, 3>{m.nx, m.ny, m.nz}[size_t(axis)] + Medium::kTile - 1) / Medium::kTile;
}

// One set of pooled arena slices (64-byte aligned) for a batch's or a group's sweeps.
std::unique_ptr<ScratchBlock> attachArenas(const std::vector<std::unique_ptr<StepSweep>>& sweeps) {
    auto slice = [](size_t floats) { return (floats + 15) / 16 * 16; };
    size_t arenaFloats = 0;
    for (const auto& sw : sweeps) arenaFloats += slice(sw->arenaFloats());
    auto arena = std::make_unique<ScratchBlock>(arenaFloats);
    size_t at = 0;
    for (const auto& sw : sweeps) {
        sw->attachArena(arena->data() + at);
        at += slice(sw->arenaFloats());
    }
    return arena;
}

}  // namespace

namespace {

// linear: the linear source's sweeps (sweepStepLinearGroup).
template <class Out>
void sweepGroupInto(const Medium& m, const std::vector<const Job*>& jobs, int r, const std::vector<Out*>& phi,
                    std::vector<Tally>& tallies, bool linear = false) {
    if (r < 1 || r > 16) throw Error("LPM", "rays per voxel must be in 1..16, got " + std::to_string(r));
    if (jobs.empty()) return;
    const Job& first = *jobs[0];
    for (const Job* j : jobs)
        if (linear ? !sameLinearPlanes(*j, first) || j->sign != first.sign || j->srcBf16
                   : !samePlanes(*j, first) || j->sign != first.sign)
            throw Error("LPM",
                        linear
                            ? "a linear-source sweep group takes jobs of one sweep axis, one sign and one float source"
                            : "a sweep group takes jobs of one sweep axis, one sign and one voxel-constant source");
    if (phi.size() != jobs.size() || tallies.size() != jobs.size())
        throw Error("LPM", "a sweep group needs one deposit buffer and one tally per job");
    // Every sweep reads the layer's planes, gathered once; each adds its deposits there and
    // scatters (and zeroes) them before the next sweeps the layer: the arithmetic of sweepStep.
    LayerPlanes planes(m, first.axis, linear);
    std::vector<std::unique_ptr<StepSweep>> sweeps;
    for (const Job* j : jobs) sweeps.push_back(std::make_unique<StepSweep>(m, *j, r, 1.0f, &planes, true, linear));
    const std::unique_ptr<ScratchBlock> arena = attachArenas(sweeps);
    const int layers = tileLayers(m, first.axis);
    for (int l = 0; l < layers; ++l) {
        const int layer = sweeps[0]->layerAt(l);
        const bool any = planes.gather(layer, first);
        for (size_t j = 0; j < sweeps.size(); ++j) {
            sweeps[j]->sweepLayer(layer, any);
            if (any) sweeps[j]->scatterOwn(layer, phi[j]);
        }
    }
    for (size_t j = 0; j < sweeps.size(); ++j) sweeps[j]->finish(tallies[j]);
}

}  // namespace

void sweepStepGroup(const Medium& m, const std::vector<const Job*>& jobs, int r, const std::vector<float*>& phi,
                    std::vector<Tally>& tallies) {
    sweepGroupInto(m, jobs, r, phi, tallies);
}

void sweepStepGroup(const Medium& m, const std::vector<const Job*>& jobs, int r, const std::vector<Bf16*>& phi,
                    std::vector<Tally>& tallies) {
    sweepGroupInto(m, jobs, r, phi, tallies);
}

void sweepStepLinearGroup(const Medium& m, const std::vector<const Job*>& jobs, int r, const std::vector<float*>& phi,
                          std::vector<Tally>& tallies) {
    sweepGroupInto(m, jobs, r, phi, tallies, true);
}

namespace {

// The sweeps of a batch through one tile layer. One sweep after another, each keeps its
// ray rows (3 r^2 floats a voxel of the layer's cross-section) in cache over the layer's
// slices and reads the layer's planes (8 floats a voxel, 26 for the linear source) anew;
// slice by slice, each slice's planes are read by every sweep while in cache, and the rays
// are read anew. bySlice: the planes outweigh the rays (the linear source with 1 ray per
// voxel: fine passes 8-25% faster on the thick 1M smoke and plume; the constant
// source at 2 rays, slice by slice, took single scattering from 0.6-0.8 s to 1.0 s).
// A voxel takes deposits only while its own slice is swept, so each voxel adds the sweeps'
// deposits in the sweeps' order either way: the same sums, bit for bit.
void sweepLayerOfBatch(const std::vector<std::unique_ptr<StepSweep>>& sweeps, int layer, bool any, bool bySlice) {
    if (!any || !bySlice) {
        for (auto& sw : sweeps) sw->sweepLayer(layer, any);
        return;
    }
    const int slices = sweeps[0]->slicesOf(layer);
    for (int k = 0; k < slices; ++k)
        for (auto& sw : sweeps) sw->sweepLayerSlice(layer, k);
}

// Whether a batch's sweeps go slice by slice (sweepLayerOfBatch): when the planes hold at
// least 4x the floats of the ray rows per voxel.
bool batchSweepsBySlice(bool linear, int r) {
    const int planeFloats = linear ? LinearChunk::kArrays : kChunk / kLanes;
    return planeFloats >= 4 * 3 * r * r;
}

// sweepStepBatch (phi a float*), or the linear source's (sweepStepLinearBatch: phi its
// LinearBatchDeposits).
template <class Target>
void sweepBatchInto(const Medium& m, const std::vector<const Job*>& jobs, int r, Target phi, Tally& tally,
                    float depositPerWeight) {
    constexpr bool linear = std::is_same_v<Target, LinearBatchDeposits>;
    if (r < 1 || r > 16) throw Error("LPM", "rays per voxel must be in 1..16, got " + std::to_string(r));
    if (jobs.empty()) return;
    const Job& first = *jobs[0];
    for (const Job* j : jobs)
        if (linear ? !sameLinearPlanes(*j, first) || j->srcBf16 : !samePlanes(*j, first))
            throw Error("LPM", linear ? "a linear-source sweep batch takes jobs of one sweep axis and one float source"
                                      : "a sweep batch takes jobs of one sweep axis and one voxel-constant source");
    // The jobs of each sign cross the layers in the same order: they advance together,
    // layer by layer, through one set of planes gathered once per layer for all of them.
    const double V = m.voxelVolume();
    const double alb[3] = {m.albedo.r, m.albedo.g, m.albedo.b};
    const bool bySlice = batchSweepsBySlice(linear, r);
    bool assign = true;  // the first sign's deposits overwrite phi, the second's add to them
    for (int sign : {1, -1}) {
        if (std::none_of(jobs.begin(), jobs.end(), [&](const Job* j) { return j->sign == sign; })) continue;
        std::vector<std::unique_ptr<StepSweep>> sweeps;
        LayerPlanes planes(m, first.axis, linear);
        double weights = 0;
        for (const Job* j : jobs)
            if (j->sign == sign) {
                sweeps.push_back(std::make_unique<StepSweep>(m, *j, r, 1.0f, &planes, false, linear));
                weights += j->weight;
            }
        if (sweeps.empty()) continue;
        const std::unique_ptr<ScratchBlock> arena = attachArenas(sweeps);
        double sca[3] = {0, 0, 0}, src[3] = {0, 0, 0};
        const int layers = tileLayers(m, first.axis);
        for (int l = 0; l < layers; ++l) {
            const int layer = sweeps[0]->layerAt(l);
            const bool any = planes.gather(layer, first);
            sweepLayerOfBatch(sweeps, layer, any, bySlice);
            if constexpr (linear) {
                if (any && assign) planes.scatterLinear<true>(layer, depositPerWeight, phi, sca, src);
                else if (any) planes.scatterLinear(layer, depositPerWeight, phi, sca, src);
            } else {
                if (any && assign) planes.scatter<true>(layer, depositPerWeight, phi, sca, src);
                else if (any) planes.scatter(layer, depositPerWeight, phi, sca, src);
            }
        }
        assign = false;
        for (auto& sw : sweeps) sw->finish(tally);
        for (int c = 0; c < 3; ++c) {
            tally.injected[c] += src[c] * V * weights;
            tally.scattered[c] += alb[c] * sca[c];
            tally.absorbed[c] += (1 - alb[c]) * sca[c];
        }
    }
}

}  // namespace

void sweepStepBatch(const Medium& m, const std::vector<const Job*>& jobs, int r, float* phi, Tally& tally,
                    float depositPerWeight) {
    sweepBatchInto(m, jobs, r, phi, tally, depositPerWeight);
}

void sweepStepLinearBatch(const Medium& m, const std::vector<const Job*>& jobs, int r, LinearBatchDeposits out,
                          Tally& tally, float depositPerWeight) {
    sweepBatchInto(m, jobs, r, out, tally, depositPerWeight);
}

}  // namespace lpm

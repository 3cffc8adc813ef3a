// Separable fine-grid sources (core/separable_source.h).
#include "core/separable_source.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "core/fold_kernel.h"
#include "core/malloc_policy.h"
#include "core/parallel.h"
#include "core/sh_rows.h"
#include "core/simd_clones.h"
#include "core/sweep.h"

namespace lpm {

namespace {

/// fn(ci, kids) for every stored coarse voxel ci of c, kids[k] its child k's index in f
/// (Medium::npos where absent), in parallel over coarse z-slices.
template <class Fn>
void forEachCoarseVoxel(const Medium& f, const Medium& c, const Fn& fn) {
    parallelForChunks(size_t(c.nz), 1, [&](size_t zb, size_t ze) {
        for (int z = int(zb); z < int(ze); ++z)
            for (int y = 0; y < c.ny; ++y)
                for (int x = 0; x < c.nx; ++x) {
                    const size_t ci = c.index(x, y, z);
                    if (ci == Medium::npos) continue;
                    size_t kids[8];
                    for (int k = 0; k < 8; ++k) {
                        const int fx = 2 * x + (k & 1), fy = 2 * y + ((k >> 1) & 1), fz = 2 * z + (k >> 2);
                        const bool inside = fx < f.nx && fy < f.ny && fz < f.nz;
                        kids[k] = inside ? f.index(fx, fy, fz) : Medium::npos;
                    }
                    fn(ci, kids);
                }
    });
}

}  // namespace

FineCoarseMap::FineCoarseMap(const Medium& f, const Medium& c) : coarseRows(c) {
    assignZeroed(sigmaSum, rows());
    assignZeroed(parent, f.voxelCount());
    std::fill(parent.begin(), parent.end(), kNone);
    children.assign(rows() * 8, kNone);
    groupSize = f.sparse() ? Medium::kTileVoxels : 2 * size_t(f.nx) * size_t(f.ny);
    forEachCoarseVoxel(f, c, [&](size_t ci, const size_t* kids) {
        const std::uint32_t row = coarseRows.rowOf[ci];
        if (row == kNone) return;
        double sigma = 0;
        for (int k = 0; k < 8; ++k)
            if (kids[k] != Medium::npos) {
                children[size_t(row) * 8 + size_t(k)] = std::uint32_t(kids[k]);
                parent[kids[k]] = row;
                sigma += f.sigmaT[kids[k]];
            }
        sigmaSum[row] = float(sigma);
    });
}

// Coarse buffers are tens of MiB: each is written into storage advised onto huge pages
// (assignZeroed), where a plain copy or assign would fault it in 4 KiB at a time (about
// 0.5 s of a plume-1M g = 0.6 bake went to those faults, docs/performance.md session 18).
std::vector<float> SeparableSource::restricted() const {
    if (!isotropic.empty()) throw Error("SeparableSource", "restricted is for a source without isotropic part");
    std::vector<float> out;
    assignZeroed(out, shape.size());
    const size_t nb = size_t(bins);
    parallelForChunks(coarseRows, 1 << 11, [&](size_t pb, size_t pe) {
        for (size_t p = pb; p < pe; ++p)
            for (size_t d = 0; d < nb; ++d)
                for (size_t c = 0; c < 3; ++c) {
                    const size_t h = heldIndex(p, d, c);
                    out[(p * nb + d) * 3 + c] = offset.empty() ? shape.at(h) : shape.at(h) + offsetAt(h);
                }
    });
    return out;
}

float SeparableSource::offsetAt(size_t h) const {
    float p = 0;
    for (const HalfBuffer& part : offset) p += part.at(h);
    return p;
}

HalfBuffer SeparableSource::holdByBin(const std::vector<float>& x, int bins) {
    HalfBuffer out;
    out.scale = HalfBuffer::scaleFor(largestFinite(x));
    const float inverse = 1.0f / out.scale;  // a power of two: exact
    assignZeroed(out.bits, x.size());
    const size_t nb = size_t(bins), rows = x.size() / (3 * nb);
    parallelForChunks(rows, 1 << 11, [&](size_t pb, size_t pe) {
        for (size_t p = pb; p < pe; ++p)
            for (size_t d = 0; d < nb; ++d)
                for (size_t c = 0; c < 3; ++c)
                    out.bits[(d * rows + p) * 3 + c] = halfFromFloat(x[(p * nb + d) * 3 + c] * inverse);
    });
    return out;
}

namespace {

/// Coarse voxels [cb, ce) of fillBin: each parent's row decoded once and written to its
/// children, U_f(bin) = R_C + (m_f - |R_C|) S_C + P_C + t_f (see the file comment). Every fine
/// voxel has one parent, so each output is written once, by one thread.
inline void storeSource(float* out, float x) { *out = x; }
inline void storeSource(Bf16* out, float x) { *out = bf16FromFloat(x); }

template <class T>
LPM_SIMD_CLONES void fillBinRange(size_t cb, size_t ce, const SeparableSource& u, const std::uint32_t* children,
                                  int bin, T* out) {
    for (size_t p = cb; p < ce; ++p) {
        const std::uint32_t* kids = &children[p * 8];
        for (size_t c = 0; c < 3; ++c) {
            const size_t i = u.heldIndex(p, size_t(bin), c), pc = p * 3 + c;
            const float r = u.shape.at(i);
            const float s = u.invAbs[pc] > 0 ? std::fabs(r) * u.invAbs[pc] : u.invWeight;
            const float n = u.norm[pc], off = u.offset.empty() ? 0.0f : u.offsetAt(i);
            for (int k = 0; k < 8; ++k)
                if (kids[k] != FineCoarseMap::kNone)
                    storeSource(&out[size_t(kids[k]) * 3 + c],
                                r + (u.magnitude[size_t(kids[k]) * 3 + c] - n) * s + off +
                                    (u.isotropic.empty() ? 0.0f : u.isotropic[size_t(kids[k]) * 3 + c]));
        }
    }
}

}  // namespace

// Fine voxels without a parent (outside the block) are set to 0 first; the parents' rows
// are decoded once each (not once per child: 8x fewer half decodes, no P_C buffer).
template <class T>
void SeparableSource::fillBin(const FineCoarseMap& map, int bin, T* out) const {
    parallelForChunks(map.parent.size(), 1 << 14, [&](size_t vb, size_t ve) {
        for (size_t v = vb; v < ve; ++v)
            if (map.parent[v] == FineCoarseMap::kNone)
                for (size_t c = 0; c < 3; ++c) out[v * 3 + c] = T{};
    });
    parallelForChunks(map.sigmaSum.size(), 1 << 11,
                      [&](size_t cb, size_t ce) { fillBinRange(cb, ce, *this, map.children.data(), bin, out); });
}

template void SeparableSource::fillBin(const FineCoarseMap&, int, float*) const;
template void SeparableSource::fillBin(const FineCoarseMap&, int, Bf16*) const;

double SeparableSource::power(const FineCoarseMap& map, const std::vector<double>& binWeight, const RGB& albedo,
                              double fineVoxelVolume) const {
    if (!isotropic.empty()) throw Error("SeparableSource", "power is for a source without isotropic part");
    // Partial sums over fixed runs of coarse voxels, added in order: the same sum for any
    // thread count (serial, this loop held the other thread idle for 0.1 s of a plume-1M bake).
    const double p = parallelSumOfChunks(map.sigmaSum.size(), 1024, [&](size_t vb, size_t ve) {
        double part = 0;
        for (size_t ci = vb; ci < ve; ++ci)
            for (int d = 0; d < bins; ++d)
                for (int c = 0; c < 3; ++c) {
                    const size_t i = heldIndex(ci, size_t(d), size_t(c));
                    const float r =
                        offset.empty() ? shape.at(i) : shape.at(i) + offsetAt(i);  // restricted(), not materialised
                    part += double(r) * map.sigmaSum[ci] * albedo[c] * binWeight[size_t(d)];
                }
        return part;
    });
    return p * fineVoxelVolume / 3.0;
}

double SeparableSource::absolutePower(const std::vector<float>& sigmaT, const RGB& albedo,
                                      double fineVoxelVolume) const {
    if (!offset.empty() || !isotropic.empty())
        throw Error("SeparableSource", "absolutePower is for a source without offset or isotropic part");
    if (magnitude.size() != sigmaT.size() * 3)
        throw Error("SeparableSource", "absolutePower: " + std::to_string(magnitude.size() / 3) + " magnitudes for " +
                                           std::to_string(sigmaT.size()) + " fine voxels");
    const double p = parallelSumOfChunks(sigmaT.size(), 1 << 14, [&](size_t fb, size_t fe) {
        double part = 0;  // fixed runs added in order: the same sum for any thread count
        for (size_t f = fb; f < fe; ++f)
            for (size_t c = 0; c < 3; ++c) part += std::fabs(double(magnitude[f * 3 + c])) * sigmaT[f] * albedo[c];
        return part;
    });
    return p * fineVoxelVolume / 3.0;
}

SeparableFold::SeparableFold(const FineCoarseMap& map, const std::vector<float>& sigmaT,
                             const std::vector<double>& binWeight, int shCoeffs, const std::uint32_t* shRow)
    : map_(map), sigmaT_(sigmaT), binWeight_(binWeight.begin(), binWeight.end()), nb_(int(binWeight.size())),
      nc_(shCoeffs), shRow_(shRow) {
    out_.bins = nb_;
    assignZeroed(out_.magnitude, map.parent.size() * 3);
    assignZeroed(shapeSum_, map.sigmaSum.size() * size_t(nb_) * 3);
}

namespace {

/// One batch's fold coefficients, each repeated for the 3 channels (addTimesRgb's layout).
struct BatchCoefs {
    size_t n = 0;
    int nb = 0, nc = 0;
    std::vector<float> bin3;  ///< [job][bin][rgb]
    std::vector<float> sh3;   ///< [job][coeff][rgb]
    std::vector<float> mag;   ///< [job]: sum_d w_d binCoef_d, the job's share of a voxel's angular integral
    const std::uint32_t* shRow = nullptr;  ///< fine voxel -> SH row (core/sh_rows.h); null: the identity
    size_t row(size_t f) const { return shRow ? shRow[f] : f; }
};

/// Fine voxels [vb, ve) of a batch's fold, in storage order: each deposit goes to the
/// voxel's SH and, times the job's `mag`, to its angular integral; sigma_f times it to its
/// parent's psi_j. A fine voxel's bin row is never formed: the coarse voxel's restriction
/// sum_f sigma_f U_f(d) is sum_j binCoef_j(d) psi_j (foldCoarseRange), one bin row per
/// coarse voxel and job instead of one per fine voxel.
inline float depositValue(float x) { return x; }
inline float depositValue(Bf16 x) { return floatFromBf16(x); }

template <class T>
LPM_SIMD_CLONES void foldFineRange(size_t vb, size_t ve, const BatchCoefs& k, const FineCoarseMap& map,
                                   const float* sigmaT, const std::vector<std::vector<T>>& phi, bool depositSh,
                                   float* sh, float* mag, float* psi) {
    for (size_t f = vb; f < ve; ++f) {
        const std::uint32_t parent = map.parent[f];
        const size_t row = k.row(f);
        const bool toSh = depositSh && row != ShRows::kNone;
        if (parent == FineCoarseMap::kNone && !toSh) continue;
        const float sigma = sigmaT[f];
        float* m = &mag[f * 3];
        float* q = parent == FineCoarseMap::kNone ? nullptr : &psi[size_t(parent) * k.n * 3];
        for (size_t j = 0; j < k.n; ++j) {
            const T* pj = &phi[j][f * 3];
            const float p[3] = {depositValue(pj[0]), depositValue(pj[1]), depositValue(pj[2])};
            if (p[0] == 0 && p[1] == 0 && p[2] == 0) continue;
            if (toSh) addTimesRgb(&sh[row * size_t(k.nc) * 3], &k.sh3[j * size_t(k.nc) * 3], RgbRepeat(p), k.nc);
            if (!q) continue;  // no mass under the parent: no source of power
            for (int c = 0; c < 3; ++c) {
                m[c] += k.mag[j] * p[c];
                q[j * 3 + size_t(c)] += sigma * p[c];
            }
        }
    }
}

/// foldFineRange for the common batch, 4 jobs and SH order 2 (27 floats per SH row), with
/// the same sums in the same order (each value takes job 0's term first, job 3's last), as
/// straight-line vector code: the general loop's per-job tests and triple patterns cost
/// more than its memory traffic (docs/performance.md, session 17).
#if defined(__GNUC__)
typedef float Float8 __attribute__((vector_size(32), aligned(4), may_alias));
/// row (27 floats) += the SH terms of 4 jobs' deposits d[job][rgb], job 0's term first.
__attribute__((always_inline)) inline void addBatchToRow4x9(float* row, const float* cf, const float* d) {
    Float8 s0 = *reinterpret_cast<const Float8*>(row), s1 = *reinterpret_cast<const Float8*>(row + 8),
           s2 = *reinterpret_cast<const Float8*>(row + 16);
    float t0 = row[24], t1 = row[25], t2 = row[26];
    for (int j = 0; j < 4; ++j) {
        const float a = d[j * 3], b = d[j * 3 + 1], c = d[j * 3 + 2];
        const Float8 pa = {a, b, c, a, b, c, a, b}, pb = {c, a, b, c, a, b, c, a}, pc = {b, c, a, b, c, a, b, c};
        const float* q = cf + j * 27;
        s0 += *reinterpret_cast<const Float8*>(q) * pa;
        s1 += *reinterpret_cast<const Float8*>(q + 8) * pb;
        s2 += *reinterpret_cast<const Float8*>(q + 16) * pc;
        t0 += q[24] * a;
        t1 += q[25] * b;
        t2 += q[26] * c;
    }
    *reinterpret_cast<Float8*>(row) = s0;
    *reinterpret_cast<Float8*>(row + 8) = s1;
    *reinterpret_cast<Float8*>(row + 16) = s2;
    row[24] = t0;
    row[25] = t1;
    row[26] = t2;
}

template <class T>
LPM_SIMD_CLONES void foldFineRange4x9(size_t vb, size_t ve, const BatchCoefs& k, const FineCoarseMap& map,
                                      const float* sigmaT, const std::vector<std::vector<T>>& phi, float* sh,
                                      float* mag, float* psi) {
    const T* const ph[4] = {phi[0].data(), phi[1].data(), phi[2].data(), phi[3].data()};
    const float* const cf = k.sh3.data();  // [job][27]
    for (size_t f = vb; f < ve; ++f) {
        const std::uint32_t parent = map.parent[f];
        const size_t row = k.row(f);
        if (parent == FineCoarseMap::kNone && row == ShRows::kNone) continue;
        float d[12];
        for (int j = 0; j < 4; ++j)
            for (int c = 0; c < 3; ++c) d[j * 3 + c] = depositValue(ph[j][f * 3 + size_t(c)]);
        if (row != ShRows::kNone) addBatchToRow4x9(&sh[row * 27], cf, d);
        if (parent == FineCoarseMap::kNone) continue;  // no mass under the parent: no source of power
        float* m = &mag[f * 3];
        for (int j = 0; j < 4; ++j)
            for (int c = 0; c < 3; ++c) m[c] += k.mag[size_t(j)] * d[j * 3 + c];
        const float sigma = sigmaT[f];
        float* ps = &psi[size_t(parent) * 12];
        for (int i = 0; i < 12; ++i) ps[i] += sigma * d[i];
    }
}
#endif

/// Coarse voxels [cb, ce): acc(d) += sum_j binCoef_j(d) psi_j, and psi back to 0.
LPM_SIMD_CLONES
void foldCoarseRange(size_t cb, size_t ce, const BatchCoefs& k, float* acc, float* psi) {
    for (size_t ci = cb; ci < ce; ++ci) {
        float* a = &acc[ci * size_t(k.nb) * 3];
        for (size_t j = 0; j < k.n; ++j) {
            float* q = &psi[(ci * k.n + j) * 3];
            if (q[0] == 0 && q[1] == 0 && q[2] == 0) continue;
            addTimesRgb(a, &k.bin3[j * size_t(k.nb) * 3], RgbRepeat(q), k.nb);
            q[0] = q[1] = q[2] = 0.0f;
        }
    }
}

}  // namespace

template <class T>
void SeparableFold::fold(bool depositSh, const Job* jobs, size_t n, const std::vector<std::vector<T>>& phi,
                         std::vector<float>& sh) {
    BatchCoefs k;
    k.n = n;
    k.nb = nb_;
    k.nc = nc_;
    k.bin3.resize(n * size_t(nb_) * 3);
    k.sh3.resize(n * size_t(nc_) * 3);
    k.mag.assign(n, 0.0f);
    k.shRow = shRow_;
    for (size_t j = 0; j < n; ++j) {
        for (int c = 0; c < 3; ++c) {
            for (int d = 0; d < nb_; ++d)
                k.bin3[(j * size_t(nb_) + size_t(d)) * 3 + size_t(c)] = float(jobs[j].binCoef[size_t(d)]);
            for (int s = 0; s < nc_; ++s)
                k.sh3[(j * size_t(nc_) + size_t(s)) * 3 + size_t(c)] = float(jobs[j].shCoef[size_t(s)]);
        }
        double m = 0;
        for (int d = 0; d < nb_; ++d) m += double(binWeight_[size_t(d)]) * jobs[j].binCoef[size_t(d)];
        k.mag[j] = float(m);
    }
    if (psi_.size() < map_.sigmaSum.size() * n * 3) assignZeroed(psi_, map_.sigmaSum.size() * n * 3);
    // Chunks of whole groups: no two write the same parent's psi.
    parallelForChunks(map_.parent.size(), map_.groupSize, [&](size_t vb, size_t ve) {
#if defined(__GNUC__)
        if (n == 4 && nc_ == 9 && depositSh) {
            foldFineRange4x9(vb, ve, k, map_, sigmaT_.data(), phi, sh.data(), out_.magnitude.data(), psi_.data());
            return;
        }
#endif
        foldFineRange(vb, ve, k, map_, sigmaT_.data(), phi, depositSh, sh.data(), out_.magnitude.data(), psi_.data());
    });
    parallelForChunks(map_.sigmaSum.size(), 4096,
                      [&](size_t cb, size_t ce) { foldCoarseRange(cb, ce, k, shapeSum_.data(), psi_.data()); });
}

template void SeparableFold::fold(bool, const Job*, size_t, const std::vector<std::vector<float>>&,
                                  std::vector<float>&);
template void SeparableFold::fold(bool, const Job*, size_t, const std::vector<std::vector<Bf16>>&, std::vector<float>&);

// R_C is rounded to half precision (core/half_buffer.h), and |R_C| and the shape's
// normaliser are taken from the rounded values, so fillBin still gives every fine voxel its
// angular integral m_f exactly: the rounding moves no power between voxels, it only changes
// how a voxel's source divides among the bins, by at most 2^-11 of each bin's value.
void SeparableFold::takeIntegralFromChildren(const HalfBuffer& part) {
    const size_t nb = size_t(nb_);
    std::vector<float> integral(map_.rows() * 3);  // |P_C| [row][rgb], signed
    parallelForChunks(map_.rows(), 4096, [&](size_t cb, size_t ce) {
        for (size_t ci = cb; ci < ce; ++ci)
            for (size_t c = 0; c < 3; ++c) {
                double sum = 0;
                for (size_t d = 0; d < nb; ++d) sum += double(binWeight_[d]) * part.at(out_.heldIndex(ci, d, c));
                integral[ci * 3 + c] = float(sum);
            }
    });
    parallelForChunks(map_.parent.size(), 4096, [&](size_t fb, size_t fe) {
        for (size_t f = fb; f < fe; ++f) {
            const std::uint32_t p = map_.parent[f];
            if (p == FineCoarseMap::kNone) continue;
            for (size_t c = 0; c < 3; ++c) out_.magnitude[f * 3 + c] -= integral[size_t(p) * 3 + c];
        }
    });
}

void SeparableFold::takeIsotropicFromShape(const std::vector<float>& t) {
    const size_t nb = size_t(nb_);
    parallelForChunks(map_.rows(), 4096, [&](size_t cb, size_t ce) {
        for (size_t ci = cb; ci < ce; ++ci) {
            const float s = map_.sigmaSum[ci];
            if (!(s > 0)) continue;
            for (size_t c = 0; c < 3; ++c) {
                double sum = 0;
                for (size_t k = 0; k < 8; ++k) {
                    const std::uint32_t f = map_.children[ci * 8 + k];
                    if (f != FineCoarseMap::kNone) sum += double(sigmaT_[f]) * t[size_t(f) * 3 + c];
                }
                const float mean = float(sum / s);
                for (size_t d = 0; d < nb; ++d) shapeSum_[(ci * nb + d) * 3 + c] -= mean;
            }
        }
    });
}

SeparableSource SeparableFold::finish(const HalfBuffer* minus, const std::vector<float>* minusIsotropic) {
    const size_t nb = size_t(nb_);
    double weightSum = 0;
    for (float w : binWeight_) weightSum += w;
    out_.coarseRows = map_.rows();
    if (minus && minus->size() != map_.rows() * nb * 3)
        throw Error("SeparableFold", "the part to take holds " + std::to_string(minus->size()) + " values for " +
                                         std::to_string(map_.rows()) + " rows of " + std::to_string(nb) + " bins");
    if (minusIsotropic && minusIsotropic->size() != map_.parent.size() * 3)
        throw Error("SeparableFold", "the isotropic part to take holds " + std::to_string(minusIsotropic->size()) +
                                         " values for " + std::to_string(map_.parent.size()) + " fine voxels");
    parallelForChunks(map_.sigmaSum.size(), 4096, [&](size_t cb, size_t ce) {
        for (size_t ci = cb; ci < ce; ++ci) {
            const float s = map_.sigmaSum[ci];
            float* r = &shapeSum_[ci * nb * 3];
            for (size_t i = 0; i < nb * 3; ++i) r[i] = s > 0 ? r[i] / s : 0.0f;
            if (minus)
                for (size_t d = 0; d < nb; ++d)
                    for (size_t c = 0; c < 3; ++c) r[d * 3 + c] -= minus->at(out_.heldIndex(ci, d, c));
        }
    });
    if (minus) takeIntegralFromChildren(*minus);
    if (minusIsotropic) {
        takeIsotropicFromShape(*minusIsotropic);
        const float W = float(weightSum);
        parallelForChunks(map_.parent.size(), 4096, [&](size_t fb, size_t fe) {
            for (size_t f = fb; f < fe; ++f)
                if (map_.parent[f] != FineCoarseMap::kNone)
                    for (size_t c = 0; c < 3; ++c) out_.magnitude[f * 3 + c] -= W * (*minusIsotropic)[f * 3 + c];
        });
    }
    out_.shape = SeparableSource::holdByBin(shapeSum_, nb_);
    shapeSum_ = std::vector<float>();
    assignZeroed(out_.norm, map_.sigmaSum.size() * 3);
    assignZeroed(out_.invAbs, map_.sigmaSum.size() * 3);
    out_.invWeight = float(1.0 / weightSum);
    parallelForChunks(map_.sigmaSum.size(), 4096, [&](size_t cb, size_t ce) {
        for (size_t ci = cb; ci < ce; ++ci)
            for (size_t c = 0; c < 3; ++c) {
                double norm = 0, abs = 0;
                for (size_t d = 0; d < nb; ++d) {
                    const double r = out_.shape.at(out_.heldIndex(ci, d, c));
                    norm += double(binWeight_[d]) * r;
                    abs += double(binWeight_[d]) * std::fabs(r);
                }
                out_.norm[ci * 3 + c] = float(norm);
                out_.invAbs[ci * 3 + c] = abs > 0 ? float(1.0 / abs) : 0.0f;
            }
    });
    SeparableSource s = std::move(out_);
    out_ = SeparableSource();
    return s;
}

}  // namespace lpm

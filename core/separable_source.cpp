// Separable fine-grid sources (core/separable_source.h).
#include "core/separable_source.h"

#include <algorithm>

#include "core/malloc_policy.h"
#include "core/parallel.h"
#include "core/sweep.h"

namespace lpm {

FineCoarseMap::FineCoarseMap(const Medium& f, const Medium& c) {
    assignZeroed(parent, f.voxelCount());
    std::fill(parent.begin(), parent.end(), kNone);
    children.assign(c.voxelCount() * 8, kNone);
    assignZeroed(sigmaSum, c.voxelCount());
    parallelForChunks(size_t(c.nz), 1, [&](size_t zb, size_t ze) {
        for (int z = int(zb); z < int(ze); ++z)
            for (int y = 0; y < c.ny; ++y)
                for (int x = 0; x < c.nx; ++x) {
                    const size_t ci = c.index(x, y, z);
                    if (ci == Medium::npos) continue;
                    double sigma = 0;
                    for (int k = 0; k < 8; ++k) {
                        const int fx = 2 * x + (k & 1), fy = 2 * y + ((k >> 1) & 1), fz = 2 * z + (k >> 2);
                        if (fx >= f.nx || fy >= f.ny || fz >= f.nz) continue;
                        const size_t fi = f.index(fx, fy, fz);
                        if (fi == Medium::npos) continue;
                        children[ci * 8 + size_t(k)] = std::uint32_t(fi);
                        parent[fi] = std::uint32_t(ci);
                        sigma += f.sigmaT[fi];
                    }
                    sigmaSum[ci] = float(sigma);
                }
    });
}

std::vector<float> SeparableSource::restricted() const {
    std::vector<float> out = shape;
    for (size_t i = 0; i < offset.size(); ++i) out[i] += offset[i];
    return out;
}

void SeparableSource::addToOffset(const std::vector<float>& coarse, float scale) {
    if (offset.empty()) offset.assign(shape.size(), 0.0f);
    for (size_t i = 0; i < offset.size(); ++i) offset[i] += scale * coarse[i];
}

void SeparableSource::fillBin(const FineCoarseMap& map, int bin, float* out) const {
    const size_t nb = size_t(bins);
    parallelForChunks(map.parent.size(), 1 << 14, [&](size_t vb, size_t ve) {
        for (size_t v = vb; v < ve; ++v) {
            const std::uint32_t p = map.parent[v];
            for (int c = 0; c < 3; ++c) {
                if (p == FineCoarseMap::kNone) {
                    out[v * 3 + c] = 0.0f;
                    continue;
                }
                const size_t i = (p * nb + size_t(bin)) * 3 + size_t(c);
                out[v * 3 + c] = magnitude[v * 3 + c] * shape[i] * invNorm[p * 3 + size_t(c)] +
                                 (offset.empty() ? 0.0f : offset[i]);
            }
        }
    });
}

double SeparableSource::power(const FineCoarseMap& map, const std::vector<double>& binWeight, const RGB& albedo,
                              double fineVoxelVolume) const {
    const std::vector<float> r = restricted();
    double p = 0;
    for (size_t ci = 0; ci < map.sigmaSum.size(); ++ci)
        for (int d = 0; d < bins; ++d)
            for (int c = 0; c < 3; ++c)
                p += double(r[(ci * size_t(bins) + size_t(d)) * 3 + size_t(c)]) * map.sigmaSum[ci] * albedo[c] *
                     binWeight[size_t(d)];
    return p * fineVoxelVolume / 3.0;
}

SeparableFold::SeparableFold(const FineCoarseMap& map, const std::vector<float>& sigmaT,
                             const std::vector<double>& binWeight, int shCoeffs)
    : map_(map), sigmaT_(sigmaT), binWeight_(binWeight.begin(), binWeight.end()), nb_(int(binWeight.size())),
      nc_(shCoeffs) {
    out_.bins = nb_;
    assignZeroed(out_.magnitude, map.parent.size() * 3);
    assignZeroed(out_.shape, map.sigmaSum.size() * size_t(nb_) * 3);
}

// As foldDeposits (core/pass_runner.cpp) with M = 1, each child's bin row formed in a local
// row and reduced at once.
void SeparableFold::fold(bool depositSh, const Job* jobs, size_t n, const std::vector<std::vector<float>>& phi,
                         std::vector<float>& sh) {
    const int nb = nb_, nc = nc_;
    std::vector<float> binC(n * size_t(nb)), shC(n * size_t(nc));
    for (size_t j = 0; j < n; ++j) {
        for (int d = 0; d < nb; ++d) binC[j * size_t(nb) + size_t(d)] = float(jobs[j].binCoef[size_t(d)]);
        for (int k = 0; k < nc; ++k) shC[j * size_t(nc) + size_t(k)] = float(jobs[j].shCoef[size_t(k)]);
    }
    const size_t coarseCount = map_.sigmaSum.size();
    parallelForChunks(coarseCount, 512, [&](size_t cb, size_t ce) {
        std::vector<float> row(size_t(nb) * 3);
        for (size_t ci = cb; ci < ce; ++ci)
            for (int k = 0; k < 8; ++k) {
                const std::uint32_t f = map_.children[ci * 8 + size_t(k)];
                if (f == FineCoarseMap::kNone) continue;
                std::fill(row.begin(), row.end(), 0.0f);
                bool any = false;
                for (size_t j = 0; j < n; ++j) {
                    const float* p = &phi[j][size_t(f) * 3];
                    if (p[0] == 0 && p[1] == 0 && p[2] == 0) continue;
                    any = true;
                    if (depositSh)
                        for (int s = 0; s < nc; ++s)
                            for (int c = 0; c < 3; ++c) sh[(size_t(f) * nc + size_t(s)) * 3 + size_t(c)] += shC[j * size_t(nc) + size_t(s)] * p[c];
                    const float* cj = &binC[j * size_t(nb)];
                    for (int d = 0; d < nb; ++d)
                        for (int c = 0; c < 3; ++c) row[size_t(d) * 3 + size_t(c)] += cj[d] * p[c];
                }
                if (!any) continue;
                const float sigma = sigmaT_[f];
                float* mag = &out_.magnitude[size_t(f) * 3];
                float* acc = &out_.shape[ci * size_t(nb) * 3];
                for (int d = 0; d < nb; ++d)
                    for (int c = 0; c < 3; ++c) {
                        const float u = row[size_t(d) * 3 + size_t(c)];
                        mag[c] += binWeight_[size_t(d)] * u;
                        acc[size_t(d) * 3 + size_t(c)] += sigma * u;
                    }
            }
    });
}

SeparableSource SeparableFold::finish() {
    const size_t nb = size_t(nb_);
    assignZeroed(out_.invNorm, map_.sigmaSum.size() * 3);
    parallelForChunks(map_.sigmaSum.size(), 4096, [&](size_t cb, size_t ce) {
        for (size_t ci = cb; ci < ce; ++ci) {
            const float s = map_.sigmaSum[ci];
            float* r = &out_.shape[ci * nb * 3];
            for (size_t i = 0; i < nb * 3; ++i) r[i] = s > 0 ? r[i] / s : 0.0f;
            for (int c = 0; c < 3; ++c) {
                double norm = 0;
                for (size_t d = 0; d < nb; ++d) norm += double(binWeight_[d]) * r[d * 3 + size_t(c)];
                out_.invNorm[ci * 3 + size_t(c)] = norm > 0 ? float(1.0 / norm) : 0.0f;
            }
        }
    });
    SeparableSource s = std::move(out_);
    out_ = SeparableSource();
    return s;
}

}  // namespace lpm

// The diffusion tail's operator and its conjugate-gradient solve: core/diffusion_tail.h.
#include "core/diffusion_tail.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "core/parallel.h"

namespace lpm {

namespace {

/// Sums over fixed chunks of voxels, added in chunk order: the same for any thread count.
constexpr std::size_t kChunk = std::size_t(1) << 13;

struct ChunkSums {
    std::vector<std::array<double, 6>> part;
    explicit ChunkSums(std::size_t voxels) : part((voxels + kChunk - 1) / kChunk) {}
    /// The three sums from slot k0 (0 or 3).
    std::array<double, 3> total(int k0) const {
        std::array<double, 3> t{0, 0, 0};
        for (const auto& p : part)
            for (int c = 0; c < 3; ++c) t[c] += p[std::size_t(k0 + c)];
        return t;
    }
    /// body(v, sums) for each voxel of each chunk, chunks in parallel, sums zeroed first.
    template <class Body>
    void forEach(std::size_t voxels, const Body& body) {
        parallelForChunks(part.size(), 1, [&](std::size_t qb, std::size_t qe) {
            for (std::size_t q = qb; q < qe; ++q) {
                part[q] = {0, 0, 0, 0, 0, 0};
                const std::size_t end = std::min(voxels, (q + 1) * kChunk);
                for (std::size_t v = q * kChunk; v < end; ++v) body(v, part[q]);
            }
        });
    }
};

}  // namespace

DiffusionOperator::DiffusionOperator(const Medium& m, double diffusionCap)
    : sigmaT_(m.sigmaT), nbr_(m.voxelCount()), coef_(m.voxelCount()), leak_(m.voxelCount(), 0.0f) {
    if (!(diffusionCap > 0))
        throw Error("LPM", "diffusion tail: the cap on D must be > 0, got " + std::to_string(diffusionCap));
    const double h = m.voxelSize.x;
    const auto D = [&](std::size_t v) { return std::min(diffusionCap * h, 1.0 / (3.0 * double(m.sigmaT[v]))); };
    static constexpr int kStep[6][3] = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
    parallelForChunks(m.voxelCount(), 4096, [&](std::size_t vb, std::size_t ve) {
        for (std::size_t v = vb; v < ve; ++v) {
            nbr_[v].fill(-1);
            coef_[v].fill(0.0f);
            if (!(m.sigmaT[v] > 0)) continue;
            int x, y, z;
            m.coord(v, x, y, z);
            double leak = 0;
            for (int k = 0; k < 6; ++k) {
                const int a = x + kStep[k][0], b = y + kStep[k][1], c = z + kStep[k][2];
                const bool inside = a >= 0 && b >= 0 && c >= 0 && a < m.nx && b < m.ny && c < m.nz;
                const std::size_t j = inside ? m.index(a, b, c) : Medium::npos;
                if (j != Medium::npos && m.sigmaT[j] > 0) {
                    const double Di = D(v), Dj = D(j);
                    nbr_[v][std::size_t(k)] = std::int32_t(j);
                    coef_[v][std::size_t(k)] = float(2.0 * Di * Dj / ((Di + Dj) * h * h));
                    leak += coef_[v][std::size_t(k)];
                } else {
                    leak += 2.0 * D(v) / (h * (h + 4.0 * D(v)));  // Marshak: light leaves
                }
            }
            leak_[v] = float(leak);
        }
    });
}

void DiffusionOperator::apply(const std::vector<float>& x, const RGB& albedo, std::vector<float>& y) const {
    y.resize(x.size());
    parallelForChunks(voxels(), 4096, [&](std::size_t vb, std::size_t ve) {
        for (std::size_t v = vb; v < ve; ++v)
            for (int c = 0; c < 3; ++c) {
                const std::size_t i = v * 3 + std::size_t(c);
                if (!(sigmaT_[v] > 0)) {
                    y[i] = x[i];
                    continue;
                }
                float s = (leak_[v] + sigmaT_[v] * (1.0f - albedo[c])) * x[i];
                for (int k = 0; k < 6; ++k)
                    if (nbr_[v][std::size_t(k)] >= 0)
                        s -= coef_[v][std::size_t(k)] * x[std::size_t(nbr_[v][std::size_t(k)]) * 3 + std::size_t(c)];
                y[i] = s;
            }
    });
}

DiffusionSolve DiffusionOperator::solve(const std::vector<float>& b, const RGB& albedo, double tolerance,
                                        int maxIterations) const {
    const std::size_t N = voxels(), n = N * 3;
    if (b.size() != n)
        throw Error("LPM", "diffusion tail: source of " + std::to_string(b.size()) + " values for " +
                               std::to_string(N) + " voxels x RGB");
    std::vector<float> diag(n), x(n, 0.0f), res(n), z(n), p(n), Ap(n);
    ChunkSums sums(N);
    sums.forEach(N, [&](std::size_t v, std::array<double, 6>& s) {
        for (int c = 0; c < 3; ++c) {
            const std::size_t i = v * 3 + std::size_t(c);
            const bool medium = sigmaT_[v] > 0;
            diag[i] = medium ? leak_[v] + sigmaT_[v] * (1.0f - albedo[c]) : 1.0f;
            res[i] = medium ? sigmaT_[v] * b[i] : 0.0f;
            z[i] = res[i] / diag[i];
            p[i] = z[i];
            s[std::size_t(c)] += double(res[i]) * res[i];
            s[std::size_t(3 + c)] += double(res[i]) * z[i];
        }
    });
    const std::array<double, 3> bb = sums.total(0);
    std::array<double, 3> rz = sums.total(3), rr = bb;
    const auto converged = [&] {
        for (int c = 0; c < 3; ++c)
            if (rr[std::size_t(c)] > tolerance * tolerance * bb[std::size_t(c)]) return false;
        return true;
    };
    DiffusionSolve out;
    for (; out.iterations < maxIterations && !converged(); ++out.iterations) {
        apply(p, albedo, Ap);
        sums.forEach(N, [&](std::size_t v, std::array<double, 6>& s) {
            for (std::size_t c = 0; c < 3; ++c) s[c] += double(p[v * 3 + c]) * Ap[v * 3 + c];
        });
        const std::array<double, 3> pAp = sums.total(0);
        float a[3];
        for (std::size_t c = 0; c < 3; ++c) a[c] = pAp[c] > 0 ? float(rz[c] / pAp[c]) : 0.0f;
        sums.forEach(N, [&](std::size_t v, std::array<double, 6>& s) {
            for (std::size_t c = 0; c < 3; ++c) {
                const std::size_t i = v * 3 + c;
                x[i] += a[c] * p[i];
                res[i] -= a[c] * Ap[i];
                z[i] = res[i] / diag[i];
                s[c] += double(res[i]) * res[i];
                s[3 + c] += double(res[i]) * z[i];
            }
        });
        rr = sums.total(0);
        const std::array<double, 3> rzNext = sums.total(3);
        float beta[3];
        for (std::size_t c = 0; c < 3; ++c) beta[c] = rz[c] > 0 ? float(rzNext[c] / rz[c]) : 0.0f;
        rz = rzNext;
        parallelForChunks(N, 1 << 14, [&](std::size_t vb, std::size_t ve) {
            for (std::size_t i = vb * 3; i < ve * 3; ++i) p[i] = z[i] + beta[i % 3] * p[i];
        });
    }
    for (std::size_t c = 0; c < 3; ++c) out.relativeResidual[c] = bb[c] > 0 ? std::sqrt(rr[c] / bb[c]) : 0.0;
    out.J = std::move(x);
    return out;
}

}  // namespace lpm

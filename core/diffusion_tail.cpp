// The diffusion tail's operator and its conjugate-gradient solve: core/diffusion_tail.h.
#include "core/diffusion_tail.h"

#include "core/diffusion_multigrid.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "core/parallel.h"

namespace lpm {

namespace {

constexpr int kStep[6][3] = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};

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

DiffusionOperator::DiffusionOperator(const Medium& m, double diffusionCap, double diffusionFloor,
                                     double transportFactor)
    : m_(m), face_(m.voxelCount()) {
    if (!(diffusionCap > 0))
        throw Error("LPM", "diffusion tail: the cap on D must be > 0, got " + std::to_string(diffusionCap));
    if (!(diffusionFloor >= 0 && diffusionFloor <= diffusionCap))
        throw Error("LPM", "diffusion tail: the floor on D must be in [0, " + std::to_string(diffusionCap) + "], got " +
                               std::to_string(diffusionFloor));
    if (!(transportFactor > 0 && transportFactor <= 2))
        throw Error("LPM", "diffusion tail: the transport factor 1 - albedo g must be in (0, 2], got " +
                               std::to_string(transportFactor));
    if (m.sparse()) linkTiles();
    const double h = m.voxelSize.x;
    const auto D = [&](std::size_t v) {
        return std::clamp(1.0 / (3.0 * double(m.sigmaT[v]) * transportFactor), diffusionFloor * h, diffusionCap * h);
    };
    const auto hasMedium = [&](std::size_t v) {
        int x, y, z;
        m.coord(v, x, y, z);
        return m.sigmaT[v] > 0 && x >= 0 && y >= 0 && z >= 0 && x < m.nx && y < m.ny && z < m.nz;
    };
    parallelForChunks(m.voxelCount(), 4096, [&](std::size_t vb, std::size_t ve) {
        for (std::size_t v = vb; v < ve; ++v) {
            face_[v] = {0, 0, 0, 0};
            if (!hasMedium(v)) continue;
            std::size_t nbr[6];
            neighbours(v, nbr);
            double leak = 0;
            for (int k = 0; k < 6; ++k) {
                const std::size_t j = nbr[k];
                if (j != Medium::npos && hasMedium(j)) {
                    const double Di = D(v), Dj = D(j);
                    const float coef = float(2.0 * Di * Dj / ((Di + Dj) * h * h));
                    if (k % 2 == 0) face_[v][std::size_t(k / 2)] = coef;
                    leak += coef;
                } else {
                    leak += 2.0 * D(v) / (h * (h + 4.0 * D(v)));  // Marshak: light leaves
                }
            }
            face_[v][3] = float(leak);
        }
    });
}

void DiffusionOperator::linkTiles() {
    const Medium& m = m_;
    tileNeighbour_.resize(m.storedTiles);
    const int tnx = m.tilesX(), tny = m.tilesY(), tnz = m.tilesZ();
    for (std::size_t slot = 0; slot < m.storedTiles; ++slot) {
        const int t = m.slotTile[slot];
        const int tx = t % tnx, ty = (t / tnx) % tny, tz = t / (tnx * tny);
        for (int k = 0; k < 6; ++k) {
            const int a = tx + kStep[k][0], b = ty + kStep[k][1], c = tz + kStep[k][2];
            const bool inside = a >= 0 && b >= 0 && c >= 0 && a < tnx && b < tny && c < tnz;
            tileNeighbour_[slot][std::size_t(k)] = inside ? m.tileSlot[std::size_t(a + tnx * (b + tny * c))] : -1;
        }
    }
}

inline void DiffusionOperator::neighbours(std::size_t v, std::size_t (&nbr)[6]) const {
    if (!m_.sparse()) {
        int x, y, z;
        m_.coord(v, x, y, z);
        for (int k = 0; k < 6; ++k) {
            const int a = x + kStep[k][0], b = y + kStep[k][1], c = z + kStep[k][2];
            const bool inside = a >= 0 && b >= 0 && c >= 0 && a < m_.nx && b < m_.ny && c < m_.nz;
            nbr[k] = inside ? m_.index(a, b, c) : Medium::npos;
        }
        return;
    }
    // In a tile: local index lx + 8 ly + 64 lz; across its face, the neighbouring tile's
    // voxel on the opposite face.
    constexpr std::size_t T = Medium::kTile, TV = Medium::kTileVoxels;
    const std::size_t slot = v / TV, local = v % TV;
    const std::size_t l[3] = {local % T, (local / T) % T, local / (T * T)};
    const auto& across = tileNeighbour_[slot];
    for (std::size_t axis = 0; axis < 3; ++axis) {
        const std::size_t stride = axis == 0 ? 1 : (axis == 1 ? T : T * T), wrap = (T - 1) * stride;
        const std::int32_t up = across[2 * axis], down = across[2 * axis + 1];
        nbr[2 * axis] = l[axis] + 1 < T ? v + stride : (up < 0 ? Medium::npos : std::size_t(up) * TV + local - wrap);
        nbr[2 * axis + 1] =
            l[axis] > 0 ? v - stride : (down < 0 ? Medium::npos : std::size_t(down) * TV + local + wrap);
    }
}

void DiffusionOperator::apply(const std::vector<float>& x, const RGB& albedo, std::vector<float>& y) const {
    y.resize(x.size());
    parallelForChunks(voxels(), 4096, [&](std::size_t vb, std::size_t ve) {
        for (std::size_t v = vb; v < ve; ++v) {
            if (!hasMedium(v)) {
                for (std::size_t c = 0; c < 3; ++c) y[v * 3 + c] = x[v * 3 + c];
                continue;
            }
            std::size_t nbr[6];
            float coef[6];
            neighbours(v, nbr);
            for (int k = 0; k < 6; ++k) {  // a -face's coefficient is held by the voxel below
                const std::size_t j = nbr[k];
                coef[k] = j == Medium::npos ? 0.0f : face_[k % 2 == 0 ? v : j][std::size_t(k / 2)];
                if (!(coef[k] > 0)) nbr[k] = v;  // no face: a zero term (x is finite)
            }
            const float* xv = &x[v * 3];
            float s[3];
            for (int c = 0; c < 3; ++c) s[c] = diagonal(v, albedo[c]) * xv[c];
            for (int k = 0; k < 6; ++k) {
                const float* xn = &x[nbr[k] * 3];
                for (int c = 0; c < 3; ++c) s[c] -= coef[k] * xn[c];
            }
            for (int c = 0; c < 3; ++c) y[v * 3 + std::size_t(c)] = s[c];
        }
    });
}

DiffusionSolve DiffusionOperator::solve(const std::vector<float>& b, const RGB& albedo, double tolerance,
                                        int maxIterations, const DiffusionMultigrid* multigrid) const {
    if (b.size() != voxels() * 3)
        throw Error("LPM", "diffusion tail: source of " + std::to_string(b.size()) + " values for " +
                               std::to_string(voxels()) + " voxels x RGB");
    return solve(b.data(), 3, albedo, tolerance, maxIterations, multigrid);
}

// Preconditioned CG: z = M res from the multigrid when given, else res / diagonal (Jacobi,
// computed where it is used rather than held).
DiffusionSolve DiffusionOperator::solve(const float* b, std::size_t stride, const RGB& albedo, double tolerance,
                                        int maxIterations, const DiffusionMultigrid* multigrid) const {
    const std::size_t N = voxels(), n = N * 3;
    std::vector<float> x(n, 0.0f), res(n), p(n), Ap(n), zHeld(multigrid ? n : 0);
    const auto z = [&](std::size_t v, std::size_t c) {
        return multigrid ? zHeld[v * 3 + c] : res[v * 3 + c] / diagonal(v, albedo[int(c)]);
    };
    ChunkSums sums(N);
    // <res, z> per channel into rz (after z = M res when the multigrid preconditions).
    const auto resDotZ = [&](std::array<double, 3>& rz) {
        multigrid->precondition(res, albedo, zHeld, Ap);
        sums.forEach(N, [&](std::size_t v, std::array<double, 6>& s) {
            for (std::size_t c = 0; c < 3; ++c) s[c] += double(res[v * 3 + c]) * zHeld[v * 3 + c];
        });
        rz = sums.total(0);
    };
    sums.forEach(N, [&](std::size_t v, std::array<double, 6>& s) {
        for (std::size_t c = 0; c < 3; ++c) {
            const std::size_t i = v * 3 + c;
            res[i] = hasMedium(v) ? m_.sigmaT[v] * b[v * stride + c] : 0.0f;
            s[c] += double(res[i]) * res[i];
            if (!multigrid) s[3 + c] += double(res[i]) * z(v, c);
        }
    });
    const std::array<double, 3> bb = sums.total(0);
    std::array<double, 3> rz = sums.total(3), rr = bb;
    if (multigrid) resDotZ(rz);
    parallelForChunks(N, 1 << 14, [&](std::size_t vb, std::size_t ve) {
        for (std::size_t v = vb; v < ve; ++v)
            for (std::size_t c = 0; c < 3; ++c) p[v * 3 + c] = z(v, c);
    });
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
                s[c] += double(res[i]) * res[i];
                if (!multigrid) s[3 + c] += double(res[i]) * z(v, c);
            }
        });
        rr = sums.total(0);
        std::array<double, 3> rzNext = sums.total(3);
        if (multigrid) resDotZ(rzNext);
        float beta[3];
        for (std::size_t c = 0; c < 3; ++c) beta[c] = rz[c] > 0 ? float(rzNext[c] / rz[c]) : 0.0f;
        rz = rzNext;
        parallelForChunks(N, 1 << 14, [&](std::size_t vb, std::size_t ve) {
            for (std::size_t v = vb; v < ve; ++v)
                for (std::size_t c = 0; c < 3; ++c) p[v * 3 + c] = z(v, c) + beta[c] * p[v * 3 + c];
        });
    }
    for (std::size_t c = 0; c < 3; ++c) out.relativeResidual[c] = bb[c] > 0 ? std::sqrt(rr[c] / bb[c]) : 0.0;
    out.J = std::move(x);
    return out;
}

}  // namespace lpm

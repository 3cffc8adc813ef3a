// The diffusion tail's multigrid preconditioner: core/diffusion_multigrid.h.
#include "core/diffusion_multigrid.h"

#include <algorithm>

#include "core/parallel.h"

namespace lpm {

namespace {

constexpr int kSmooth = 2;              ///< damped-Jacobi steps before and after each coarse correction
constexpr float kJacobiWeight = 0.75f;  ///< their damping (below 1: Jacobi then damps every error mode)
constexpr int kCoarsest = 16;           ///< Jacobi steps on the coarsest level
constexpr std::size_t kCoarsestCells = 4096;
/// The coarse correction's weight: a piecewise-constant prolongation corrects smooth error
/// too little (its energy is higher than the interpolated one's), and the usual remedy is
/// to over-correct by a fixed factor (Braess 1995; Vanek et al. 1996 for aggregation).
constexpr float kOverCorrect = 1.6f;

using Level = DiffusionMultigrid::Level;

/// kSmooth damped-Jacobi steps on A x = b (from x = 0 when `fromZero`); t is scratch.
template <class Op>
void jacobi(const Op& op, std::size_t cells, const RGB& albedo, const std::vector<float>& b, std::vector<float>& x,
            std::vector<float>& t, bool fromZero) {
    int steps = kSmooth;
    if (fromZero) {
        parallelForChunks(cells, 4096, [&](std::size_t ib, std::size_t ie) {
            for (std::size_t i = ib; i < ie; ++i)
                for (int c = 0; c < 3; ++c)
                    x[i * 3 + std::size_t(c)] = kJacobiWeight * b[i * 3 + std::size_t(c)] / op.diagonal(i, albedo[c]);
        });
        --steps;
    }
    for (int s = 0; s < steps; ++s) {
        op.apply(x, albedo, t);
        parallelForChunks(cells, 4096, [&](std::size_t ib, std::size_t ie) {
            for (std::size_t i = ib; i < ie; ++i)
                for (int c = 0; c < 3; ++c) {
                    const std::size_t k = i * 3 + std::size_t(c);
                    x[k] += kJacobiWeight * (b[k] - t[k]) / op.diagonal(i, albedo[c]);
                }
        });
    }
}

/// The fine grid's cells as the level above sees them: the operator's stored voxels.
struct FineCells {
    const DiffusionOperator& a;
    std::size_t cells() const { return a.voxels(); }
    int dim(int axis) const { return a.medium().dim(axis); }
    /// The cell at block coordinates (x, y, z) when it has medium, else -1.
    std::int64_t at(int x, int y, int z) const {
        const Medium& m = a.medium();
        if (x >= m.nx || y >= m.ny || z >= m.nz) return -1;
        const std::size_t v = m.index(x, y, z);
        return v != Medium::npos && a.hasMedium(v) ? std::int64_t(v) : -1;
    }
    bool hasMedium(std::size_t i) const { return a.hasMedium(i); }
    void coords(std::size_t i, int& x, int& y, int& z) const { a.medium().coord(i, x, y, z); }
    const std::array<float, 4>& face(std::size_t i) const { return a.faces(i); }
    float sigma(std::size_t i) const { return a.medium().sigmaT[i]; }
};

/// A dense coarse level's cells, seen so by the level above it.
struct DenseCells {
    const Level& L;
    std::size_t cells() const { return L.cells(); }
    int dim(int axis) const { return axis == 0 ? L.nx : (axis == 1 ? L.ny : L.nz); }
    std::int64_t at(int x, int y, int z) const {
        if (x >= L.nx || y >= L.ny || z >= L.nz) return -1;
        const std::size_t i = L.index(x, y, z);
        return L.hasMedium(i) ? std::int64_t(i) : -1;
    }
    bool hasMedium(std::size_t i) const { return L.hasMedium(i); }
    void coords(std::size_t i, int& x, int& y, int& z) const {
        x = int(i % std::size_t(L.nx));
        y = int((i / std::size_t(L.nx)) % std::size_t(L.ny));
        z = int(i / (std::size_t(L.nx) * std::size_t(L.ny)));
    }
    const std::array<float, 4>& face(std::size_t i) const { return L.face[i]; }
    float sigma(std::size_t i) const { return L.sigma[i]; }
};

/// body(k, d, i) for each child k of coarse cell (X, Y, Z) with medium: d its offset in the
/// 2x2x2 block, i its index on the finer level.
template <class Cells, class Body>
void forEachChild(const Cells& finer, int X, int Y, int Z, const Body& body) {
    for (int k = 0; k < 8; ++k) {
        const int d[3] = {k & 1, (k >> 1) & 1, k >> 2};
        const std::int64_t i = finer.at(2 * X + d[0], 2 * Y + d[1], 2 * Z + d[2]);
        if (i >= 0) body(d, std::size_t(i));
    }
}

/// t = b - A x, and the coarser level's right side summed from it over each cell's
/// children (unless `coarse` is null: the caller sums).
template <class Op, class Cells>
void restrictResidual(const Op& op, const Cells& finer, const RGB& albedo, const std::vector<float>& b,
                      const std::vector<float>& x, std::vector<float>& t, const Level* coarseLevel) {
    op.apply(x, albedo, t);
    parallelForChunks(t.size(), 1 << 14, [&](std::size_t ib, std::size_t ie) {
        for (std::size_t i = ib; i < ie; ++i) t[i] = b[i] - t[i];
    });
    if (!coarseLevel) return;
    const Level& coarse = *coarseLevel;
    DenseCells grid{coarse};
    parallelForChunks(coarse.cells(), 4096, [&](std::size_t Ib, std::size_t Ie) {
        for (std::size_t I = Ib; I < Ie; ++I) {
            int X, Y, Z;
            grid.coords(I, X, Y, Z);
            float s[3] = {0, 0, 0};
            forEachChild(finer, X, Y, Z, [&](const int*, std::size_t i) {
                for (std::size_t c = 0; c < 3; ++c) s[c] += t[i * 3 + c];
            });
            for (std::size_t c = 0; c < 3; ++c) coarse.rhs[I * 3 + c] = s[c];
        }
    });
}

/// x += kOverCorrect times the coarser level's x at each cell's parent.
template <class Cells>
void prolongAdd(const Cells& finer, const Level& coarse, std::vector<float>& x) {
    parallelForChunks(finer.cells(), 4096, [&](std::size_t ib, std::size_t ie) {
        for (std::size_t i = ib; i < ie; ++i) {
            if (!finer.hasMedium(i)) continue;
            int fx, fy, fz;
            finer.coords(i, fx, fy, fz);
            const std::size_t P = coarse.index(fx / 2, fy / 2, fz / 2);
            for (std::size_t c = 0; c < 3; ++c) x[i * 3 + c] += kOverCorrect * coarse.sol[P * 3 + c];
        }
    });
}

/// body(i, X, Y, Z) for each stored fine voxel i with medium and its parent cell (X, Y, Z),
/// a tile at a time (an 8^3 tile feeds its own 4^3 parents: tiles may run in parallel).
template <class Body>
void forEachTileVoxel(const DiffusionOperator& a, std::size_t slot, const Body& body) {
    const Medium& m = a.medium();
    constexpr int T = Medium::kTile;
    const int t = m.slotTile[slot];
    const int tx = t % m.tilesX(), ty = (t / m.tilesX()) % m.tilesY(), tz = t / (m.tilesX() * m.tilesY());
    std::size_t i = slot * Medium::kTileVoxels;
    for (int z = 0; z < T; ++z)
        for (int y = 0; y < T; ++y)
            for (int x = 0; x < T; ++x, ++i)
                if (a.hasMedium(i)) body(i, (tx * T + x) / 2, (ty * T + y) / 2, (tz * T + z) / 2);
}

/// restrictResidual's sum and prolongAdd from the fine grid when it is stored in tiles.
void restrictFromTiles(const DiffusionOperator& a, const std::vector<float>& t, const Level& coarse) {
    std::fill(coarse.rhs.begin(), coarse.rhs.end(), 0.0f);
    parallelForChunks(a.medium().storedTiles, 8, [&](std::size_t sb, std::size_t se) {
        for (std::size_t slot = sb; slot < se; ++slot)
            forEachTileVoxel(a, slot, [&](std::size_t i, int X, int Y, int Z) {
                float* to = &coarse.rhs[coarse.index(X, Y, Z) * 3];
                for (std::size_t c = 0; c < 3; ++c) to[c] += t[i * 3 + c];
            });
    });
}

void prolongToTiles(const DiffusionOperator& a, const Level& coarse, std::vector<float>& x) {
    parallelForChunks(a.medium().storedTiles, 8, [&](std::size_t sb, std::size_t se) {
        for (std::size_t slot = sb; slot < se; ++slot)
            forEachTileVoxel(a, slot, [&](std::size_t i, int X, int Y, int Z) {
                const float* from = &coarse.sol[coarse.index(X, Y, Z) * 3];
                for (std::size_t c = 0; c < 3; ++c) x[i * 3 + c] += kOverCorrect * from[c];
            });
    });
}

/// The level above a finer one, its operator the Galerkin product (header).
template <class Cells>
Level coarsen(const Cells& finer) {
    Level L;
    L.nx = (finer.dim(0) + 1) / 2;
    L.ny = (finer.dim(1) + 1) / 2;
    L.nz = (finer.dim(2) + 1) / 2;
    const std::size_t n = std::size_t(L.nx) * std::size_t(L.ny) * std::size_t(L.nz);
    L.face.resize(n);
    L.sigma.resize(n);
    L.rhs.resize(n * 3);
    L.sol.resize(n * 3);
    L.tmp.resize(n * 3);
    const DenseCells grid{L};
    parallelForChunks(n, 1024, [&](std::size_t Ib, std::size_t Ie) {
        for (std::size_t I = Ib; I < Ie; ++I) {
            int X, Y, Z;
            grid.coords(I, X, Y, Z);
            double sigma = 0, leak = 0, f[3] = {0, 0, 0};
            forEachChild(finer, X, Y, Z, [&](const int* d, std::size_t i) {
                const std::array<float, 4>& ff = finer.face(i);
                sigma += finer.sigma(i);
                leak += ff[3];
                for (int a = 0; a < 3; ++a) {  // a +face inside the aggregate is counted from both sides
                    if (d[a] == 0) leak -= 2.0 * ff[std::size_t(a)];
                    else f[a] += ff[std::size_t(a)];
                }
            });
            L.face[I] = {float(f[0]), float(f[1]), float(f[2]), float(std::max(leak, 0.0))};
            L.sigma[I] = float(sigma);
        }
    });
    return L;
}

}  // namespace

void Level::apply(const std::vector<float>& in, const RGB& albedo, std::vector<float>& y) const {
    y.resize(in.size());
    const std::size_t sx = 1, sy = std::size_t(nx), sz = std::size_t(nx) * std::size_t(ny);
    parallelForChunks(cells(), 4096, [&](std::size_t ib, std::size_t ie) {
        for (std::size_t I = ib; I < ie; ++I) {
            if (!hasMedium(I)) {
                for (std::size_t c = 0; c < 3; ++c) y[I * 3 + c] = in[I * 3 + c];
                continue;
            }
            const int X = int(I % sy), Y = int((I / sy) % std::size_t(ny)), Z = int(I / sz);
            // Neighbours and their face coefficients (a -face's held by the cell below).
            const std::size_t nbr[6] = {I + sx, I - sx, I + sy, I - sy, I + sz, I - sz};
            const float coef[6] = {X + 1 < nx ? face[I][0] : 0.0f, X > 0 ? face[I - sx][0] : 0.0f,
                                   Y + 1 < ny ? face[I][1] : 0.0f, Y > 0 ? face[I - sy][1] : 0.0f,
                                   Z + 1 < nz ? face[I][2] : 0.0f, Z > 0 ? face[I - sz][2] : 0.0f};
            for (int c = 0; c < 3; ++c) {
                float s = diagonal(I, albedo[c]) * in[I * 3 + std::size_t(c)];
                for (int k = 0; k < 6; ++k)
                    if (coef[k] > 0) s -= coef[k] * in[nbr[k] * 3 + std::size_t(c)];
                y[I * 3 + std::size_t(c)] = s;
            }
        }
    });
}

DiffusionMultigrid::DiffusionMultigrid(const DiffusionOperator& a) : a_(a) {
    levels_.push_back(coarsen(FineCells{a}));
    while (levels_.back().cells() > kCoarsestCells) {
        const Level& f = levels_.back();
        if (f.nx < 2 || f.ny < 2 || f.nz < 2) break;
        Level next = coarsen(DenseCells{f});
        levels_.push_back(std::move(next));
    }
}

void DiffusionMultigrid::cycle(std::size_t l, const RGB& albedo) const {
    const Level& L = levels_[l];
    if (l + 1 == levels_.size()) {
        for (int s = 0; s < kCoarsest; s += kSmooth) jacobi(L, L.cells(), albedo, L.rhs, L.sol, L.tmp, s == 0);
        return;
    }
    jacobi(L, L.cells(), albedo, L.rhs, L.sol, L.tmp, true);
    restrictResidual(L, DenseCells{L}, albedo, L.rhs, L.sol, L.tmp, &levels_[l + 1]);
    cycle(l + 1, albedo);
    prolongAdd(DenseCells{L}, levels_[l + 1], L.sol);
    jacobi(L, L.cells(), albedo, L.rhs, L.sol, L.tmp, false);
}

void DiffusionMultigrid::precondition(const std::vector<float>& r, const RGB& albedo, std::vector<float>& z,
                                      std::vector<float>& scratch) const {
    z.resize(r.size());
    scratch.resize(r.size());
    const bool tiles = a_.medium().sparse();
    jacobi(a_, a_.voxels(), albedo, r, z, scratch, true);
    restrictResidual(a_, FineCells{a_}, albedo, r, z, scratch, tiles ? nullptr : &levels_[0]);
    if (tiles) restrictFromTiles(a_, scratch, levels_[0]);
    cycle(0, albedo);
    if (tiles) prolongToTiles(a_, levels_[0], z);
    else prolongAdd(FineCells{a_}, levels_[0], z);
    jacobi(a_, a_.voxels(), albedo, r, z, scratch, false);
}

std::size_t DiffusionMultigrid::bytes() const {
    std::size_t b = 0;
    for (const Level& L : levels_) b += L.cells() * (sizeof(L.face[0]) + sizeof(float) + 9 * sizeof(float));
    return b;
}

}  // namespace lpm

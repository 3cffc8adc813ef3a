// A multigrid preconditioner for the diffusion tail's conjugate gradients
// (core/diffusion_tail.h; docs/multires.md, "Diffusion tail"). Jacobi alone needs about
// 1 / sqrt(condition) iterations, and the diffusion matrix's condition grows as the square
// of the medium's size in voxels where absorption is weak (albedo near 1): 80-90
// iterations to 1e-2 on the 1M smoke. A V-cycle removes the smooth error Jacobi leaves.
//
// Levels: the fine grid (the operator's stored voxels), then dense grids 2x coarser each,
// down to a few thousand cells (each 56 B a cell: 7 B a fine block voxel for the first). Each coarse cell aggregates
// the 2x2x2 cells below it that have medium (piecewise-constant prolongation P, restriction P^T: the sum), and its
// operator is the Galerkin product P^T A P, again a 7-point stencil: writing
// A_c = L + (1 - albedo_c) Sigma (L leakage, Sigma the extinction on the diagonal), the
// coarse Sigma sums its children's, a coarse face coefficient sums the fine faces between
// the two aggregates, and the coarse leakage sums its children's less twice each face
// inside it. So every level is symmetric positive definite with the fine one's albedos.
//
// One application z = M r is a symmetric V-cycle from zero: on each level kPreSmooth
// damped-Jacobi steps, the residual restricted, the coarser level's cycle prolonged and
// added, the same number of Jacobi steps after; the coarsest level takes kCoarsest steps.
// Jacobi is symmetric and the cycle's two halves mirror each other, so M is symmetric, as
// CG needs. The same result for any thread count (no sums across voxels).
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "core/diffusion_tail.h"

namespace lpm {

class DiffusionMultigrid {
public:
    explicit DiffusionMultigrid(const DiffusionOperator& a);

    /// z = M r on [stored voxel][rgb] vectors, per channel with A_c's albedo; `scratch` is
    /// overwritten (the CG lends its A p, which it needs again only after this).
    void precondition(const std::vector<float>& r, const RGB& albedo, std::vector<float>& z,
                      std::vector<float>& scratch) const;

    /// Levels below the fine grid.
    int coarseLevels() const { return int(levels_.size()); }
    /// Bytes held (coefficients, maps and scratch of every level).
    std::size_t bytes() const;

    /// One dense coarse level (public for the cycle's helpers in the .cpp).
    struct Level {
        int nx = 0, ny = 0, nz = 0;
        std::vector<std::array<float, 4>> face;    ///< +x, +y, +z coefficients, leakage (as the fine operator's)
        std::vector<float> sigma;                  ///< Sigma's diagonal: the children's extinction summed
        mutable std::vector<float> rhs, sol, tmp;  ///< right side, iterate, scratch ([cell][rgb])
        std::size_t cells() const { return sigma.size(); }
        std::size_t index(int x, int y, int z) const {
            return std::size_t(x) + std::size_t(nx) * (std::size_t(y) + std::size_t(ny) * std::size_t(z));
        }
        bool hasMedium(std::size_t i) const { return sigma[i] > 0; }
        float diagonal(std::size_t i, float albedo) const {
            return hasMedium(i) ? face[i][3] + sigma[i] * (1.0f - albedo) : 1.0f;
        }
        void apply(const std::vector<float>& in, const RGB& albedo, std::vector<float>& y) const;
    };
    /// The k-th level below the fine grid (0: the first).
    const Level& level(int k) const { return levels_[std::size_t(k)]; }

private:
    void cycle(std::size_t level, const RGB& albedo) const;  ///< levels_[level].sol from .rhs

    const DiffusionOperator& a_;
    std::vector<Level> levels_;
};

}  // namespace lpm

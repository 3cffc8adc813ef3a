// The diffusion operator of the two-grid cycle's diffusion tail (docs/performance.md,
// session 49: diffusion synthetic acceleration on the fine grid). With U the source a pass
// sweeps (emission sigma_s U) and J its mean radiance, one pass is K U = rho T U; diffusion
// stands in for T, so the sources a residual r gives rise to beyond itself are rho J with
//     (sigma_t (1 - rho) - div D grad) J = sigma_t r,    D = min(1 / (3 sigma_t), cap h)
// on the stored voxels with extinction: cell-centred finite volumes, the harmonic mean of D
// across a face between two such voxels, and a Marshak vacuum condition at a face to a
// voxel without extinction (or outside the block), which adds 2 D / (h (h + 4 D)) to the
// diagonal. The matrix is symmetric positive definite; it is solved by Jacobi-
// preconditioned conjugate gradients for the three channels at once. Voxels without
// extinction get J = 0. Cubic voxels (the solver's convention).
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "core/math.h"
#include "core/medium.h"

namespace lpm {

struct DiffusionSolve {
    std::vector<float> J;                    ///< [stored voxel][rgb]
    int iterations = 0;                      ///< CG iterations (all three channels together)
    std::array<double, 3> relativeResidual;  ///< |b - A J| / |b| per channel (L2), at the end
};

class DiffusionOperator {
public:
    /// `diffusionCap`: the largest D in voxel edges (thin voxels: D = 1 / (3 sigma_t) grows
    /// without bound, and with it the matrix's condition number).
    explicit DiffusionOperator(const Medium& m, double diffusionCap = 1.0);

    /// Solves A_c J_c = sigma_t b_c for each channel c (b [stored voxel][rgb], the means of
    /// the residual), A_c = sigma_t (1 - albedo_c) + leakage, until |residual| <= tolerance
    /// |sigma_t b| in every channel or maxIterations. The same result for any thread count.
    DiffusionSolve solve(const std::vector<float>& b, const RGB& albedo, double tolerance, int maxIterations) const;

    /// y = A_c x for one channel's albedo, on [stored voxel][rgb] vectors (tests).
    void apply(const std::vector<float>& x, const RGB& albedo, std::vector<float>& y) const;

    std::size_t voxels() const { return sigmaT_.size(); }

private:
    std::vector<float> sigmaT_;                     ///< extinction per stored voxel
    std::vector<std::array<std::int32_t, 6>> nbr_;  ///< neighbours with extinction, -1 for none
    std::vector<std::array<float, 6>> coef_;        ///< D_face / h^2 towards each of them
    std::vector<float> leak_;                       ///< the diagonal's leakage: faces and vacuum
};

}  // namespace lpm

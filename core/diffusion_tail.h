// The diffusion operator of the two-grid cycle's diffusion tail (docs/performance.md,
// session 49: diffusion synthetic acceleration on the fine grid). With U the source a pass
// sweeps (emission sigma_s U) and J its mean radiance, one pass is K U = rho T U; diffusion
// stands in for T, so the sources a residual r gives rise to beyond itself are rho J with
//     (sigma_t (1 - rho) - div D grad) J = sigma_t r,    D = clamp(1 / (3 sigma_tr), floor h, cap h)
// with sigma_tr = sigma_t (1 - rho g) the transport extinction (sigma_t where g = 0)
// on the stored voxels with extinction: cell-centred finite volumes, the harmonic mean of D
// across a face between two such voxels, and a Marshak vacuum condition at a face to a
// voxel without extinction (or outside the block), which adds 2 D / (h (h + 4 D)) to the
// diagonal. The matrix is symmetric positive definite; it is solved by conjugate
// gradients (multigrid-preconditioned, core/diffusion_multigrid.h) for the three channels
// at once. Voxels without extinction get J = 0. Cubic voxels (the solver's convention).
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "core/math.h"
#include "core/medium.h"

namespace lpm {

class DiffusionMultigrid;  // core/diffusion_multigrid.h

struct DiffusionSolve {
    std::vector<float> J;                    ///< [stored voxel][rgb]
    int iterations = 0;                      ///< CG iterations (all three channels together)
    std::array<double, 3> relativeResidual;  ///< |b - A J| / |b| per channel (L2), at the end
};

class DiffusionOperator {
public:
    /// `diffusionCap`: the largest D in voxel edges (thin voxels: D = 1 / (3 sigma_t) grows
    /// without bound, and with it the matrix's condition number). `diffusionFloor`: the
    /// smallest, in [0, diffusionCap] (thick voxels: the discrete transport carries light
    /// from voxel to voxel faster than 1 / (3 sigma_t) says; docs/multires.md, "Diffusion
    /// tail"). `transportFactor`: sigma_tr / sigma_t = 1 - rho g, rho the channels' mean
    /// albedo (1 for g = 0). Keeps a reference to `m`.
    explicit DiffusionOperator(const Medium& m, double diffusionCap = 1.0, double diffusionFloor = 0.0,
                               double transportFactor = 1.0);

    /// Solves A_c J_c = sigma_t b_c for each channel c (b_c of voxel v at b[v * stride + c],
    /// the means of the residual), A_c = sigma_t (1 - albedo_c) + leakage, until |residual|
    /// <= tolerance |sigma_t b| in every channel or maxIterations. The same result for any
    /// thread count. Holds four [voxel][rgb] vectors (J among them) while it runs.
    /// `multigrid` (built on this operator) preconditions; Jacobi without it.
    DiffusionSolve solve(const float* b, std::size_t stride, const RGB& albedo, double tolerance, int maxIterations,
                         const DiffusionMultigrid* multigrid = nullptr) const;
    /// The same with b [stored voxel][rgb].
    DiffusionSolve solve(const std::vector<float>& b, const RGB& albedo, double tolerance, int maxIterations,
                         const DiffusionMultigrid* multigrid = nullptr) const;

    /// y = A_c x for one channel's albedo, on [stored voxel][rgb] vectors.
    void apply(const std::vector<float>& x, const RGB& albedo, std::vector<float>& y) const;

    std::size_t voxels() const { return face_.size(); }
    const Medium& medium() const { return m_; }
    /// Whether stored voxel v has extinction (its row is the identity otherwise).
    bool hasMedium(std::size_t v) const { return face_[v][3] > 0; }
    /// Its coefficients towards +x, +y, +z and its leakage (see face_).
    const std::array<float, 4>& faces(std::size_t v) const { return face_[v]; }
    /// A_c's diagonal: leakage and absorption (1 for a voxel without extinction).
    float diagonal(std::size_t v, float albedo) const {
        return hasMedium(v) ? face_[v][3] + m_.sigmaT[v] * (1.0f - albedo) : 1.0f;
    }

private:
    /// Stored voxel `v`'s neighbours on sides +x, -x, +y, -y, +z, -z, Medium::npos where not
    /// stored (outside the block or in an unallocated tile).
    inline __attribute__((always_inline)) void neighbours(std::size_t v, std::size_t (&nbr)[6]) const;
    void linkTiles();  ///< tileNeighbour_

    const Medium& m_;
    /// Per stored voxel: D_face / h^2 towards its +x, +y, +z neighbour (0 where either has no
    /// extinction: the face then leaks through the Marshak term), and the diagonal's leakage
    /// (every face's coefficient or Marshak term; 0 marks a voxel without extinction).
    /// 16 bytes a voxel: the operator is applied from these and the medium's sigma_t.
    std::vector<std::array<float, 4>> face_;
    /// Sparse media: per tile slot, the slot of the tile on each side, -1 where none.
    std::vector<std::array<std::int32_t, 6>> tileNeighbour_;
};

}  // namespace lpm

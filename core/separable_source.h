// Separable fine-grid sources of the two-grid solve (docs/multires.md, "Separable fine
// sources"). An anisotropic unshot source U_f(d) (fine voxel f, unshot bin d, RGB) held in
// full costs bins x 12 B per voxel (24 bins: 288 B), the largest buffer of an anisotropic
// bake. Held separably, each fine voxel keeps only its angular integral per channel and
// its coarse parent C the angular shape:
//     m_f = sum_d w_d U_f(d)                                   [fine voxel][rgb]
//     R_C(d) = sum_f sigma_f U_f(d) / sum_f sigma_f             [coarse voxel][bin][rgb]
//     U_f(d) ~= R_C(d) + (m_f - |R_C|) S_C(d) + P_C(d) + t_f,   |R_C| = sum_d w_d R_C(d)
// with S_C(d) = |R_C(d)| / sum_d w_d |R_C(d)| the parent's angular shape (isotropic where
// R_C = 0): where R_C has one sign in every bin this is m_f R_C(d) / |R_C|, and it stays
// linear in m_f where it has not (the two-grid cycle's residuals change sign; a division
// by |R_C| there lost their sources and stalled the cycle at albedo 0.99).
// P_C is a piecewise-constant part (the two-grid cycle's coarse tail), held as a
// half-precision buffer (core/half_buffer.h); t_f an isotropic part of each fine voxel,
// the same in every bin (the diffusion tail, core/diffusion_cycle.cpp), added to U_f(d). R_C is held in half precision
// too, |R_C| and S_C taken from the rounded values. Exact: every fine voxel's angular
// integral. To within R_C's rounding (2^-11): the sigma-weighted restriction (so the
// source power of every coarse voxel in every bin). Approximate: how the angular shape
// varies among the 8 children of a coarse voxel.
#pragma once

#include <cstdint>
#include <vector>

#include "core/bf16.h"
#include "core/half_buffer.h"
#include "core/mass_rows.h"
#include "core/medium.h"

namespace lpm {

struct Job;

/// Fine voxels and their coarse parents (the coarse medium of core/multires.h: voxels
/// twice as large, fine voxel (x, y, z) the child of coarse voxel (x/2, y/2, z/2)), by the
/// coarse voxels' rows with mass (core/mass_rows.h): every coarse-sized buffer of a
/// separable source, and of the coarse solve it hands to, holds those rows only.
struct FineCoarseMap {
    static constexpr std::uint32_t kNone = ~std::uint32_t(0);
    MassRows coarseRows;  ///< the coarse medium's voxels with mass
    /// [fine voxel] its parent's row; kNone outside the block and under a parent without
    /// mass (such a voxel's sigma_t is 0, or so small that its parent's, the mean over 8
    /// children, rounds to 0 in float: the children's sum below 6e-45)
    std::vector<std::uint32_t> parent;
    std::vector<std::uint32_t> children;  ///< [row][8] its fine voxels, kNone where absent
    std::vector<float> sigmaSum;          ///< [row] sum of its children's sigma_t
    /// Fine voxels [k groupSize, (k + 1) groupSize) have parents no other group has: a fine
    /// tile when the fine medium is sparse, else two z-slices.
    size_t groupSize = 1;
    FineCoarseMap(const Medium& fine, const Medium& coarse);
    size_t rows() const { return coarseRows.size(); }
};

/// A fine-grid source held separably (see the file comment), its coarse buffers by the
/// map's rows (FineCoarseMap). The half-precision buffers are held bin-major,
/// [bin][row][rgb], so filling one bin (fillBin, 24 times a pass) reads 6 contiguous bytes
/// per coarse row instead of one per 144-byte row.
struct SeparableSource {
    int bins = 0;
    size_t coarseRows = 0;         ///< FineCoarseMap::rows()
    std::vector<float> magnitude;  ///< m_f [fine voxel][rgb] (0 under a parent without mass)
    HalfBuffer shape;              ///< R_C [bin][row][rgb], in half precision
    std::vector<float> norm;       ///< |R_C| [row][rgb] (signed)
    std::vector<float> invAbs;     ///< 1 / sum_d w_d |R_C(d)| [row][rgb], 0 where R_C = 0
    float invWeight = 0;           ///< 1 / sum_d w_d: the isotropic shape
    /// P_C [bin][row][rgb], the sum of these parts (none: 0). Their sum is formed
    /// where it is read (fillBin, power, restricted), never as a coarse buffer of floats.
    std::vector<HalfBuffer> offset;
    /// t_f [fine voxel][rgb]: added to every bin of fine voxel f (empty: none; 0 under a
    /// parent without mass). Its integral is W t_f, W = sum_d w_d = 1 / invWeight.
    std::vector<float> isotropic;

    /// x [row][bin][rgb] in half precision, held bin-major (as shape and offset).
    static HalfBuffer holdByBin(const std::vector<float>& x, int bins);
    /// Where (row, bin, channel) lies in shape and offset.
    size_t heldIndex(size_t row, size_t bin, size_t c) const { return (bin * coarseRows + row) * 3 + c; }
    /// The source restricted to the coarse grid, R_C + P_C [row][bin][rgb] (what
    /// restrictSource gives for the full source, at the rows).
    std::vector<float> restricted() const;
    /// P_C at held index h (heldIndex).
    float offsetAt(size_t h) const;
    /// out [fine voxel][rgb] = U_f(bin), 0 for voxels outside the block; T is float or Bf16
    /// (core/bf16.h: each value rounded as it is stored).
    template <class T>
    void fillBin(const FineCoarseMap& map, int bin, T* out) const;
    /// Source power sum_f sigma_s U_f(d) w_d V, mean over RGB (as LpmSolve::sourcePower).
    double power(const FineCoarseMap& map, const std::vector<double>& binWeight, const RGB& albedo,
                 double fineVoxelVolume) const;
    /// The same sum with each fine voxel's angular integral taken by its absolute value,
    /// sum_f sigma_s |m_f| V (mean over RGB): what a signed sum hides where the source
    /// changes sign between voxels (a two-grid residual). For a source without offset or
    /// isotropic part.
    double absolutePower(const std::vector<float>& sigmaT, const RGB& albedo, double fineVoxelVolume) const;
};

/// Folds a pass's per-direction deposits into the SH result and a separable next source:
/// the fold of core/pass_runner.cpp with a voxel's bin row reduced, as it is formed, to
/// its angular integral and its parent's sigma-weighted sum. Parallel over coarse voxels,
/// each taking its children in a fixed order: sums do not depend on the thread count.
class SeparableFold {
public:
    SeparableFold(const FineCoarseMap& map, const std::vector<float>& sigmaT, const std::vector<double>& binWeight,
                  int shCoeffs, const std::uint32_t* shRow = nullptr);
    /// Deposits phi[j] [fine voxel][rgb] of jobs[0..n), in job order; T is float or Bf16
    /// (core/bf16.h), each value widened to float as it is read.
    template <class T>
    void fold(bool depositSh, const Job* jobs, size_t n, const std::vector<std::vector<T>>& phi,
              std::vector<float>& sh);
    /// The folded source (R_C normalised by the children's sigma sums). Leaves the fold empty.
    /// With `minus` (P_C [bin][row][rgb], held as SeparableSource::offset): the folded source
    /// less that piecewise-constant part, taken from R_C before it is rounded and its
    /// angular integral |P_C| from every child's m_f, so the result holds no offset (the
    /// restriction and every fine voxel's integral stay exact; the shape of m_f - |R_C|
    /// becomes that of R_C - P_C). With `minusIsotropic` (t_f [fine voxel][rgb], held as
    /// SeparableSource::isotropic): the folded source less that isotropic part, taken from
    /// every bin of R_C by its children's sigma-weighted mean and from m_f by W t_f.
    SeparableSource finish(const HalfBuffer* minus = nullptr, const std::vector<float>* minusIsotropic = nullptr);

private:
    /// m_f -= |part| of f's parent ([bin][row][rgb] held by bin), for every fine voxel.
    void takeIntegralFromChildren(const HalfBuffer& part);
    /// R_C(d) -= the children's sigma-weighted mean of t (every bin), before R_C is rounded.
    void takeIsotropicFromShape(const std::vector<float>& t);

    const FineCoarseMap& map_;
    const std::vector<float>& sigmaT_;
    std::vector<float> binWeight_;
    int nb_, nc_;
    const std::uint32_t* shRow_;  ///< fine voxel -> SH row (core/sh_rows.h); null: the identity
    SeparableSource out_;
    std::vector<float> shapeSum_;  ///< sum_f sigma_f U_f(d) [row][bin][rgb] until finish()
    std::vector<float> psi_;       ///< [row][job][rgb]: a batch's sum_f sigma_f phi_j(f), 0 between batches
};

}  // namespace lpm

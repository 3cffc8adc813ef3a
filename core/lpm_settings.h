// The solver's knobs (core/lpm_solver.h) and their valid ranges. What each auto value
// (-1) turns into for a given scene is decided by the effect planner (core/solve_plan.h).
#pragma once

#include <cstddef>
#include <functional>
#include <memory>
#include <string>

namespace lpm {

class LpmCache;

/// Range limits of the settings (validate(); the CLI's help quotes them).
constexpr int kMaxDirectionsPerFace = 64;
constexpr int kMaxRaysPerVoxel = 16;
constexpr int kMaxSubdivide = 8;

struct LpmSettings {
    int directionsPerFace = 4;  ///< n: n x n propagation directions per cube face (6 n^2 in all)
    int raysPerVoxel = 2;       ///< ray-map rays per voxel along each lateral axis (r^2 per voxel face)
    int raysHigherOrders = -1;  ///< rays per voxel of the passes after the first (multiple scattering):
                                ///< -1 auto (1 when the two-grid solve runs, else raysPerVoxel), or 1..16
    int binsPerFace = -1;       ///< unshot bins: -1 auto (1 isotropic bin when g == 0, else 2x2 per face
                                ///< when n is even, n x n for n = 1 or 3, else 1 per face); must divide n;
                                ///< 0 = one isotropic bin, b = b x b per face
    int shOrder = 2;            ///< SH order of the result, 0..3 (forced to 0 when g == 0)
    double tolerance = 1e-3;    ///< stop when the estimated scattered power still to come / injected < tolerance
    int maxOrders = 1000;       ///< hard cap on propagation passes
    bool krylov = true;         ///< allow GMRES acceleration when source iteration would be slow
    int krylovAfter = 25;       ///< switch when plain iteration would need more than this many passes
    int coarseKrylovAfter = 8;  ///< the same on the multi-resolution coarse grid (its passes are cheap)
    int krylovRestart = 40;     ///< GMRES restart length (capped by krylovBytes, down to 3)
    /// Memory GMRES's Krylov vectors may take, in half precision. The plan caps it further:
    /// at full resolution by the memory line (core/solve_plan.cpp, 4 vectors at least); the
    /// two-grid solve gives its coarse grid 40 B per fine stored voxel (core/two_grid.cpp).
    double krylovBytes = double(std::size_t(2) << 30);
    bool coarseTailExtrapolation = true;  ///< the two-grid coarse solve stops early where its passes decay
                                          ///< geometrically and adds the rest as that series
                                          ///< (docs/multires.md, "Geometric tail"); so does a
                                          ///< solve on one grid, within a tenth of the tolerance
    int shapedCoarseTail = -1;            ///< the two-grid cycle's tail inside each coarse voxel: -1 auto (shaped
                                          ///< when coarse voxels may be optically thicker than shapedTailAbove and
                                          ///< the fine sources are not separable), 0 flat, 1 shaped by the first
                                          ///< residual the children hold (core/tail_shape.h)
    double shapedTailAbove = 1.0;         ///< auto threshold: twice the largest fine voxel's optical depth
    int diffusionTail = -1;               ///< the two-grid cycle's tail from a diffusion solve on the fine grid
                                          ///< instead of the coarse grid's transport (core/diffusion_tail.h;
                                          ///< docs/multires.md "Diffusion tail"): -1 auto (albedo up to at least
                                          ///< diffusionTailAlbedo, and fine voxels up to optical depth at least
                                          ///< diffusionTailTau or a medium at least diffusionTailSize across),
                                          ///< 0 off, 1 on; one unshot bin or separable sources
    double diffusionTailAlbedo = 0.97;    ///< auto threshold: the largest channel's albedo
    double diffusionTailTau = 2.0;        ///< auto threshold: the largest fine voxel's optical depth
    double diffusionTailSize = 60.0;      ///< auto threshold: the optical size of the medium's thickest region
                                          ///< (core/optical_size.h)
    int cycleSmoothing = 1;               ///< source-iteration passes of each two-grid cycle's residual before
                                          ///< the next coarse solve (docs/multires.md, "Smoothing"); 0 = none
    /// Set by the two-grid cycle for its coarse solves with a shaped tail: each pass's source
    /// is measured by its absolute power (the residual they distribute changes sign between
    /// voxels, and a signed sum would end them after a pass; docs/multires.md, "Shaped tail").
    bool absoluteSourcePower = false;
    /// Set by the two-grid cycle for its coarse solves: the share of the input within which
    /// a geometric tail's estimated error must stay (0: the tolerance). The cycle stops its
    /// coarse solves at a tenth of their input, but a series extrapolated from there must
    /// still be as good as the bake's tolerance asks (docs/multires.md, "Geometric tail").
    double extrapolationTolerance = 0;
    int linearSource = -1;              ///< -1 auto (on when a voxel is optically thicker than
                                        ///< linearSourceAbove, or see linearSourceDiffusive), 0 voxel-constant
                                        ///< (step) source, 1 linear source
                                        ///< inside each voxel (linear characteristics; 4x the unshot memory)
    double linearSourceAbove = 2.0;     ///< auto threshold: largest per-voxel optical depth
    double linearSourceDiffusive = 12;  ///< auto threshold (albedo >= diffusionTailAlbedo, one unshot bin): the
                                        ///< largest per-voxel optical depth times the
                                        ///< medium's optical size in diffusion lengths, T sqrt(3 (1 - albedo))
    double linearSourceVoxelCap = 8.0;  ///< voxels optically thicker than this keep a constant source
    int deltaM = -1;                    ///< forward-peak truncation (delta-M, f = g^4): -1 auto (on when
                                        ///< g > deltaMAbove and the albedo is grey), 0 off, 1 on (g > 0, grey albedo)
    double deltaMAbove = 0.0;           ///< auto threshold on g (measured better for g = 0.5, 0.85, 0.9, 0.99)
    double envHotShare = 0.01;          ///< environment pixels holding at least this share of its power
                                        ///< (at most 16) are swept like suns, in their exact direction; 0 = off
    int multires = -1;                  ///< higher orders on a 2x coarser grid: -1 auto (when the block stores
                                        ///< at least multiresMinVoxels voxels), 0 off, 1 on
    int multiresAfter = 1;              ///< passes at full resolution before the coarse grid takes over (>= 1)
    int multiresMinVoxels = 32769;      ///< auto threshold on stored voxels: more than 32^3 (the MC
                                        ///< comparison set keeps measuring full resolution)
    int multiresDirections = -1;        ///< directions per face on the coarse grid: -1 auto (n/2 when the
                                        ///< bins still divide it and it is >= 2, else n)
    int separableSource = -1;           ///< fine-grid sources of the two-grid solve held separably (each
                                        ///< voxel's angular integral, its coarse parent's angular shape;
                                        ///< core/separable_source.h): -1 auto (with unshot bins), 0 off, 1 on
    int subdivide = 1;                  ///< solve on voxels split k x k x k (same medium), average back: for
                                        ///< optically thick voxels, where a voxel-constant source leaks light
    std::function<void(const std::string&)> progress;  ///< optional, called once per pass
    /// Also return each sun's beam transmittance (LpmResult::sunTerms) so its single
    /// scattering can be stored exactly beside the SH (core/sun_term.h); res.sh is unchanged.
    bool sunTerms = false;
    /// Return a directional SH result held by the written voxels' rows (LpmResult::shRow,
    /// core/sh_rows.h) instead of one row per stored voxel: for a caller that reads it
    /// through shRow (the bake's writer) or expands it (LpmResult::expandSh) when it must.
    bool keepShRows = false;
    /// Optional: precomputations shared between solves (the frames of a sequence); the
    /// results are the same without it.
    std::shared_ptr<LpmCache> cache;

    /// Throws lpm::Error naming the setting and the offending value when one is out of its
    /// range: the one home of the range rules (the CLI maps the errors to its flag names).
    void validate() const;
};

}  // namespace lpm

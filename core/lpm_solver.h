// Light Propagation Maps (Fattal 2009): a discrete-ordinates solver for the RTE on a
// voxel grid, by source iteration over scattering orders. See docs/lpm_solver.md for
// the equations, conventions and the energy bookkeeping.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "core/medium.h"
#include "core/sh.h"
#include "core/sun_term.h"

namespace lpm {

class LpmCache;

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
    int krylovRestart = 40;     ///< GMRES restart length (capped by a 2 GiB budget for Krylov vectors)
    int linearSource = -1;      ///< -1 auto (on when a voxel is optically thicker than
                                ///< linearSourceAbove), 0 voxel-constant (step) source, 1 linear source
                                ///< inside each voxel (linear characteristics; 4x the unshot memory)
    double linearSourceAbove = 2.0;  ///< auto threshold: largest per-voxel optical depth
    double linearSourceVoxelCap = 8.0;  ///< voxels optically thicker than this keep a constant source
    int deltaM = -1;            ///< forward-peak truncation (delta-M, f = g^4): -1 auto (on when
                                ///< g > deltaMAbove and the albedo is grey), 0 off, 1 on (g > 0, grey albedo)
    double deltaMAbove = 0.0;   ///< auto threshold on g (measured better for g = 0.5, 0.85, 0.9, 0.99)
    double envHotShare = 0.01;  ///< environment pixels holding at least this share of its power
                                ///< (at most 16) are swept like suns, in their exact direction; 0 = off
    int multires = -1;          ///< higher orders on a 2x coarser grid: -1 auto (when the block stores
                                ///< at least multiresMinVoxels voxels), 0 off, 1 on
    int multiresAfter = 1;      ///< passes at full resolution before the coarse grid takes over (>= 1)
    int multiresMinVoxels = 1 << 16;  ///< auto threshold on stored voxels (2 x 32^3)
    int multiresDirections = -1;  ///< directions per face on the coarse grid: -1 auto (n/2 when the
                                  ///< bins still divide it and it is >= 2, else n)
    int subdivide = 1;          ///< solve on voxels split k x k x k (same medium), average back: for
                                ///< optically thick voxels, where a voxel-constant source leaks light
    std::function<void(const std::string&)> progress;  ///< optional, called once per pass
    /// Also return each sun's beam transmittance (LpmResult::sunTerms) so its single
    /// scattering can be stored exactly beside the SH (core/sun_term.h); res.sh is unchanged.
    bool sunTerms = false;
    /// Optional: precomputations shared between solves (the frames of a sequence); the
    /// results are the same without it.
    std::shared_ptr<LpmCache> cache;
};

struct PassStats {
    int pass = 0;            ///< 0 = external light (scattered power = single scattering)
    double injected = 0;     ///< power entering this pass (boundary + sources), mean over RGB
    double absorbed = 0;
    double escaped = 0;
    double scattered = 0;    ///< power scattered in this pass: the next pass's source
    double seconds = 0;
    bool krylov = false;     ///< a GMRES matrix-vector pass (not a physical scattering order)
    bool coarse = false;     ///< solved on the multi-resolution coarse grid
};

struct LpmResult {
    int shOrder = 0;  ///< effective SH order of `sh`
    int coeffs = 1;   ///< (shOrder + 1)^2
    std::vector<float> sh;  ///< [voxel][coeff][rgb] SH coefficients of S(x, w)
    std::vector<PassStats> passes;
    double injected = 0;   ///< external power (environment, suns, emission), mean over RGB
    double absorbed = 0;   ///< summed over passes
    double escaped = 0;    ///< summed over passes
    double unshot = 0;     ///< scattered power of the last pass, not propagated further
    double residual = 0;   ///< unshot / injected
    bool converged = false;
    int directionCount = 0, binCount = 0;
    std::uint64_t segments = 0;  ///< ray-segment updates performed
    double seconds = 0;
    std::vector<std::string> decisions;  ///< what the solver decided and why
    /// With LpmSettings::sunTerms: every sun swept (the lights' suns, then the environment's
    /// hot pixels), with its transmittance; res.sh includes their single scattering.
    std::vector<SunTerm> sunTerms;
    /// Coarse continuation only (internal to multi-resolution): every source the passes
    /// propagated, plus the unshot remainder, [voxel][bin][rgb].
    std::vector<float> sourceSum;

    RGB coeff(size_t voxel, int k) const {
        const float* p = &sh[(voxel * coeffs + k) * 3];
        return {p[0], p[1], p[2]};
    }
};

/// Solves for the SH coefficients of the phase-weighted in-scattered radiance
/// S(x, w) = Int p(w, w') L(x, w') dw' (w = travel direction) in every voxel.
/// Throws lpm::Error on invalid input. Results are bit-identical for any thread count.
LpmResult solveLpm(const Medium& medium, const Lights& lights, const LpmSettings& settings);

}  // namespace lpm

// Light Propagation Maps (Fattal 2009): a discrete-ordinates solver for the RTE on a
// voxel grid, by source iteration over scattering orders. See docs/lpm_solver.md for
// the equations, conventions and the energy bookkeeping.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "core/lpm_settings.h"
#include "core/medium.h"
#include "core/sh.h"
#include "core/solve_plan.h"
#include "core/sun_term.h"

namespace lpm {

struct PassStats {
    int pass = 0;         ///< 0 = external light (scattered power = single scattering)
    double injected = 0;  ///< power entering this pass (boundary + sources), mean over RGB
    double absorbed = 0;
    double escaped = 0;
    double scattered = 0;  ///< power scattered in this pass: the next pass's source
    double seconds = 0;
    bool krylov = false;         ///< a GMRES matrix-vector pass (not a physical scattering order)
    bool coarse = false;         ///< solved on the multi-resolution coarse grid
    std::uint64_t segments = 0;  ///< ray-segment updates of this pass
};

struct LpmResult {
    int shOrder = 0;        ///< effective SH order of `sh`
    int coeffs = 1;         ///< (shOrder + 1)^2
    std::vector<float> sh;  ///< [row][coeff][rgb] SH coefficients of S(x, w), row below
    /// Stored voxel v's row of sh: shRow[v] (ShRows::kNone: none, S = 0 there) when the
    /// solve ran with LpmSettings::keepShRows and kept rows only for the voxels written;
    /// empty: row = voxel.
    std::vector<std::uint32_t> shRow;
    std::vector<PassStats> passes;
    double injected = 0;  ///< external power (environment, suns, emission), mean over RGB
    /// The tolerance's reference, "the input": the volume's own light budget, the power it
    /// takes from the light in pass 0 (absorbed + scattered) plus the power it emits, mean
    /// over RGB; a coarse continuation's, its initial source's power. Not `injected`, which
    /// counts every ray entering the block: light that crosses empty space around a medium
    /// would loosen the stop test by the block's size (docs/lpm_solver.md, "The stop
    /// test's reference").
    double input = 0;
    double absorbed = 0;  ///< summed over passes
    double escaped = 0;   ///< summed over passes
    double unshot = 0;    ///< scattered power of the last pass, not propagated further
    double residual = 0;  ///< unshot / input
    /// Two-grid cycles that also test their residual's absolute power (the shaped and the
    /// diffusion tails, core/two_grid.cpp kAbsoluteGuard): that power / input at the stop,
    /// and the line it had to meet (a multiple of the tolerance); both 0 otherwise. A bake
    /// can stop at its cycle cap with `residual` within the tolerance and this above it.
    double absoluteResidual = 0;
    double absoluteLine = 0;
    bool converged = false;
    /// Not converged because the two-grid solve ran its cycles out (core/two_grid.cpp),
    /// not because of LpmSettings::maxOrders: more orders would not help.
    bool stoppedAtCycleCap = false;
    int directionCount = 0, binCount = 0;
    std::uint64_t segments = 0;  ///< ray-segment updates performed
    double seconds = 0;
    std::vector<std::string> decisions;  ///< the plan's decisions and why, then what the solve met while running
    SolvePlan plan;                      ///< the effect planner's plan this solve carried out
    double sunTermSeconds = 0;           ///< time of the exact sun term's extra sweeps
    /// With LpmSettings::sunTerms: every sun swept (the lights' suns, then the environment's
    /// hot pixels), with its transmittance; res.sh includes their single scattering.
    std::vector<SunTerm> sunTerms;
    /// Coarse continuation only (internal to multi-resolution): every source the passes
    /// propagated beyond the initial one, plus the unshot remainder, [voxel][bin][rgb].
    std::vector<float> sourceSum;

    /// Voxel v's row of sh, or null where none is held (S = 0).
    const float* shAt(size_t voxel) const;
    RGB coeff(size_t voxel, int k) const {
        const float* p = shAt(voxel);
        if (!p) return RGB(0.0f);
        return {p[k * 3], p[k * 3 + 1], p[k * 3 + 2]};
    }
    /// Turns sh into one row per stored voxel (shRow emptied); nothing when it is already.
    void expandSh();
};

/// What solveLpm will do for these inputs (core/solve_plan.h), without solving: for
/// printing the plan first. Throws lpm::Error on invalid settings.
SolvePlan planLpm(const Medium& medium, const Lights& lights, const LpmSettings& settings);

/// Solves for the SH coefficients of the phase-weighted in-scattered radiance
/// S(x, w) = Int p(w, w') L(x, w') dw' (w = travel direction) in every voxel.
/// Throws lpm::Error on invalid input. Results are bit-identical for any thread count.
LpmResult solveLpm(const Medium& medium, const Lights& lights, const LpmSettings& settings);

}  // namespace lpm

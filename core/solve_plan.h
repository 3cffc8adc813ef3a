// The effect planner: one pure function that decides, from what the scene holds and the
// settings, what a solve does (which light passes run, the resolution schedule of the
// scattering orders, SH order, unshot bins, source shape, delta-M, acceleration), and
// says why, with each decision's predicted cost. The solver only carries the plan out;
// what it decides while running (the GMRES switch, clamps, convergence) it reports as
// events beside the plan. Design note: docs/solve_plan.md.
#pragma once

#include <cstddef>
#include <limits>
#include <string>
#include <vector>

#include "core/lpm_settings.h"
#include "core/math.h"

namespace lpm {

struct Medium;
struct Lights;
struct EnvBinning;

/// What the planner looks at: statistics of the medium and the lights, no voxel data.
struct SceneSummary {
    int dims[3] = {0, 0, 0};    ///< block dimensions in voxels
    size_t storedVoxels = 0;    ///< voxels the solve allocates (allocated tiles only)
    size_t wantedVoxels = 0;    ///< voxels whose S the caller reads (Medium::wantedS; all stored when unset)
    double maxVoxelTau = 0;     ///< largest sigma_t times the longest voxel edge
    double opticalSize = 0;     ///< optical size of the thickest region (core/optical_size.h)
    double g = 0;               ///< Henyey-Greenstein asymmetry of the medium
    RGB albedo;                 ///< single-scattering albedo
    bool emission = false;      ///< an emission grid feeds a source
    bool environment = false;   ///< an environment with non-zero power
    int suns = 0;               ///< explicit suns that carry light
    int hotPixels = 0;          ///< environment hot spots swept as suns (core/env_binning.h)
    double hotShare = 0;        ///< their share of the environment's power
    bool continuation = false;  ///< the coarse grid of a two-grid solve: no external light
};

/// Reads the summary off a medium and its lights. `binned` is the environment's binning
/// (null without an environment): it says how many hot spots are swept as suns.
SceneSummary summarizeScene(const Medium& m, const Lights& lights, const EnvBinning* binned, bool continuation);

/// One decision: what the solve does, why, and what it is predicted to cost.
struct PlanDecision {
    std::string what;                  ///< e.g. "SH order 0"
    std::string why;                   ///< e.g. "the phase function is isotropic (g = 0), ..."
    double predictedSeconds = -1;      ///< < 0: no time of its own
    double predictedBytes = -1;        ///< < 0: no memory of its own
    std::string text() const;          ///< "what: why" (the same for any thread count: it goes into the bake)
    std::string textWithCost() const;  ///< text() plus the predicted cost, for -v
};

struct SolvePlan {
    int subdivide = 1;             ///< solve on voxels split k x k x k, average back
    bool deltaM = false;           ///< forward-peak truncation (core/delta_m.h)
    double deltaMFraction = 0;     ///< f = g^4 when deltaM
    double gPropagation = 0;       ///< g the propagation's unshot bins see (g' under delta-M)
    double gOut = 0;               ///< g of the phase function that S is defined with
    int shOrder = 0;               ///< SH order of the result
    int binsPerFace = 0;           ///< unshot bins: 0 one isotropic bin, b = b x b per face
    bool linearSource = false;     ///< linear source inside voxels (4 moments per bin)
    bool environmentPass = false;  ///< pass 0 sweeps the environment through the boundary
    bool emissionPass = false;     ///< pass 0 sweeps the emission source
    int sunPasses = 0;             ///< explicit suns swept in pass 0
    int hotPixelPasses = 0;        ///< environment hot spots swept as suns in pass 0
    int coarseFrom = 0;            ///< first order on the 2x coarser grid; 0 = full resolution throughout
    int coarseDirectionsPerFace = 0;
    bool separableSource = false;  ///< fine sources held separably (core/separable_source.h)
    bool shapedTail = false;       ///< the two-grid tail shaped inside coarse voxels (core/tail_shape.h)
    bool diffusionTail = false;    ///< the cycle's tail from a fine-grid diffusion solve (core/diffusion_tail.h)
    int raysSingle = 2;            ///< rays per voxel of pass 0 (single scattering)
    int raysHigher = 2;            ///< rays per voxel of the later passes
    bool krylov = true;            ///< GMRES may take over when plain iteration would be slow
    int krylovAfter = 25;          ///< switch when plain iteration predicts more passes than this
    /// GMRES's Krylov basis at most, in bytes (the solver keeps 3 vectors at least)
    double krylovBytes = std::numeric_limits<double>::infinity();
    double predictedSegmentsPerFinePass = 0;  ///< ray-segment updates of one full-resolution pass
    double predictedSecondsPerFinePass = 0;   ///< at the planner's throughput estimate
    double predictedBytes = 0;                ///< the solve's main buffers
    std::vector<PlanDecision> decisions;

    /// One line per decision (text(), or textWithCost()).
    std::vector<std::string> lines(bool withCost = false) const;
};

/// Ray-segment updates per second and thread that the planner's time predictions assume,
/// per kind of pass: the batched sweeps of the isotropic fold, per-direction sweeps with
/// the general fold (bins and SH), and the same two with the linear source. Measured on this
/// project's 2-core reference machine (docs/solve_plan.md); the stats JSON gives the
/// measured time of the first fine pass beside the prediction.
constexpr double kPlannedRateBatched = 2.5e8;
constexpr double kPlannedRateGeneralFold = 5.0e7;
constexpr double kPlannedRateLinearBatched = 1.4e8;
constexpr double kPlannedRateLinearSource = 1.0e7;

/// The plan for `scene` under `s` (s must be valid: LpmSettings::validate). Pure: the
/// same inputs give the same plan. `threads` only scales the predicted seconds.
SolvePlan planSolve(const SceneSummary& scene, const LpmSettings& s, int threads);

}  // namespace lpm

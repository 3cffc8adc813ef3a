// One LPM solve carried out (internal to core/lpm_solver.cpp and core/two_grid.cpp): the
// plan's passes in order. Pass 0 sweeps the external light (or, on the coarse grid of a
// two-grid solve, the restricted source); the passes after it propagate what the last one
// scattered (source iteration), until the tail falls below the tolerance, the coarse grid
// takes over (docs/multires.md), or GMRES does (core/gmres.h).
#pragma once

#include <chrono>
#include <memory>
#include <vector>

#include "core/gmres.h"
#include "core/half_buffer.h"
#include "core/job_factory.h"
#include "core/lpm_cache.h"
#include "core/lpm_solver.h"
#include "core/mass_rows.h"
#include "core/pass_runner.h"
#include "core/quadrature.h"
#include "core/separable_source.h"
#include "core/sh_rows.h"
#include "core/solve_plan.h"

namespace lpm {

class LpmSolve {
public:
    /// `initialSource`: null for the external-light problem; for the coarse continuation of
    /// a two-grid solve, the restricted unshot [voxel][bin][rgb] that replaces pass 0 (taken
    /// over: with a voxel-constant source it becomes the first source without a copy); such
    /// a solve returns its source sum and no SH result (`sh` stays empty).
    /// `shRows` (outlives the solve; null: one row per voxel): where the SH result holds
    /// each voxel's row; run() returns it so, and the caller expands it (core/sh_rows.h).
    /// `sourceRows` (a coarse continuation's, outlives the solve; m's voxels with mass,
    /// core/mass_rows.h): the initial source and the source sum are held by these rows,
    /// [row][bin][rgb], and so is every source the solve propagates.
    LpmSolve(const Medium& m, const Lights& lights, const LpmSettings& s, const SolvePlan& plan,
             std::shared_ptr<LpmCache> cache, std::vector<float>* initialSource, const ShRows* shRows = nullptr,
             const MassRows* sourceRows = nullptr);
    LpmResult run();

private:
    using Clock = std::chrono::steady_clock;
    void passZero();
    void startFromSource();
    bool iterate();  ///< source iteration; true when GMRES is to take over
    // The two-grid continuation (core/two_grid.cpp).
    struct TwoGridCount {
        int coarsePasses = 0;
        bool converged = true;
    };
    /// A cycle's residual r' = K E - tail: its signed power (the stop test, as every pass's)
    /// and its absolute power (the next coarse solve's tolerance; reported beside it).
    struct Residual {
        double power = 0, absolute = 0;
    };
    void continueOnCoarse(int firstPass);
    void continueOnCoarseSeparable(int firstPass);
    void continueWithDiffusion(int firstPass);  ///< core/diffusion_cycle.cpp
    void continueWithDiffusionSeparable(int firstPass);
    void finishDiffusionCycles(int cycles, const Residual& left, const std::string& summary, double cgSeconds,
                               Clock::time_point start);
    std::vector<float> tailShapeOf(const Medium& mc, const std::vector<float>& r) const;
    std::vector<float> coarseOrders(const Medium& mc, LpmSettings& cs, const SolvePlan& coarsePlan,
                                    std::vector<float> uc, const Residual& left, bool shapedTail, int cycle, int& p,
                                    TwoGridCount& count, const MassRows* rows = nullptr);
    bool cycleConverged(const Residual& r, bool shapedTail) const;
    /// LpmResult::absoluteResidual and its line, where the cycle tests the absolute power.
    void recordAbsoluteResidual(const Residual& r, bool shapedTail);
    /// One physical fine pass p++ of the source r (deposits to S): r <- K r, next_ then holds
    /// the old r.
    void sweepInPlace(std::vector<float>& r, int& p);
    /// s_.cycleSmoothing physical passes r <- K r of a cycle's residual.
    Residual smoothResidual(std::vector<float>& r, int& p);
    Residual smoothSeparableResidual(SeparableSource& r, int& p);
    /// -v: one cycle's residual after its fine pass (signed and absolute power); cycle -1:
    /// after a smoothing pass.
    void reportCycle(int cycle, const Residual& left) const;
    void reportTwoGrid(const Medium& mc, const LpmSettings& cs, int cycles, const TwoGridCount& count,
                       const Residual& r, bool shapedTail, bool smoothed, Clock::time_point start);
    /// One fine pass with separable sources: of the light jobs (src null) or of `src`; its
    /// deposits fold into the SH result and sep_->next, less `takeFromNext` (a coarse part
    /// held as SeparableSource::offset) and `takeIsotropic` (held as SeparableSource::isotropic;
    /// SeparableFold::finish) when given.
    void runSeparablePass(const SeparableSource* src, Tally& t, const std::vector<Job>* lightJobs = nullptr,
                          const HalfBuffer* takeFromNext = nullptr, const std::vector<float>* takeIsotropic = nullptr);
    // The GMRES continuation (core/krylov_pass.cpp).
    void finishWithGmres();
    void finishWithGeometricTail();
    HalfOperator basisOperator();
    double gmresTarget(double bNorm, bool coarse) const;  ///< the residual norm GMRES stops at
    void startFromSourceSum(std::vector<float>& B, HalfBuffer& halfB, std::vector<float>& X,
                            std::vector<float>& firstResidual, Tally& sumTally);
    template <class Rhs>
    double unaccounted(const Rhs& B, const std::vector<float>& KX, const std::vector<float>& X) const;
    void clampNegativeLinear();
    void addToSourceSum(const std::vector<float>& src, float scale = 1.0f);
    bool extrapolateTail(double last, double ratio);  ///< coarse continuation: the geometric tail
    void recordPass(int pass, const Tally& t, Clock::time_point start, bool physical = true);
    /// sigma_s U V w_d summed, mean over RGB; `absolute`: each value by its absolute value
    double sourcePower(const std::vector<float>& u, bool absolute = false) const;
    std::vector<Job> sourceJobs(const std::vector<float>& src) const { return jobs_.sourceJobs(src, M_, m_.albedo); }
    /// One pass of the source `src` (held as the solve holds sources: by rows_ when set):
    /// deposits added to `out`, tallies to t.
    void propagate(const std::vector<float>& src, Tally& t, bool depositSh, std::vector<float>& out);
    size_t voxelOf(size_t row) const { return rows_ ? rows_->voxel[row] : row; }

    const Medium& m_;
    const Lights& lights_;
    const LpmSettings& s_;
    const SolvePlan& plan_;
    std::shared_ptr<LpmCache> cache_;
    std::vector<float>* initialSource_;
    LpmResult res_;
    size_t N_;
    const MassRows* rows_;  ///< where sources are held (a coarse continuation's voxels with mass); null: by voxel
    size_t S_;              ///< source rows: rows_->size(), or N_
    double V_;
    int M_, nb_, nc_, r_;
    size_t perVoxel_;
    const ShRows* shRows_;  ///< where res_.sh holds each voxel's row (core/sh_rows.h); null: row = voxel
    CubeQuadrature quad_;
    std::shared_ptr<const FormFactors> ff_;
    JobFactory jobs_;
    std::vector<std::uint8_t> slopeVoxel_;
    std::unique_ptr<PassRunner> runner_;
    std::vector<float> unshot_, next_;  ///< [voxel][bin][moment][rgb]
    /// Separable fine sources (plan.separableSource): in place of unshot_ and next_.
    struct SeparableState {
        Medium coarse;  ///< the two-grid solve's coarse medium
        FineCoarseMap map;
        std::vector<double> binWeight;
        SeparableSource unshot, next;
        std::vector<Bf16> binSource;  ///< [voxel][rgb]: the source of the bin being swept, in bfloat16
        explicit SeparableState(const Medium& fine);
    };
    std::unique_ptr<SeparableState> sep_;
    std::vector<std::vector<float>>
        halfSlots_;  ///< a half-precision source's decoded bins [slot][voxel][rgb] (core/half_source_pass.h)
    int pass_ = 1;
    float tailFactor_ = 1.0f;        ///< next's weight in the source sum: 1, or 1/(1 - rho) when extrapolated
    double extrapolatedError_ = -1;  ///< the extrapolation's estimated error (power), when it stopped the solve
    bool continuedOnCoarse_ = false;
    bool finishWithTail_ = false;  ///< a one-grid solve's geometric tail: one last pass of next / (1 - rho)
    bool depositSh_ = true;        ///< false in a coarse continuation (only its source sum is used)
};

}  // namespace lpm

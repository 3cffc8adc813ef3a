// The sweep jobs (core/sweep.h) of the solver's passes: one per quadrature direction, with
// its SH and unshot-bin fold coefficients, and one per sun. Equations (docs/lpm_solver.md):
//   SH of S:      c_lm += W_i g^l Ybar_lm(i)    (Funk-Hecke for HG; Ybar the bin average of Y)
//   next source:  U_d  += W_i F^{i,d} / w_d      (bin-averaged S)
#pragma once

#include <vector>

#include "core/medium.h"
#include "core/quadrature.h"
#include "core/sweep.h"

namespace lpm {

class JobFactory {
public:
    /// `R`: the medium's local-to-world rotation; `V`: voxel volume; `coeffs` SH
    /// coefficients of S, defined with asymmetry `gOut`.
    JobFactory(const CubeQuadrature& quad, const FormFactors& ff, const Mat3& R, double V, int coeffs, double gOut);

    /// The job of quadrature direction i (no boundary light, no source).
    Job direction(int i) const;
    /// Pass 0: every direction with its environment radiance `envBin[i]` through the
    /// boundary and, when m has emission, its source; then one job per lit sun.
    std::vector<Job> lightJobs(const Medium& m, const std::vector<RGB>& envBin, bool sweepDirections,
                               const std::vector<Sun>& suns) const;
    /// A propagation pass whose source is `src` ([voxel][bin][moment][rgb], `moments` per bin).
    std::vector<Job> sourceJobs(const std::vector<float>& src, int moments, const RGB& albedo) const;
    /// A propagation pass of a separable source (core/separable_source.h): the directions
    /// ordered by unshot bin, all reading `binSource` ([voxel][rgb]), which holds the bin of
    /// the jobs being swept. jobBin[j] receives job j's bin.
    std::vector<Job> binJobs(const Bf16* binSource, const RGB& albedo, std::vector<int>& jobBin) const;
    /// sourceJobs' jobs (a voxel-constant source), in its order, job j reading its bin from
    /// slots[j % slots.size()] ([voxel][rgb]), which the caller fills before sweeping it.
    /// jobBin[j] receives job j's bin.
    std::vector<Job> slotJobs(const std::vector<std::vector<float>>& slots, const RGB& albedo,
                              std::vector<int>& jobBin) const;

private:
    Job sun(const Sun& s) const;

    const CubeQuadrature& quad_;
    const FormFactors& ff_;
    Mat3 R_, Rinv_;
    double V_, gOut_;
    int nc_;
    std::vector<double> ybar_;  ///< [direction][coeff]: g^l times the bin average of Y_lm
};

}  // namespace lpm

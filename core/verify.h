// A bake's self-check (`lpmbake --verify N`, docs/verify.md): N Monte Carlo probes of the
// in-scattered radiance at voxels drawn with probability proportional to what a renderer
// sees of them, giving an estimate of the bake's relative error with a confidence interval.
//
// Weights and estimator. A voxel v contributes w_v = T_v sum_c sigma_s,c(v) S_c(v) to an
// image (T_v: its transmittance to the outside, averaged over the 6 axis directions; S the
// bake's band-0 in-scattered radiance). Probes draw voxels with p_v = w_v / sum w. The
// quantity estimated is the contribution-weighted relative RMS error of band 0,
//   e^2 = sum_v p_v (1/3) sum_c (S_c(v) - S*_c(v))^2 / Sbar(v)^2,  Sbar = mean_c S_c,
// S* the exact solution. A probe's Monte Carlo estimate M_c = S*_c + noise of standard
// error s_c, so each probe's term  t = (1/3) sum_c ((S_c - M_c)^2 - s_c^2) / Sbar^2  is
// unbiased for e^2 (the noise's own variance is subtracted). e^2 is the mean of the N
// terms, its interval mean +- t_{N-1} sd / sqrt(N) (Student t, 95%), and e and its
// bounds are the square roots (negative bounds clamp to 0).
//
// The probes use core/mc_reference (no code shared with the LPM sweeps), on the medium the
// solver saw. Deterministic for a seed, whatever the thread count.
#pragma once

#include <cstdint>
#include <vector>

#include "core/medium.h"

namespace lpm {

struct VerifySettings {
    int probes = 64;           ///< voxels drawn (with replacement)
    int pathsPerProbe = 4096;  ///< Monte Carlo paths at each probe
    std::uint64_t seed = 0x5eed;
    double confidence = 0.95;  ///< two-sided level of the interval (0.9, 0.95 or 0.99)
    void validate() const;     ///< throws SettingError (fields probes, pathsPerProbe, confidence)
};

struct VerifyProbe {
    size_t voxel = 0;
    double bake = 0;  ///< Sbar: the bake's band-0 coefficient, mean over RGB
    double mc = 0;    ///< the Monte Carlo estimate, mean over RGB
    double term = 0;  ///< the probe's unbiased estimate of e^2
};

struct VerifyReport {
    int probes = 0, pathsPerProbe = 0;
    double error = 0;          ///< estimated relative RMS error e (0.01 = 1%)
    double low = 0, high = 0;  ///< its confidence interval
    double confidence = 0.95;
    double mcNoise = 0;  ///< RMS relative standard error of the probes' MC estimates
    double seconds = 0;
    std::vector<VerifyProbe> probeList;
};

/// Per stored voxel: the transmittance from its centre to the block's boundary, averaged
/// over the six axis directions (1 outside the medium's support).
std::vector<float> axisTransmittance(const Medium& medium);

/// Checks `sh` ([voxel][coeff][rgb], `coeffs` per voxel, band 0 first: the solver's
/// result including every sun's single scattering) against Monte Carlo probes. A medium
/// with no scattering contribution (all weights 0) returns probes = 0 and error 0.
VerifyReport verifyBake(const Medium& medium, const Lights& lights, const std::vector<float>& sh, int coeffs,
                        const VerifySettings& settings);

/// The two-sided Student t quantile for `confidence` (0.9, 0.95, 0.99) and `dof` >= 1.
double studentT(double confidence, int dof);

}  // namespace lpm

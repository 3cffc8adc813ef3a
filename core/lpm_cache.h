// Precomputations of the solver that depend on the settings and the lights but not on
// the medium: the form factors of a quadrature and phase function, and the binned
// environment. The frames of a sequence share one cache (baker/sequence.cpp), so they
// are computed once per sequence; results are the same with or without a cache.
#pragma once

#include <array>
#include <map>
#include <memory>
#include <mutex>
#include <tuple>

#include "core/env_binning.h"
#include "core/quadrature.h"

namespace lpm {

class LpmCache {
public:
    /// Form factors of the n x n-per-face quadrature into b x b-per-face bins (b = 0: one
    /// isotropic bin) for Henyey-Greenstein g.
    std::shared_ptr<const FormFactors> formFactors(int directionsPerFace, int binsPerFace, double g);
    /// binEnvironment(env, CubeQuadrature(n), Rinv, hotShare). Keyed by the EnvMap's
    /// address: `env` must outlive the cache, or call forgetEnvironments() first.
    std::shared_ptr<const EnvBinning> envBinning(const EnvMap& env, int directionsPerFace, const Mat3& Rinv,
                                                 double hotShare);
    void forgetEnvironments();
    int formFactorsComputed() const { return ffComputed_; }
    int envBinningsComputed() const { return envComputed_; }

private:
    using EnvKey = std::tuple<const EnvMap*, int, double, std::array<double, 9>>;
    std::mutex mutex_;
    std::map<std::tuple<int, int, double>, std::shared_ptr<const FormFactors>> formFactors_;
    std::map<EnvKey, std::shared_ptr<const EnvBinning>> envBinnings_;
    int ffComputed_ = 0, envComputed_ = 0;
};

}  // namespace lpm

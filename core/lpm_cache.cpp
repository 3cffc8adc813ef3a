// Solver precomputation cache (lpm_cache.h).
#include "core/lpm_cache.h"

namespace lpm {

std::shared_ptr<const FormFactors> LpmCache::formFactors(int directionsPerFace, int binsPerFace, double g) {
    const std::lock_guard<std::mutex> lock(mutex_);
    auto& slot = formFactors_[{directionsPerFace, binsPerFace, g}];
    if (!slot) {
        const CubeQuadrature quad(directionsPerFace);
        std::unique_ptr<CubeQuadrature> bins;
        if (binsPerFace > 0) bins.reset(new CubeQuadrature(binsPerFace));
        slot = std::make_shared<const FormFactors>(quad, bins.get(), g);
        ++ffComputed_;
    }
    return slot;
}

std::shared_ptr<const EnvBinning> LpmCache::envBinning(const EnvMap& env, int directionsPerFace, const Mat3& Rinv,
                                                       double hotShare) {
    const std::lock_guard<std::mutex> lock(mutex_);
    auto& slot = envBinnings_[EnvKey{&env, directionsPerFace, hotShare, Rinv.m}];
    if (!slot) {
        slot =
            std::make_shared<const EnvBinning>(binEnvironment(env, CubeQuadrature(directionsPerFace), Rinv, hotShare));
        ++envComputed_;
    }
    return slot;
}

void LpmCache::forgetEnvironments() {
    const std::lock_guard<std::mutex> lock(mutex_);
    envBinnings_.clear();
}

}  // namespace lpm

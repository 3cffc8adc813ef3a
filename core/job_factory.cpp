// Sweep jobs of the solver's passes (core/job_factory.h).
#include "core/job_factory.h"

#include <cmath>

#include "core/sh.h"

namespace lpm {

JobFactory::JobFactory(const CubeQuadrature& quad, const FormFactors& ff, const Mat3& R, double V, int coeffs,
                       double gOut)
    : quad_(quad), ff_(ff), R_(R), Rinv_(R.transposed()), V_(V), gOut_(gOut), nc_(coeffs) {
    const int nd = quad.count();
    ybar_.assign(size_t(nd) * nc_, 0.0);
    std::vector<Vec3> sd;
    std::vector<double> sw;
    double y[16];
    for (int i = 0; i < nd; ++i) {
        quad.subdivide(i, 8, sd, sw);
        for (size_t j = 0; j < sd.size(); ++j) {
            shEval(R * sd[j], y);
            for (int k = 0; k < nc_; ++k) ybar_[size_t(i) * nc_ + k] += y[k] * sw[j] / quad.weight(i);
        }
        for (int k = 0; k < nc_; ++k) ybar_[size_t(i) * nc_ + k] *= std::pow(gOut, shBand(k));
    }
}

Job JobFactory::direction(int i) const {
    Job j;
    j.w = quad_.dir(i);
    j.axis = CubeQuadrature::faceAxis(quad_.face(i));
    j.sign = CubeQuadrature::faceSign(quad_.face(i));
    j.weight = quad_.weight(i);
    // A different lattice offset per direction (R2 low-discrepancy sequence) keeps the ray
    // maps of neighbouring directions from aliasing with the voxel grid in the same way;
    // coverage stays exact for any offset.
    j.offsetU = std::fmod(0.5 + 0.7548776662466927 * (i + 1), 1.0);
    j.offsetV = std::fmod(0.5 + 0.5698402909980532 * (i + 1), 1.0);
    j.shCoef.resize(nc_);
    for (int k = 0; k < nc_; ++k) j.shCoef[k] = quad_.weight(i) * ybar_[size_t(i) * nc_ + k] / V_;
    const int nb = ff_.binCount();
    j.binCoef.resize(nb);
    const double* row = ff_.row(i);
    for (int d = 0; d < nb; ++d) j.binCoef[d] = quad_.weight(i) * row[d] / (ff_.binWeight(d) * V_);
    return j;
}

Job JobFactory::sun(const Sun& s) const {
    const Vec3 wWorld = normalize(-s.toSun);
    Job j;
    j.w = Rinv_ * wWorld;
    j.axis = dominantAxis(j.w);
    j.sign = j.w[j.axis] > 0 ? 1 : -1;
    j.boundary = s.irradiance;
    j.weight = 1.0;
    const double half = 0.5 * s.angularDiameterDeg * kPi / 180.0;
    double y[16];
    shEval(wWorld, y);
    j.shCoef.resize(nc_);
    for (int k = 0; k < nc_; ++k) j.shCoef[k] = y[k] * std::pow(gOut_, shBand(k)) * capBandFactor(shBand(k), half) / V_;
    const std::vector<double> row = ff_.rowForCone(j.w, half);
    const int nb = ff_.binCount();
    j.binCoef.resize(nb);
    for (int d = 0; d < nb; ++d) j.binCoef[d] = row[d] / (ff_.binWeight(d) * V_);
    return j;
}

std::vector<Job> JobFactory::lightJobs(const Medium& m, const std::vector<RGB>& envBin, bool sweepDirections,
                                       const std::vector<Sun>& suns) const {
    std::vector<Job> jobs;
    if (sweepDirections) {
        for (int i = 0; i < quad_.count(); ++i) {
            Job j = direction(i);
            j.boundary = envBin[i];
            if (m.hasEmission()) {
                j.src = reinterpret_cast<const float*>(m.emission.data());
                j.srcScale = RGB(1 - m.albedo.r, 1 - m.albedo.g, 1 - m.albedo.b);
            }
            if (j.boundary.isBlack() && !j.src) continue;
            jobs.push_back(std::move(j));
        }
    }
    for (const Sun& s : suns)
        if (!s.irradiance.isBlack()) jobs.push_back(sun(s));
    return jobs;
}

std::vector<Job> JobFactory::sourceJobs(const std::vector<float>& src, int moments, const RGB& albedo) const {
    const size_t perVoxel = size_t(ff_.binCount()) * moments * 3;
    std::vector<Job> jobs;
    jobs.reserve(quad_.count());
    for (int i = 0; i < quad_.count(); ++i) {
        Job j = direction(i);
        j.src = &src[size_t(ff_.binOfDirection(i)) * moments * 3];
        j.srcStride = perVoxel;
        j.srcLinear = moments == 4;
        j.srcScale = albedo;
        jobs.push_back(std::move(j));
    }
    return jobs;
}

std::vector<Job> JobFactory::slotJobs(const std::vector<std::vector<float>>& slots, const RGB& albedo,
                                      std::vector<int>& jobBin) const {
    std::vector<Job> jobs;
    jobBin.clear();
    for (int i = 0; i < quad_.count(); ++i) {
        Job j = direction(i);
        j.src = slots[size_t(i) % slots.size()].data();
        j.srcStride = 3;
        j.srcScale = albedo;
        jobs.push_back(std::move(j));
        jobBin.push_back(ff_.binOfDirection(i));
    }
    return jobs;
}

std::vector<Job> JobFactory::binJobs(const Bf16* binSource, const RGB& albedo, std::vector<int>& jobBin) const {
    std::vector<Job> jobs;
    jobBin.clear();
    for (int d = 0; d < ff_.binCount(); ++d)
        for (int i = 0; i < quad_.count(); ++i) {
            if (ff_.binOfDirection(i) != d) continue;
            Job j = direction(i);
            j.srcBf16 = binSource;
            j.srcStride = 3;
            j.srcScale = albedo;
            jobs.push_back(std::move(j));
            jobBin.push_back(d);
        }
    return jobs;
}

}  // namespace lpm

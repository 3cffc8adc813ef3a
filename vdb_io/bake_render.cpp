// The preview ray march of a bake (bake_render.h).
#include "vdb_io/bake_render.h"

#include <algorithm>
#include <cmath>
#include <memory>

#include <openvdb/tools/Interpolation.h>

#include "core/parallel.h"
#include "core/sh.h"
#include "core/sun_term.h"
#include "vdb_io/bake_schema.h"
#include "vdb_io/io_error.h"

namespace lpm {

namespace {

using openvdb::tools::BoxSampler;

/// Ray/box intersection in index space; returns false when the ray misses.
bool clipRay(const openvdb::Vec3d& o, const openvdb::Vec3d& d, const openvdb::BBoxd& box, double& t0, double& t1) {
    t0 = 0;
    t1 = 1e300;
    for (int a = 0; a < 3; ++a) {
        if (std::fabs(d[a]) < 1e-300) {
            if (o[a] < box.min()[a] || o[a] > box.max()[a]) return false;
            continue;
        }
        double ta = (box.min()[a] - o[a]) / d[a], tb = (box.max()[a] - o[a]) / d[a];
        if (ta > tb) std::swap(ta, tb);
        t0 = std::max(t0, ta);
        t1 = std::min(t1, tb);
    }
    return t0 < t1;
}

/// Index-space box that holds every voxel the trilinear density can be non-zero in.
openvdb::BBoxd marchBox(const openvdb::FloatGrid& density) {
    const openvdb::CoordBBox cb = density.evalActiveVoxelBoundingBox();
    return openvdb::BBoxd(cb.min().asVec3d() - openvdb::Vec3d(1), cb.max().asVec3d() + openvdb::Vec3d(1));
}

/// One task's view of the bake: accessors are not thread-safe, so each task has its own.
class RayMarcher {
public:
    RayMarcher(const BakeFile& bake, const ShaderParams& shader, double stepVoxels)
        : bake_(bake), shader_(shader), step_(stepVoxels), density_(bake.density->getConstAccessor()),
          nc_(shCount(bake.shOrder)), box_(marchBox(*bake.density)) {
        for (int k = 0; k < nc_; ++k) sh_.push_back(bake.sh[k]->getConstAccessor());
        for (const auto& g : bake.sunTransmittance) sunT_.push_back(g->getConstAccessor());
        if (bake.emission) emission_ = std::make_unique<Vec3Acc>(bake.emission->getConstAccessor());
        for (size_t k = 0; k < bake.sunTransmittance.size() && k < shader.sunTerms.size(); ++k) {
            SunTerm t;
            t.toSun = shader.sunTerms[k].toward;
            t.irradiance = shader.sunTerms[k].irradiance;
            suns_.push_back(t);
        }
    }

    /// Radiance reaching `eye` along world direction v from the volume, and the
    /// transmittance through it.
    void march(const Vec3& eye, const Vec3& v, double L[3], double& T) {
        const openvdb::math::Transform& xf = bake_.density->transform();
        const openvdb::Vec3d eo = xf.worldToIndex(openvdb::Vec3d(eye.x, eye.y, eye.z));
        const openvdb::Vec3d di = xf.worldToIndex(openvdb::Vec3d(eye.x + v.x, eye.y + v.y, eye.z + v.z)) - eo;
        double t0, t1;
        if (!clipRay(eo, di, box_, t0, t1)) return;
        double Y[(kMaxShOrder + 1) * (kMaxShOrder + 1)];
        shEval(-v, Y);  // S(x, -v): light travelling toward the eye
        std::vector<double> sunPhase(suns_.size());
        for (size_t k = 0; k < suns_.size(); ++k) sunPhase[k] = sunTermPhase(suns_[k], shader_.sunTermG, -v);
        const double dt = step_ / di.length();  // world length of one step
        for (double t = t0 + 0.5 * dt; t < t1 && T > 1e-4; t += dt) {
            const openvdb::Vec3d p = eo + di * t;
            float dens = 0;
            BoxSampler::sample(density_, p, dens);
            if (!(dens > 0)) continue;
            const double tau = double(dens) * shader_.densityScale * dt;
            const double a = -std::expm1(-tau);  // 1 - exp(-tau), accurate for small tau
            double S[3], Le[3];
            inScattered(p, Y, sunPhase, S);
            emitted(p, Le);
            for (int ch = 0; ch < 3; ++ch)
                L[ch] += T * a * (shader_.albedo[ch] * S[ch] + (1 - shader_.albedo[ch]) * Le[ch]);
            T *= std::exp(-tau);
        }
    }

private:
    using Vec3Acc = openvdb::Vec3SGrid::ConstAccessor;

    /// S(x, -v) at index point p: the SH sum clamped at zero, plus the exact sun terms.
    void inScattered(const openvdb::Vec3d& p, const double* Y, const std::vector<double>& sunPhase, double S[3]) {
        double sh[3] = {0, 0, 0};
        for (int k = 0; k < nc_; ++k) {
            openvdb::Vec3s c;
            BoxSampler::sample(sh_[k], p, c);
            for (int ch = 0; ch < 3; ++ch) sh[ch] += c[ch] * Y[k];
        }
        for (int ch = 0; ch < 3; ++ch) S[ch] = std::max(0.0, sh[ch]);
        for (size_t k = 0; k < suns_.size(); ++k) {  // exact, non-negative: added after the clamp
            float T = 0;
            BoxSampler::sample(sunT_[k], p, T);
            for (int ch = 0; ch < 3; ++ch) S[ch] += suns_[k].irradiance[ch] * T * sunPhase[k];
        }
    }

    void emitted(const openvdb::Vec3d& p, double Le[3]) {
        openvdb::Vec3s le(0.f);
        if (emission_) BoxSampler::sample(*emission_, p, le);
        for (int ch = 0; ch < 3; ++ch) Le[ch] = le[ch];
    }

    const BakeFile& bake_;
    const ShaderParams& shader_;
    double step_;
    openvdb::FloatGrid::ConstAccessor density_;
    int nc_;
    openvdb::BBoxd box_;
    std::vector<Vec3Acc> sh_;
    std::vector<openvdb::FloatGrid::ConstAccessor> sunT_;
    std::unique_ptr<Vec3Acc> emission_;
    std::vector<SunTerm> suns_;
};

}  // namespace

PinholeCamera framingCamera(const BakeFile& bake, double fovYDeg, int width, int height) {
    if (!bake.density || bake.density->activeVoxelCount() == 0)
        throw InputError("render", "'" + bake.path + "' is an empty bake: give --eye and --target");
    const UpAxis up = readShaderParams(*bake.meta).up;
    const openvdb::BBoxd wb = bake.density->transform().indexToWorld(marchBox(*bake.density));
    const openvdb::Vec3d c = wb.getCenter();
    const double radius = 0.5 * (wb.max() - wb.min()).length();
    PinholeCamera cam;
    cam.target = {c.x(), c.y(), c.z()};
    cam.eye = cam.target + normalize(upAxisToWorld(up, Vec3(0.3, 0.35, 1.0))) *
                               (1.05 * radius / std::sin(0.5 * fovYDeg * kPi / 180));
    cam.up = upAxisToWorld(up, Vec3(0, 1, 0));
    cam.fovYDeg = fovYDeg;
    cam.width = width;
    cam.height = height;
    return cam;
}

std::vector<float> renderBake(const BakeFile& bake, const PinholeCamera& cam, const EnvMap* env, double stepVoxels) {
    const ShaderParams shader = readShaderParams(*bake.meta);
    const bool hasVolume = bake.density && bake.density->activeVoxelCount() > 0 && !bake.sh.empty();
    std::vector<float> img(size_t(cam.width) * cam.height * 3, 0.f);
    parallelForChunks(size_t(cam.height), 1, [&](size_t y0, size_t y1) {
        std::unique_ptr<RayMarcher> marcher;
        if (hasVolume) marcher = std::make_unique<RayMarcher>(bake, shader, stepVoxels);
        for (size_t py = y0; py < y1; ++py)
            for (int px = 0; px < cam.width; ++px) {
                const Vec3 v = cam.rayDirection(px + 0.5, py + 0.5);
                double L[3] = {0, 0, 0}, T = 1;
                if (marcher) marcher->march(cam.eye, v, L, T);
                if (env) {
                    const RGB b = env->lookupSmooth(v);
                    for (int ch = 0; ch < 3; ++ch) L[ch] += T * b[ch];
                }
                float* d = &img[(py * cam.width + px) * 3];
                for (int ch = 0; ch < 3; ++ch) d[ch] = std::isfinite(L[ch]) ? float(L[ch]) : 0.f;
            }
    });
    return img;
}

}  // namespace lpm

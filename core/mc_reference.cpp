#include "core/mc_reference.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/parallel.h"
#include "core/phase.h"
#include "core/rng.h"
#include "core/sh.h"

namespace lpm {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// Ray walking through the voxel grid in the local frame (Amanatides & Woo 1987).
class Tracker {
public:
    explicit Tracker(const Medium& m) : m_(m) {
        N_[0] = m.nx;
        N_[1] = m.ny;
        N_[2] = m.nz;
        for (int a = 0; a < 3; ++a) {
            h_[a] = m.voxelSize[a];
            ext_[a] = N_[a] * h_[a];
        }
    }

    // Calls f(voxel, sigma, ta, tb) for each voxel crossed by o + t d, t in [0, inf);
    // f returns true to stop.
    template <class F>
    void walk(const Vec3& o, const Vec3& d, F&& f) const {
        double t0 = 0, t1 = kInf;
        for (int a = 0; a < 3; ++a) {
            if (d[a] == 0) {
                if (o[a] < 0 || o[a] > ext_[a]) return;
                continue;
            }
            double ta = (0 - o[a]) / d[a], tb = (ext_[a] - o[a]) / d[a];
            if (ta > tb) std::swap(ta, tb);
            t0 = std::max(t0, ta);
            t1 = std::min(t1, tb);
        }
        if (!(t1 > t0)) return;
        int idx[3], step[3];
        double tMax[3], tDelta[3];
        const double tMid = t0 + 1e-9 * (t1 - t0);
        for (int a = 0; a < 3; ++a) {
            const double p = o[a] + d[a] * tMid;
            idx[a] = std::clamp(int(std::floor(p / h_[a])), 0, N_[a] - 1);
            if (d[a] > 0) {
                step[a] = 1;
                tMax[a] = ((idx[a] + 1) * h_[a] - o[a]) / d[a];
                tDelta[a] = h_[a] / d[a];
            } else if (d[a] < 0) {
                step[a] = -1;
                tMax[a] = (idx[a] * h_[a] - o[a]) / d[a];
                tDelta[a] = -h_[a] / d[a];
            } else {
                step[a] = 0;
                tMax[a] = kInf;
                tDelta[a] = kInf;
            }
        }
        double t = t0;
        for (;;) {
            int a = 0;
            if (tMax[1] < tMax[a]) a = 1;
            if (tMax[2] < tMax[a]) a = 2;
            const double tn = std::min(tMax[a], t1);
            const size_t vox = m_.index(idx[0], idx[1], idx[2]);
            const double sg = vox == Medium::npos ? 0.0 : double(m_.sigmaT[vox]);  // unallocated tile: empty
            if (tn > t && f(vox, sg, t, tn)) return;
            t = std::max(t, tn);
            if (t >= t1) return;
            idx[a] += step[a];
            if (idx[a] < 0 || idx[a] >= N_[a]) return;
            tMax[a] += tDelta[a];
        }
    }

    double transmittance(const Vec3& o, const Vec3& d) const {
        double tau = 0;
        walk(o, d, [&](size_t, double s, double ta, double tb) {
            tau += s * (tb - ta);
            return tau > 800.0;
        });
        return std::exp(-tau);
    }

    // Samples a collision with density sigma_t(t) T(t) along the ray. Returns false on escape.
    bool collide(const Vec3& o, const Vec3& d, Pcg32& rng, Vec3& hit, size_t& voxel) const {
        const double target = -std::log1p(-rng.uniform());
        double acc = 0;
        bool found = false;
        walk(o, d, [&](size_t vox, double s, double ta, double tb) {
            const double dt = s * (tb - ta);
            if (s > 0 && acc + dt >= target) {
                const double t = ta + (target - acc) / s;
                hit = o + d * std::min(t, tb);
                voxel = vox;
                found = true;
                return true;
            }
            acc += dt;
            return false;
        });
        return found;
    }

private:
    const Medium& m_;
    int N_[3];
    double h_[3], ext_[3];
};

struct Context {
    const Medium& m;
    const Lights& lights;
    Tracker tracker;
    Mat3 R, Rinv;
    int rouletteDepth;
    Context(const Medium& m_, const Lights& l_, const McSettings& s)
        : m(m_), lights(l_), tracker(m_), R(m_.localToWorld), Rinv(m_.localToWorld.transposed()),
          rouletteDepth(s.rouletteDepth) {}
};

Vec3 uniformSphere(double u1, double u2) {
    const double z = 1 - 2 * u1, r = std::sqrt(std::max(0.0, 1 - z * z)), phi = 2 * kPi * u2;
    return {r * std::cos(phi), r * std::sin(phi), z};
}

Vec3 sampleCone(const Vec3& w, double halfAngle, double u1, double u2) {
    if (halfAngle <= 0) return w;
    Vec3 t, b;
    orthonormalBasis(w, t, b);
    const double cosT = 1 - u1 * (1 - std::cos(halfAngle));
    const double sinT = std::sqrt(std::max(0.0, 1 - cosT * cosT)), phi = 2 * kPi * u2;
    return t * (sinT * std::cos(phi)) + b * (sinT * std::sin(phi)) + w * cosT;
}

double coneSolidAngle(double halfAngle) { return 2 * kPi * (1 - std::cos(halfAngle)); }
double sunHalfAngle(const Sun& sun) { return 0.5 * sun.angularDiameterDeg * kPi / 180.0; }

// Direct (uncollided) light arriving at local point x: one environment sample and one
// sample per sun, each reported as accum(w_world travel direction, radiance or irradiance,
// weight). With `mis` (a collision with outgoing travel direction mis->wOut), the weight
// includes the balance-heuristic MIS weight against phase-function sampling, which
// collidedRadiance counts when a phase-sampled ray escapes into the same light.
struct MisPhase {
    Vec3 wOut;
    double g;
};
template <class Accum>
void directLight(const Context& c, const Vec3& x, Pcg32& rng, Accum&& accum, const MisPhase* mis = nullptr) {
    if (c.lights.env) {
        Vec3 toward;
        double pdf;
        const double u1 = rng.uniform(), u2 = rng.uniform();
        const RGB Le = c.lights.env->sample(u1, u2, toward, pdf);
        if (pdf > 0 && !Le.isBlack()) {
            const double T = c.tracker.transmittance(x, c.Rinv * toward);
            double w = T / pdf;
            if (mis) w *= pdf / (pdf + henyeyGreenstein(dot(mis->wOut, -toward), mis->g));
            if (T > 0) accum(-toward, Le, w);
        }
    }
    for (const Sun& sun : c.lights.suns) {
        const double u1 = rng.uniform(), u2 = rng.uniform();
        const double half = sunHalfAngle(sun);
        const Vec3 toward = sampleCone(normalize(sun.toSun), half, u1, u2);
        const double T = c.tracker.transmittance(x, c.Rinv * toward);
        double w = T;  // irradiance E = radiance E / Omega over the cone, sampled with pdf 1 / Omega
        if (mis && half > 0) {
            const double pdfLight = 1.0 / coneSolidAngle(half);
            w *= pdfLight / (pdfLight + henyeyGreenstein(dot(mis->wOut, -toward), mis->g));
        }
        if (T > 0) accum(-toward, sun.irradiance, w);
    }
}

// Light reaching a collision along a phase-sampled direction that escaped the volume
// (toward = world direction toward the light, pdfPhase its sampling density): the
// environment and any sun disc it points into, with the MIS weights complementary to
// directLight's. Delta suns (diameter 0) are reached by next-event estimation only.
RGB escapedLight(const Context& c, const Vec3& toward, double pdfPhase) {
    double L[3] = {0, 0, 0};
    if (c.lights.env) {
        const RGB Le = c.lights.env->lookup(toward);
        const double pdfEnv = c.lights.env->pdf(toward);
        const double w = pdfPhase / (pdfPhase + pdfEnv);
        for (int k = 0; k < 3; ++k) L[k] += Le[k] * w;
    }
    for (const Sun& sun : c.lights.suns) {
        const double half = sunHalfAngle(sun);
        if (half <= 0 || dot(toward, normalize(sun.toSun)) < std::cos(half)) continue;
        const double omega = coneSolidAngle(half), pdfLight = 1.0 / omega;
        const double w = pdfPhase / (pdfPhase + pdfLight);
        for (int k = 0; k < 3; ++k) L[k] += sun.irradiance[k] / omega * w;
    }
    return RGB(float(L[0]), float(L[1]), float(L[2]));
}

// Radiance arriving at local point o from world look direction `look` (light travelling
// along -look), excluding uncollided environment and sun light: emission plus everything
// scattered at least once. Direct light at each collision combines next-event estimation
// and phase sampling with MIS (balance heuristic), so strongly forward or backward phase
// functions (|g| -> 1) against small bright suns stay low-variance.
RGB collidedRadiance(const Context& c, Vec3 o, Vec3 look, Pcg32& rng) {
    double L[3] = {0, 0, 0};
    double beta[3] = {1, 1, 1};
    const double g = c.m.g;
    double pdfPhase = 0;  // density of the last phase-sampled direction (0: the primary ray)
    for (int depth = 0;; ++depth) {
        Vec3 hit;
        size_t vox;
        if (!c.tracker.collide(o, c.Rinv * look, rng, hit, vox)) {
            if (pdfPhase > 0) {
                const RGB Le = escapedLight(c, look, pdfPhase);
                for (int k = 0; k < 3; ++k) L[k] += beta[k] * Le[k];
            }
            break;
        }
        const RGB& alb = c.m.albedo;
        if (c.m.hasEmission()) {
            const RGB& Le = c.m.emission[vox];
            for (int k = 0; k < 3; ++k) L[k] += beta[k] * (1 - alb[k]) * Le[k];
        }
        for (int k = 0; k < 3; ++k) beta[k] *= alb[k];
        if (beta[0] == 0 && beta[1] == 0 && beta[2] == 0) break;
        const Vec3 wOut = -look;  // travel direction of the light we are estimating
        const MisPhase mis{wOut, g};
        directLight(
            c, hit, rng,
            [&](const Vec3& wIn, const RGB& Li, double w) {
                const double p = henyeyGreenstein(dot(wOut, wIn), g) * w;
                for (int k = 0; k < 3; ++k) L[k] += beta[k] * Li[k] * p;
            },
            &mis);
        const double u1 = rng.uniform(), u2 = rng.uniform();
        const Vec3 wIn = sampleHenyeyGreenstein(wOut, g, u1, u2);
        pdfPhase = henyeyGreenstein(dot(wOut, wIn), g);
        look = -wIn;
        o = hit;
        if (depth >= c.rouletteDepth) {
            const double q = std::max(beta[0], std::max(beta[1], beta[2]));
            if (q < 1) {
                if (rng.uniform() >= q) break;
                for (int k = 0; k < 3; ++k) beta[k] /= q;
            }
        }
    }
    return RGB(float(L[0]), float(L[1]), float(L[2]));
}

struct Welford {
    std::vector<double> mean, m2;
    int n = 0;
    explicit Welford(size_t k) : mean(k, 0.0), m2(k, 0.0) {}
    void add(const std::vector<double>& x) {
        ++n;
        for (size_t i = 0; i < x.size(); ++i) {
            const double d = x[i] - mean[i];
            mean[i] += d / n;
            m2[i] += d * (x[i] - mean[i]);
        }
    }
    std::vector<double> stdErr() const {
        std::vector<double> e(mean.size(), 0.0);
        if (n > 1)
            for (size_t i = 0; i < e.size(); ++i) e[i] = std::sqrt(m2[i] / (n - 1) / n);
        return e;
    }
};

}  // namespace

std::vector<McVoxelEstimate> mcVoxelSH(const Medium& m, const Lights& lights, const std::vector<size_t>& voxels,
                                       int samples, int shOrder, const McSettings& s) {
    m.validate();
    if (shOrder < 0 || shOrder > kMaxShOrder)
        throw Error("MC", "SH order must be in 0..3, got " + std::to_string(shOrder));
    const Context c(m, lights, s);
    const int nc = shCount(shOrder);
    std::vector<double> gl(nc);
    for (int k = 0; k < nc; ++k) gl[k] = std::pow(m.g, shBand(k));
    // Lobes for the scattered-light direction: with |g| >= 0.5, the radiance scattered once
    // from a sun peaks around the sun's travel direction (g > 0) or against it (g < 0).
    std::vector<Vec3> lobes;
    const double lobeG = std::fabs(m.g);
    if (lobeG >= 0.5)
        for (const Sun& sun : lights.suns)
            if (!sun.irradiance.isBlack()) lobes.push_back(normalize(m.g > 0 ? -sun.toSun : sun.toSun));
    std::vector<McVoxelEstimate> out(voxels.size());
    parallelForChunks(voxels.size(), 1, [&](size_t b, size_t e) {
        for (size_t vi = b; vi < e; ++vi) {
            const size_t vox = voxels[vi];
            if (vox >= m.voxelCount()) throw Error("MC", "voxel index " + std::to_string(vox) + " out of range");
            int ix, iy, iz;
            m.coord(vox, ix, iy, iz);
            Pcg32 rng(s.seed, 0x9e3779b97f4a7c15ULL ^ (vox * 2 + 1));
            Welford w(size_t(nc) * 3);
            std::vector<double> acc(size_t(nc) * 3);
            double y[16];
            for (int n = 0; n < samples; ++n) {
                std::fill(acc.begin(), acc.end(), 0.0);
                const Vec3 x{(ix + rng.uniform()) * m.voxelSize.x, (iy + rng.uniform()) * m.voxelSize.y,
                             (iz + rng.uniform()) * m.voxelSize.z};
                auto add = [&](const Vec3& wWorld, const RGB& L, double weight) {
                    shEval(wWorld, y);
                    for (int k = 0; k < nc; ++k)
                        for (int ch = 0; ch < 3; ++ch) acc[size_t(k) * 3 + ch] += gl[k] * y[k] * L[ch] * weight;
                };
                directLight(c, x, rng, add);
                // Scattered light: one direction from a defensive mixture of the uniform
                // sphere and, with a peaked phase function and suns, HG lobes around each
                // sun's aureole (forward) or glory (backward) direction.
                const double u0 = lobes.empty() ? 0.0 : rng.uniform();
                const double u1 = rng.uniform(), u2 = rng.uniform();
                Vec3 wTravel;
                if (lobes.empty() || u0 < 0.5) {
                    wTravel = uniformSphere(u1, u2);
                } else {
                    const size_t k = std::min(lobes.size() - 1, size_t((u0 - 0.5) * 2 * lobes.size()));
                    wTravel = sampleHenyeyGreenstein(lobes[k], lobeG, u1, u2);
                }
                double pdf = 1.0 / kFourPi;
                if (!lobes.empty()) {
                    double lobePdf = 0;
                    for (const Vec3& l : lobes) lobePdf += henyeyGreenstein(dot(l, wTravel), lobeG);
                    pdf = 0.5 * pdf + 0.5 * lobePdf / lobes.size();
                }
                const RGB Lc = collidedRadiance(c, x, -wTravel, rng);
                if (!Lc.isBlack()) add(wTravel, Lc, 1.0 / pdf);
                w.add(acc);
            }
            McVoxelEstimate& est = out[vi];
            est.voxel = vox;
            est.samples = samples;
            est.mean = w.mean;
            est.stdErr = w.stdErr();
        }
    });
    return out;
}

McImage mcRenderImage(const Medium& m, const Lights& lights, const PinholeCamera& cam, int spp, const McSettings& s) {
    m.validate();
    if (cam.width <= 0 || cam.height <= 0) throw Error("MC", "image size must be positive");
    const Context c(m, lights, s);
    McImage img;
    img.width = cam.width;
    img.height = cam.height;
    const size_t np = size_t(cam.width) * cam.height;
    img.mean.assign(np * 3, 0.0);
    img.stdErr.assign(np * 3, 0.0);
    const Vec3 eyeLocal = c.Rinv * (cam.eye - m.origin);
    parallelForChunks(np, 16, [&](size_t b, size_t e) {
        for (size_t p = b; p < e; ++p) {
            Pcg32 rng(s.seed, 0xda3e39cb94b95bdbULL ^ (p * 2 + 1));
            Welford w(3);
            std::vector<double> v(3);
            const int px = int(p % cam.width), py = int(p / cam.width);
            for (int n = 0; n < spp; ++n) {
                const Vec3 look = cam.rayDirection(px + rng.uniform(), py + rng.uniform());
                const RGB Lc = collidedRadiance(c, eyeLocal, look, rng);
                RGB Lb(0.f);
                if (lights.env && s.background)
                    Lb = lights.env->lookup(look) * float(c.tracker.transmittance(eyeLocal, c.Rinv * look));
                for (int k = 0; k < 3; ++k) v[k] = double(Lc[k]) + double(Lb[k]);
                w.add(v);
            }
            const std::vector<double> se = w.stdErr();
            for (int k = 0; k < 3; ++k) {
                img.mean[p * 3 + k] = w.mean[k];
                img.stdErr[p * 3 + k] = se[k];
            }
        }
    });
    return img;
}

}  // namespace lpm

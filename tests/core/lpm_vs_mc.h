// Shared by the solver tests and the benchmarks: the test scenes (heterogeneous procedural
// volumes, sky + sun), the error measures against the MC reference, and small checks.
#pragma once

#include <chrono>
#include <cmath>
#include <string>
#include <vector>

#include "core/lpm_solver.h"
#include "core/mc_reference.h"
#include "test_scenes.h"

namespace lpm::test {

struct Case {
    std::string name;
    VolumeKind kind;
    double g, albedo, tau;
};

/// The pinned comparison set: three volumes; g in {0, 0.5, 0.85}; albedo in {0.5, 0.95}.
inline std::vector<Case> comparisonCases() {
    return {{"cloud g0 a0.5", VolumeKind::Cloud, 0.0, 0.5, 8.0},
            {"cloud g0.85 a0.95", VolumeKind::Cloud, 0.85, 0.95, 8.0},
            {"plume g0.5 a0.95", VolumeKind::Plume, 0.5, 0.95, 8.0},
            {"plume g0 a0.95", VolumeKind::Plume, 0.0, 0.95, 8.0},
            {"shell g0.85 a0.5", VolumeKind::Shell, 0.85, 0.5, 8.0},
            {"shell g0.5 a0.5", VolumeKind::Shell, 0.5, 0.5, 8.0}};
}

struct Scene {
    Medium medium;
    EnvMap sky = makeSky(128);
    Lights lights;
};

inline Scene makeScene(const Case& c, int n = 32) {
    Scene s;
    s.medium = makeVolume(c.kind, n, 1.0, 17);
    scaleToMaxOpticalDepth(s.medium, c.tau);
    s.medium.g = c.g;
    s.medium.albedo = RGB(float(c.albedo));
    s.lights.suns.push_back({normalize(Vec3{-0.5, 1.0, 0.35}), RGB(3.0f, 2.8f, 2.4f), 0.53});
    return s;
}

/// Voxels with sigma_t > 0, chosen uniformly at random (fixed seed).
inline std::vector<size_t> sampleVoxels(const Medium& m, int count, std::uint64_t seed = 99) {
    std::vector<size_t> dense;
    for (size_t i = 0; i < m.voxelCount(); ++i)
        if (m.sigmaT[i] > 0) dense.push_back(i);
    std::vector<size_t> out;
    Pcg32 rng(seed, 3);
    for (int k = 0; k < count && !dense.empty(); ++k) out.push_back(dense[size_t(rng.uniform() * dense.size())]);
    return out;
}

struct Comparison {
    double band0Rms = 0;    ///< relative RMS error of band 0 (all channels), MC noise included
    double band0Noise = 0;  ///< RMS relative standard error of the MC estimates
    double band0Bias = 0;   ///< mean relative error (LPM - MC) / MC
    double band12Rms = 0;   ///< RMS over voxels of |c_1..8 (LPM - MC)| / |c_0 (MC)|
    double band12Noise = 0;
    /// Band-0 error with the MC noise removed in quadrature.
    double band0Corrected() const { return std::sqrt(std::max(0.0, band0Rms * band0Rms - band0Noise * band0Noise)); }
};

inline Comparison compare(const LpmResult& r, const std::vector<McVoxelEstimate>& mc) {
    Comparison c;
    double n0 = 0, n12 = 0;
    for (const auto& e : mc) {
        for (int ch = 0; ch < 3; ++ch) {
            const double ref = e.mean[ch];
            const double rel = (r.coeff(e.voxel, 0)[ch] - ref) / ref;
            c.band0Rms += rel * rel;
            c.band0Bias += rel;
            c.band0Noise += (e.stdErr[ch] / ref) * (e.stdErr[ch] / ref);
            n0 += 1;
            if (r.coeffs >= 9 && e.mean.size() >= 27) {
                double d2 = 0, s2 = 0;
                for (int k = 1; k < 9; ++k) {
                    const double d = r.coeff(e.voxel, k)[ch] - e.mean[k * 3 + ch];
                    d2 += d * d;
                    s2 += e.stdErr[k * 3 + ch] * e.stdErr[k * 3 + ch];
                }
                c.band12Rms += d2 / (ref * ref);
                c.band12Noise += s2 / (ref * ref);
                n12 += 1;
            }
        }
    }
    c.band0Rms = std::sqrt(c.band0Rms / n0);
    c.band0Noise = std::sqrt(c.band0Noise / n0);
    c.band0Bias /= n0;
    if (n12 > 0) {
        c.band12Rms = std::sqrt(c.band12Rms / n12);
        c.band12Noise = std::sqrt(c.band12Noise / n12);
    }
    return c;
}

/// The white-furnace volume: the heterogeneous 16^3 cloud scaled to a largest line
/// optical depth `tau`, albedo 1 (lit by a constant environment, S = L0 everywhere).
inline Medium furnaceCloud(double tau) {
    Medium m = makeVolume(VolumeKind::Cloud, 16, 1.0);
    scaleToMaxOpticalDepth(m, tau);
    m.albedo = RGB(1.0f);
    return m;
}

/// Worst |S/L0 - 1| of band 0 (red) over voxels with sigma_t > 0: the white-furnace check.
inline double worstFurnaceError(const Medium& m, const LpmResult& r, float L0) {
    double worst = 0;
    for (size_t v = 0; v < m.voxelCount(); ++v)
        if (m.sigmaT[v] > 0) worst = std::max(worst, std::fabs(r.coeff(v, 0)[0] * kY00 / L0 - 1));
    return worst;
}

/// The sky of `sky` plus a sun toward (0.3, 1, 0.2), irradiance (5, 5, 4), 0.5 degrees:
/// the energy-balance tests' lighting.
inline Lights skyAndSun(const EnvMap& sky) {
    Lights lights;
    lights.env = &sky;
    lights.suns.push_back({normalize(Vec3{0.3, 1, 0.2}), RGB(5, 5, 4), 0.5});
    return lights;
}

/// Whether one of the solver's decisions contains `what`.
/// Relative RMS difference of a's band 0 against b's over the voxels holding medium.
inline double band0RelativeRms(const Medium& m, const LpmResult& a, const LpmResult& b) {
    double num = 0, den = 0;
    for (size_t v = 0; v < m.voxelCount(); ++v) {
        if (!(m.sigmaT[v] > 0)) continue;
        for (int c = 0; c < 3; ++c) {
            const double x = a.coeff(v, 0)[c], y = b.coeff(v, 0)[c];
            num += (x - y) * (x - y);
            den += y * y;
        }
    }
    return std::sqrt(num / den);
}

/// Passes a two-grid solve ran on its coarse grid.
inline int coarsePassCount(const LpmResult& r) {
    int n = 0;
    for (const PassStats& p : r.passes) n += p.coarse;
    return n;
}

/// The fixed point a two-grid solve iterates toward: full resolution with its rays (one
/// per voxel after single scattering), converged to tolerance 1e-5.
inline LpmResult twoGridFixedPoint(const Medium& m, const Lights& lights, LpmSettings s = {}) {
    s.multires = 0;
    s.raysHigherOrders = 1;
    s.tolerance = 1e-5;
    return solveLpm(m, lights, s);
}

inline bool saidDecision(const LpmResult& r, const char* what) {
    for (const auto& d : r.decisions)
        if (d.find(what) != std::string::npos) return true;
    return false;
}

inline double secondsOf(const std::function<void()>& f) {
    const auto t0 = std::chrono::steady_clock::now();
    f();
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace lpm::test

// Light Propagation Maps solver. Equations (docs/lpm_solver.md):
//   segment of length l in a voxel with extinction s, tau = s l, T = exp(-tau):
//     L_out = L_in T + Q l phi1(tau)
//     Int L ds = L_in l phi1(tau) + Q l^2 phi2(tau)
//   with phi1 = (1 - e^-tau)/tau, phi2 = (tau - 1 + e^-tau)/tau^2 (no 0/0 at s = 0).
//   A ray of direction i (solid angle w_i, tube cross-section A_perp) deposits
//   Phi_i(x) += A_perp Int L ds; W_i = w_i Phi_i / V is the radiance integrated over bin i.
//   SH of S:        c_lm += W_i g^l Ybar_lm(i)              (Funk-Hecke for HG)
//   next source:    U_d  += W_i F^{i,d} / w_d               (bin-averaged S)
#include "core/lpm_solver.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>

#include "core/lpm_cache.h"
#include "core/multires.h"
#include "core/parallel.h"
#include "core/quadrature.h"
#include "core/sweep.h"

namespace lpm {

namespace {

using Clock = std::chrono::steady_clock;
double secondsSince(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }



// Splits every voxel into k^3 copies of itself: the same piecewise-constant medium.
Medium subdivided(const Medium& m, int k) {
    Medium f = m;
    f.voxelSize = m.voxelSize / double(k);
    if (m.sparse()) {
        // A fine tile lies inside the coarse tile floor(fine tile / k): keep sparsity.
        Medium probe;
        probe.nx = m.nx * k;
        probe.ny = m.ny * k;
        probe.nz = m.nz * k;
        std::vector<std::uint8_t> active(size_t(probe.tilesX()) * probe.tilesY() * probe.tilesZ(), 0);
        for (int tz = 0; tz < probe.tilesZ(); ++tz)
            for (int ty = 0; ty < probe.tilesY(); ++ty)
                for (int tx = 0; tx < probe.tilesX(); ++tx) {
                    const size_t ct = size_t(tx / k) + size_t(m.tilesX()) * (size_t(ty / k) + size_t(m.tilesY()) * (tz / k));
                    active[size_t(tx) + size_t(probe.tilesX()) * (size_t(ty) + size_t(probe.tilesY()) * tz)] =
                        m.tileSlot[ct] >= 0;
                }
        f.allocate(probe.nx, probe.ny, probe.nz, &active, m.hasEmission());
    } else {
        f.allocate(m.nx * k, m.ny * k, m.nz * k, nullptr, m.hasEmission());
    }
    for (int z = 0; z < f.nz; ++z)
        for (int y = 0; y < f.ny; ++y)
            for (int x = 0; x < f.nx; ++x) {
                const size_t src = m.index(x / k, y / k, z / k), dst = f.index(x, y, z);
                if (src == Medium::npos || dst == Medium::npos) continue;
                f.sigmaT[dst] = m.sigmaT[src];
                if (m.hasEmission()) f.emission[dst] = m.emission[src];
            }
    return f;
}
}  // namespace

// gOut: the asymmetry of the phase function that S is defined with (differs from m.g when
// m is the delta-M-scaled medium). initialSource: null for the external-light problem; for
// the coarse continuation of multi-resolution, the restricted unshot [voxel][bin][rgb] that
// replaces pass 0 (no external light).
/// Per-voxel values of the k-fold subdivided medium `fm`, averaged back onto `m`'s voxels.
std::vector<float> averageBack(const Medium& m, const Medium& fm, int k, const std::vector<float>& fine) {
    std::vector<float> out(m.voxelCount(), 0.0f);
    parallelForChunks(size_t(m.nz), 1, [&](size_t zb, size_t ze) {
        for (int z = int(zb); z < int(ze); ++z)
            for (int y = 0; y < m.ny; ++y)
                for (int x = 0; x < m.nx; ++x) {
                    const size_t v = m.index(x, y, z);
                    if (v == Medium::npos) continue;
                    double acc = 0;
                    for (int dz = 0; dz < k; ++dz)
                        for (int dy = 0; dy < k; ++dy)
                            for (int dx = 0; dx < k; ++dx) acc += fine[fm.index(x * k + dx, y * k + dy, z * k + dz)];
                    out[v] = float(acc / (k * k * k));
                }
    });
    return out;
}

/// The exact sun term's transmittance (core/sun_term.h): each sun's job of pass 0 swept
/// again with unit irradiance; its deposit per voxel volume is the voxel mean of the
/// beam's transmittance. `jobs` ends with the suns' jobs, in `suns` order (black suns
/// have none); the first `explicitSuns` suns came from the lights, the rest are hot pixels.
void sweepSunTerms(const Medium& m, const std::vector<Sun>& suns, size_t explicitSuns, const std::vector<Job>& jobs,
                   int raysPerVoxel, int moments, double voxelVolume, LpmResult& res) {
    size_t lit = 0;
    for (const Sun& sun : suns) lit += sun.irradiance.isBlack() ? 0 : 1;
    size_t job = jobs.size() - lit;
    for (size_t i = 0; i < suns.size(); ++i) {
        if (suns[i].irradiance.isBlack()) continue;
        Job unit = jobs[job++];
        unit.boundary = RGB(1.0f);
        std::vector<float> phi(m.voxelCount() * 3 * moments, 0.0f);
        Tally ignored;
        if (moments == 4) sweepReference<true>(m, unit, raysPerVoxel, phi.data(), ignored);
        else sweepStep(m, unit, raysPerVoxel, phi.data(), ignored);
        SunTerm t;
        t.toSun = normalize(suns[i].toSun);
        t.irradiance = suns[i].irradiance;
        t.angularDiameterDeg = suns[i].angularDiameterDeg;
        t.fromEnvironment = i >= explicitSuns;
        t.transmittance.resize(m.voxelCount());
        for (size_t v = 0; v < t.transmittance.size(); ++v)
            t.transmittance[v] = float(std::clamp(phi[v * 3 * moments] / voxelVolume, 0.0, 1.0));
        res.sunTerms.push_back(std::move(t));
    }
}

/// The jobs grouped into sweep batches (sweepStepBatch): per sweep axis and source (in order
/// of first appearance), the jobs dealt alternately into `split` batches in job order. The
/// grouping depends on the jobs only, never on the thread count.
static std::vector<std::vector<const Job*>> sweepBatches(const std::vector<Job>& jobs, int split) {
    auto sameKey = [](const Job& a, const Job& b) {
        return a.axis == b.axis && a.src == b.src && a.srcStride == b.srcStride && a.srcScale.r == b.srcScale.r &&
               a.srcScale.g == b.srcScale.g && a.srcScale.b == b.srcScale.b;
    };
    std::vector<std::vector<const Job*>> keys;
    for (const Job& j : jobs) {
        auto it = std::find_if(keys.begin(), keys.end(), [&](const auto& k) { return sameKey(*k[0], j); });
        if (it == keys.end()) keys.push_back({&j});
        else it->push_back(&j);
    }
    // Batch s of every key before batch s + 1 of any: the halves of the list that two
    // threads take first then hold one batch of each axis (the axes' costs differ).
    std::vector<std::vector<const Job*>> batches;
    for (int part = 0; part < split; ++part)
        for (const auto& k : keys) {
            const size_t n = std::min(k.size(), size_t(split));
            if (size_t(part) >= n) continue;
            batches.emplace_back();
            for (size_t i = size_t(part); i < k.size(); i += n) batches.back().push_back(k[i]);
        }
    return batches;
}

/// Sizes of the per-direction fold: unshot bins, source moments, SH coefficients.
struct FoldShape {
    int bins, moments, coeffs;
    bool depositSh;
};

/// An RGB triple repeated 8 times: 24 floats = 3 channels x 8 lanes.
struct RgbRepeat {
    float v[24];
    explicit RgbRepeat(const float* p) {
        for (int k = 0; k < 24; k += 3) {
            v[k] = p[0];
            v[k + 1] = p[1];
            v[k + 2] = p[2];
        }
    }
};

/// dst[i] += coef[i] * p[i % 3] for i < 3 count: coefficients repeated per channel times an
/// RGB triple, written so that it vectorises.
static inline void addTimesRgb(float* __restrict dst, const float* __restrict coef, const RgbRepeat& p, int count) {
    int i = 0;
    for (; i + 24 <= 3 * count; i += 24)
        for (int k = 0; k < 24; ++k) dst[i + k] += coef[i + k] * p.v[k];
    for (; i < 3 * count; ++i) dst[i] += coef[i] * p.v[i % 3];
}

/// Folds the deposits phi[j] ([voxel][moment][rgb]) of jobs[0..n) into the SH result
/// ([voxel][coeff][rgb]) and the next unshot source `out` ([voxel][bin][moment][rgb]).
/// Voxels outer, jobs inner (in job order, so the sums do not depend on the thread count):
/// a voxel's unshot row stays in L1 across the jobs instead of streaming through memory
/// once per job.
static void foldDeposits(const FoldShape& f, const Job* jobs, size_t n, const std::vector<std::vector<float>>& phi,
                         const std::vector<std::uint8_t>& slopeVoxel, std::vector<float>& sh, std::vector<float>& out) {
    const int nb = f.bins, M = f.moments, nc = f.coeffs;
    const size_t N = phi.empty() ? 0 : phi[0].size() / (3 * size_t(M)), perVoxel = size_t(nb) * M * 3;
    // Per job, each bin and SH coefficient repeated for the 3 channels.
    std::vector<float> binC(n * nb * 3), shC(n * nc * 3);
    for (size_t j = 0; j < n; ++j)
        for (int c = 0; c < 3; ++c) {
            for (int d = 0; d < nb; ++d) binC[(j * nb + d) * 3 + c] = float(jobs[j].binCoef[d]);
            for (int k = 0; k < nc; ++k) shC[(j * nc + k) * 3 + c] = float(jobs[j].shCoef[k]);
        }
    parallelForChunks(N, 1024, [&](size_t vb, size_t ve) {
        for (size_t x = vb; x < ve; ++x) {
            float* un = &out[x * perVoxel];
            const int mx = slopeVoxel.empty() || slopeVoxel[x] ? M : 1;
            for (size_t j = 0; j < n; ++j) {
                const float* p = &phi[j][x * 3 * M];  // [moment][rgb]; moment 0 is the mean
                if (p[0] == 0 && p[1] == 0 && p[2] == 0) continue;
                const RgbRepeat rep(p);
                if (f.depositSh) addTimesRgb(&sh[x * nc * 3], &shC[j * nc * 3], rep, nc);
                const float* cj = &binC[j * nb * 3];
                if (M == 1) {
                    addTimesRgb(un, cj, rep, nb);
                    continue;
                }
                for (int d = 0; d < nb; ++d) {
                    const float bc = cj[d * 3];
                    for (int c = 0; c < 3; ++c) un[d * M * 3 + c] += bc * p[c];
                    // Least-squares slope from the first moment: Int xi_k^2 = 1/12.
                    for (int k = 1; k < mx; ++k)
                        for (int c = 0; c < 3; ++c) un[(d * M + k) * 3 + c] += 12.0f * bc * p[k * 3 + c];
                }
            }
        }
    });
}

static LpmResult solveImpl(const Medium& m, const Lights& lights, const LpmSettings& s, double gOut,
                           const std::vector<float>* initialSource = nullptr) {
    const auto t0 = Clock::now();
    m.validate();
    if (s.subdivide < 1 || s.subdivide > 8)
        throw Error("LPM", "subdivision must be in 1..8, got " + std::to_string(s.subdivide));
    if (s.subdivide > 1) {
        // Solve on the refined grid, then average the SH of S back over each voxel (the
        // voxel average of S is what the result means at any resolution).
        const int k = s.subdivide;
        LpmSettings fs = s;
        fs.subdivide = 1;
        const Medium fm = subdivided(m, k);
        LpmResult fr = solveLpm(fm, lights, fs);
        LpmResult res = fr;
        const size_t N = m.voxelCount(), nc = size_t(fr.coeffs);
        res.sh.assign(N * nc * 3, 0.0f);
        parallelForChunks(size_t(m.nz), 1, [&](size_t zb, size_t ze) {
            std::vector<double> acc(nc * 3);
            for (int z = int(zb); z < int(ze); ++z)
                for (int y = 0; y < m.ny; ++y)
                    for (int x = 0; x < m.nx; ++x) {
                        const size_t v = m.index(x, y, z);
                        if (v == Medium::npos) continue;
                        std::fill(acc.begin(), acc.end(), 0.0);
                        for (int dz = 0; dz < k; ++dz)
                            for (int dy = 0; dy < k; ++dy)
                                for (int dx = 0; dx < k; ++dx) {
                                    const size_t fv = fm.index(x * k + dx, y * k + dy, z * k + dz);
                                    for (size_t i = 0; i < nc * 3; ++i) acc[i] += fr.sh[fv * nc * 3 + i];
                                }
                        for (size_t i = 0; i < nc * 3; ++i) res.sh[v * nc * 3 + i] = float(acc[i] / (k * k * k));
                    }
        });
        for (SunTerm& t : res.sunTerms) t.transmittance = averageBack(m, fm, k, t.transmittance);
        res.decisions.push_back("solved on voxels split " + std::to_string(k) + "x" + std::to_string(k) + "x" +
                                std::to_string(k) + " and averaged back");
        res.seconds = secondsSince(t0);
        return res;
    }
    if (s.raysPerVoxel < 1 || s.raysPerVoxel > 16)
        throw Error("LPM", "rays per voxel must be in 1..16, got " + std::to_string(s.raysPerVoxel));
    if (s.shOrder < 0 || s.shOrder > kMaxShOrder)
        throw Error("LPM", "SH order must be in 0..3, got " + std::to_string(s.shOrder));
    if (!(s.tolerance > 0)) throw Error("LPM", "tolerance must be positive, got " + std::to_string(s.tolerance));
    if (s.multires < -1 || s.multires > 1)
        throw Error("LPM", "multi-resolution must be -1 (auto), 0 or 1, got " + std::to_string(s.multires));
    if (s.raysHigherOrders != -1 && (s.raysHigherOrders < 1 || s.raysHigherOrders > 16))
        throw Error("LPM", "rays per voxel of the higher orders must be -1 or in 1..16, got " +
                               std::to_string(s.raysHigherOrders));
    if (s.multiresAfter < 1)
        throw Error("LPM", "full-resolution passes before the coarse grid must be >= 1, got " + std::to_string(s.multiresAfter));
    if (s.maxOrders < 1) throw Error("LPM", "max orders must be at least 1, got " + std::to_string(s.maxOrders));
    if (s.krylovAfter < 0 || s.coarseKrylovAfter < 0)
        throw Error("LPM", "Krylov switch points must be >= 0, got " + std::to_string(s.krylovAfter) + " and " +
                               std::to_string(s.coarseKrylovAfter));
    for (const Sun& sun : lights.suns) {
        if (!(length(sun.toSun) > 0)) throw Error("LPM", "sun direction must be non-zero");
        for (int c = 0; c < 3; ++c)
            if (!(sun.irradiance[c] >= 0) || !std::isfinite(sun.irradiance[c]))
                throw Error("LPM", "sun irradiance must be finite and non-negative, got " + std::to_string(sun.irradiance[c]));
        if (!(sun.angularDiameterDeg >= 0 && sun.angularDiameterDeg < 180))
            throw Error("LPM", "sun angular diameter must be in [0, 180) degrees, got " + std::to_string(sun.angularDiameterDeg));
    }

    LpmResult res;
    const size_t N = m.voxelCount();
    const double V = m.voxelVolume();
    const Mat3& R = m.localToWorld;
    const Mat3 Rinv = R.transposed();

    // Decisions: SH order and angular resolution of the unshot buffers.
    res.shOrder = s.shOrder;
    if (gOut == 0.0 && s.shOrder > 0) {
        res.shOrder = 0;
        res.decisions.push_back("SH order 0: the phase function is isotropic (g = 0), so S has no directional part");
    }
    res.coeffs = shCount(res.shOrder);
    int binsPerFace = s.binsPerFace;
    if (binsPerFace < 0) {
        // Bins must nest the direction texels (b divides n), or a direction straddling a
        // bin edge is given to one side and the scattered light is skewed.
        // Even n: 2x2 per face. n = 1 or 3: one bin per direction. Larger odd n: 1 per
        // face, which is coarse for forward scattering (measured in docs/accuracy.md).
        const int n = s.directionsPerFace;
        binsPerFace = m.g == 0.0 ? 0 : (n % 2 == 0 ? 2 : (n <= 3 ? n : 1));
        res.decisions.push_back(m.g == 0.0 ? "one isotropic unshot bin: g = 0"
                                           : std::to_string(binsPerFace) + "x" + std::to_string(binsPerFace) +
                                                 " unshot bins per cube face: g = " + std::to_string(m.g));
    }
    if (binsPerFace > 0 && s.directionsPerFace % binsPerFace != 0)
        throw Error("LPM", "bins per face (" + std::to_string(binsPerFace) + ") must divide directions per face (" +
                               std::to_string(s.directionsPerFace) + ")");
    // Source shape inside a voxel. A voxel-constant (step) source leaks light across
    // optically thick voxels (it is carried to the exit face undamped); a linear source with
    // deposited first moments follows the decay inside the voxel (docs/lpm_solver.md).
    double maxTau = 0;
    {
        const double hmax = std::max(m.voxelSize.x, std::max(m.voxelSize.y, m.voxelSize.z));
        for (float sg : m.sigmaT) maxTau = std::max(maxTau, double(sg) * hmax);
    }
    if (s.linearSource < -1 || s.linearSource > 1)
        throw Error("LPM", "linear source must be -1 (auto), 0 or 1, got " + std::to_string(s.linearSource));
    const bool linear = s.linearSource == 1 || (s.linearSource < 0 && maxTau > s.linearSourceAbove);
    {
        char buf[240];
        if (s.linearSource < 0)
            std::snprintf(buf, sizeof buf, "%s source inside voxels: largest voxel optical depth %.3g %s %.3g",
                          linear ? "linear" : "voxel-constant", maxTau, linear ? ">" : "<=", s.linearSourceAbove);
        else
            std::snprintf(buf, sizeof buf, "%s source inside voxels (requested)", linear ? "linear" : "voxel-constant");
        res.decisions.push_back(buf);
        const double leakAbove = linear ? s.linearSourceVoxelCap : 2.0;
        if (maxTau > leakAbove) {
            std::snprintf(buf, sizeof buf,
                          "warning: voxels up to optical depth %.3g across; above ~%g light leaks through them "
                          "(measured in docs/accuracy.md): subdivide by %d to bring it near %g",
                          maxTau, leakAbove, int(std::ceil(maxTau / leakAbove)), leakAbove);
            res.decisions.push_back(buf);
        }
    }
    const int M = linear ? 4 : 1;  // per bin: mean, or mean and x, y, z slopes
    const CubeQuadrature quad(s.directionsPerFace);
    std::shared_ptr<LpmCache> cache = s.cache ? s.cache : std::make_shared<LpmCache>();
    const std::shared_ptr<const FormFactors> formFactors = cache->formFactors(s.directionsPerFace, binsPerFace, m.g);
    const FormFactors& ff = *formFactors;
    const int nd = quad.count(), nb = ff.binCount(), nc = res.coeffs;
    res.directionCount = nd;
    res.binCount = nb;

    // Per-direction SH factors: g^l times the bin average of Y_lm (world directions).
    std::vector<double> ybar(size_t(nd) * nc, 0.0);
    {
        std::vector<Vec3> sd;
        std::vector<double> sw;
        double y[16];
        for (int i = 0; i < nd; ++i) {
            quad.subdivide(i, 8, sd, sw);
            for (size_t j = 0; j < sd.size(); ++j) {
                shEval(R * sd[j], y);
                for (int k = 0; k < nc; ++k) ybar[size_t(i) * nc + k] += y[k] * sw[j] / quad.weight(i);
            }
            for (int k = 0; k < nc; ++k) ybar[size_t(i) * nc + k] *= std::pow(gOut, shBand(k));
        }
    }

    // Environment radiance box-filtered over each direction bin (core/env_binning.h).
    std::vector<RGB> envBin(nd, RGB(0.f));
    const bool hasEnv = lights.env && lights.env->integral() > 0;
    std::vector<Sun> suns = lights.suns;  // and the environment's hot pixels
    if (hasEnv) {
        const std::shared_ptr<const EnvBinning> binned =
            cache->envBinning(*lights.env, s.directionsPerFace, Rinv, s.envHotShare);
        envBin = binned->radiance;
        suns.insert(suns.end(), binned->hotSuns.begin(), binned->hotSuns.end());
        if (!binned->hotSuns.empty()) {
            char buf[200];
            std::snprintf(buf, sizeof buf,
                          "environment: hot pixels (each >= %.3g of the power) with %.1f%% of its power swept as %zu "
                          "sun(s) in their exact direction",
                          s.envHotShare, 100 * binned->hotShare, binned->hotSuns.size());
            res.decisions.push_back(buf);
        }
    } else {
        if (!initialSource) res.decisions.push_back("no environment pass: no environment light");
    }
    if (!m.hasEmission() && !initialSource) res.decisions.push_back("no emission source: no emission grid");

    // Fold coefficients for LPM directions.
    auto makeJob = [&](int i) {
        Job j;
        j.w = quad.dir(i);
        j.axis = CubeQuadrature::faceAxis(quad.face(i));
        j.sign = CubeQuadrature::faceSign(quad.face(i));
        j.weight = quad.weight(i);
        // A different lattice offset per direction (R2 low-discrepancy sequence) keeps
        // the ray maps of neighbouring directions from aliasing with the voxel grid in
        // the same way; coverage stays exact for any offset.
        j.offsetU = std::fmod(0.5 + 0.7548776662466927 * (i + 1), 1.0);
        j.offsetV = std::fmod(0.5 + 0.5698402909980532 * (i + 1), 1.0);
        j.shCoef.resize(nc);
        for (int k = 0; k < nc; ++k) j.shCoef[k] = quad.weight(i) * ybar[size_t(i) * nc + k] / V;
        j.binCoef.resize(nb);
        const double* row = ff.row(i);
        for (int d = 0; d < nb; ++d) j.binCoef[d] = quad.weight(i) * row[d] / (ff.binWeight(d) * V);
        return j;
    };

    res.sh.assign(N * nc * 3, 0.0f);
    // Unshot radiance per bin, layout [voxel][bin][moment][rgb] (moments: the mean, and with
    // a linear source the x, y, z slopes U_k of U0 + sum_k U_k xi_k).
    const size_t perVoxel = size_t(nb) * M * 3;
    // Linear source: voxels thicker than linearSourceVoxelCap keep a constant source. In
    // them the fitted slope approaches its bound 6 U0 (all light deposited at one face), the
    // linear profile goes strongly negative and the iteration loses accuracy (white furnace
    // of line depth 500, voxels up to ~60: worst error 0.5% / 0.7% / 1.8% / no convergence
    // with caps 4 / 8 / 16 / none).
    std::vector<std::uint8_t> slopeVoxel;
    size_t capped = 0;
    if (linear) {
        const double hmax = std::max(m.voxelSize.x, std::max(m.voxelSize.y, m.voxelSize.z));
        slopeVoxel.resize(N);
        for (size_t x = 0; x < N; ++x) {
            slopeVoxel[x] = double(m.sigmaT[x]) * hmax <= s.linearSourceVoxelCap;
            capped += slopeVoxel[x] ? 0 : 1;
        }
        if (capped) {
            char buf[200];
            std::snprintf(buf, sizeof buf, "%zu voxels thicker than optical depth %g keep a constant source", capped,
                          s.linearSourceVoxelCap);
            res.decisions.push_back(buf);
        }
    }
    std::vector<float> unshot(perVoxel * N, 0.0f), next(perVoxel * N, 0.0f);
    int r = s.raysPerVoxel;  // pass 0; the later passes use raysHigherOrders
    const size_t batchMem = size_t(512) << 20;
    const size_t maxBatch = std::max<size_t>(1, batchMem / std::max<size_t>(1, N * 3 * M * sizeof(float)));

    // Runs jobs in batches: sweeps in parallel (one buffer per job), then folds the batch
    // in job order, in parallel over voxels. Thread-count independent by construction.
    auto runJobs = [&](const std::vector<Job>& jobs, Tally& total, bool depositSh, std::vector<float>& out) {
        const size_t batch = std::min(jobs.size(), std::min<size_t>(maxBatch, 16));
        std::vector<std::vector<float>> phi(batch);
        for (size_t b0 = 0; b0 < jobs.size(); b0 += batch) {
            const size_t nbatch = std::min(batch, jobs.size() - b0);
            std::vector<Tally> tallies(nbatch);
            parallelForChunks(nbatch, 1, [&](size_t jb, size_t je) {
                for (size_t j = jb; j < je; ++j) {
                    phi[j].assign(N * 3 * M, 0.0f);
                    if (M == 4)
                        sweepReference<true>(m, jobs[b0 + j], r, phi[j].data(), tallies[j]);
                    else
                        sweepStep(m, jobs[b0 + j], r, phi[j].data(), tallies[j]);
                }
            });
            for (size_t j = 0; j < nbatch; ++j) total.add(tallies[j]);
            FoldShape shape{nb, M, nc, depositSh};
            foldDeposits(shape, &jobs[b0], nbatch, phi, slopeVoxel, res.sh, out);
        }
    };

    // Isotropic bins, SH order 0 and a voxel-constant source: every job folds as one scalar
    // (its bin coefficient) times the same pair (1 for the bin, shPerBin for band 0), so jobs
    // deposit straight into fixed accumulators: no per-direction buffer and no fold pass.
    // The accumulators are the sweep batches (jobs of one axis and one source, dealt
    // alternately into kBatchSplit groups, in job order; sweepStepBatch shares their planes),
    // so the sums are the same for any thread count.
    constexpr int kBatchSplit = 2;
    const bool isotropicFold = M == 1 && nb == 1 && nc == 1;
    auto runJobsIsotropic = [&](const std::vector<Job>& jobs, Tally& total, bool depositSh, std::vector<float>& out) {
        const double shPerBin = jobs.empty() ? 0.0 : jobs[0].shCoef[0] / jobs[0].binCoef[0];
        const float perWeight = jobs.empty() ? 0.0f : float(jobs[0].binCoef[0] / jobs[0].weight);
        const std::vector<std::vector<const Job*>> batches = sweepBatches(jobs, kBatchSplit);
        const size_t G = batches.size();
        std::vector<std::vector<float>> acc(G);
        std::vector<Tally> tallies(G);
        parallelForChunks(G, 1, [&](size_t gb, size_t ge) {
            for (size_t g = gb; g < ge; ++g) {
                acc[g].assign(N * 3, 0.0f);
                sweepStepBatch(m, batches[g], r, acc[g].data(), tallies[g], perWeight);
            }
        });
        for (const Tally& t : tallies) total.add(t);
        parallelForChunks(N * 3, 1 << 14, [&](size_t b, size_t e) {
            for (size_t i = b; i < e; ++i) {
                float sum = 0;
                for (size_t g = 0; g < G; ++g) sum += acc[g][i];
                out[i] += sum;
                if (depositSh) res.sh[i] += float(shPerBin * sum);
            }
        });
    };
    // Every job of the isotropic fold must share the SH-per-bin and bin-per-weight ratios.
    auto sameFoldShape = [&](const std::vector<Job>& jobs) {
        if (jobs.empty()) return true;
        const double ratio = jobs[0].shCoef[0] / jobs[0].binCoef[0], perWeight = jobs[0].binCoef[0] / jobs[0].weight;
        auto near = [](double a, double b) { return std::fabs(a - b) <= 1e-9 * std::fabs(b); };
        for (const Job& j : jobs)
            if (!near(j.shCoef[0] / j.binCoef[0], ratio) || !near(j.binCoef[0] / j.weight, perWeight)) return false;
        return true;
    };
    auto runJobsAny = [&](const std::vector<Job>& jobs, Tally& total, bool depositSh, std::vector<float>& out) {
        if (isotropicFold && sameFoldShape(jobs))
            runJobsIsotropic(jobs, total, depositSh, out);
        else
            runJobs(jobs, total, depositSh, out);
    };

    auto recordPass = [&](int pass, const Tally& t, Clock::time_point tp, bool physical = true) {
        PassStats ps;
        ps.pass = pass;
        ps.krylov = !physical;
        ps.injected = Tally::mean(t.injected);
        ps.absorbed = Tally::mean(t.absorbed);
        ps.escaped = Tally::mean(t.escaped);
        ps.scattered = Tally::mean(t.scattered);
        ps.seconds = secondsSince(tp);
        res.passes.push_back(ps);
        if (physical) {
            res.absorbed += ps.absorbed;
            res.escaped += ps.escaped;
        }
        res.segments += t.segments;
        if (s.progress) {
            char buf[200];
            std::snprintf(buf, sizeof buf, "pass %d: scattered %.6g (%.3g of injected), %.2f s", pass, ps.scattered,
                          res.injected > 0 ? ps.scattered / res.injected : 0.0, ps.seconds);
            s.progress(buf);
        }
    };

    // Pass 0: external light (environment through the boundary, emission, suns), or the
    // restricted source of a coarse continuation.
    if (initialSource) {
        double power = 0;
        for (size_t x = 0; x < N; ++x)
            for (int d = 0; d < nb; ++d)
                for (int c = 0; c < 3; ++c) {
                    const float u = (*initialSource)[(x * nb + d) * 3 + c];
                    next[(x * nb + d) * M * 3 + c] = u;
                    power += double(u) * m.sigmaT[x] * m.albedo[c] * ff.binWeight(d) * V;
                }
        res.injected = power / 3.0;
        PassStats ps;
        ps.injected = ps.scattered = res.injected;
        res.passes.push_back(ps);
    } else {
        const auto tp = Clock::now();
        std::vector<Job> jobs;
        if (hasEnv || m.hasEmission()) {
            for (int i = 0; i < nd; ++i) {
                Job j = makeJob(i);
                j.boundary = envBin[i];
                if (m.hasEmission()) {
                    j.src = reinterpret_cast<const float*>(m.emission.data());
                    j.srcScale = RGB(1 - m.albedo.r, 1 - m.albedo.g, 1 - m.albedo.b);
                }
                if (j.boundary.isBlack() && !j.src) continue;
                jobs.push_back(std::move(j));
            }
        }
        for (const Sun& sun : suns) {
            if (sun.irradiance.isBlack()) continue;
            const Vec3 wWorld = normalize(-sun.toSun);
            Job j;
            j.w = Rinv * wWorld;
            j.axis = dominantAxis(j.w);
            j.sign = j.w[j.axis] > 0 ? 1 : -1;
            j.boundary = sun.irradiance;
            j.weight = 1.0;
            const double half = 0.5 * sun.angularDiameterDeg * kPi / 180.0;
            double y[16];
            shEval(wWorld, y);
            j.shCoef.resize(nc);
            for (int k = 0; k < nc; ++k)
                j.shCoef[k] = y[k] * std::pow(gOut, shBand(k)) * capBandFactor(shBand(k), half) / V;
            const std::vector<double> row = ff.rowForCone(j.w, half);
            j.binCoef.resize(nb);
            for (int d = 0; d < nb; ++d) j.binCoef[d] = row[d] / (ff.binWeight(d) * V);
            jobs.push_back(std::move(j));
        }
        Tally t;
        runJobsAny(jobs, t, true, next);
        res.injected = Tally::mean(t.injected);
        if (s.sunTerms) sweepSunTerms(m, suns, lights.suns.size(), jobs, r, M, V, res);
        recordPass(0, t, tp);
    }

    // Jobs of a propagation pass whose source is `src` ([bin][voxel][rgb]).
    auto sourceJobs = [&](const std::vector<float>& src) {
        std::vector<Job> jobs;
        jobs.reserve(nd);
        for (int i = 0; i < nd; ++i) {
            Job j = makeJob(i);
            j.src = &src[size_t(ff.binOfDirection(i)) * M * 3];
            j.srcStride = perVoxel;
            j.srcLinear = M == 4;
            j.srcScale = m.albedo;
            jobs.push_back(std::move(j));
        }
        return jobs;
    };

    // Passes 1..: propagate what the previous pass scattered (source iteration). When
    // the per-pass energy ratio shows that plain iteration would need many more passes
    // (albedo near 1, thick media), switch to GMRES on the remaining sum.
    // Multi-resolution: the orders from coarseFrom on are solved on a grid twice as coarse
    // (docs/multires.md) and their S is interpolated back.
    int coarseFrom = 0;
    bool coarseDone = false;
    if (!initialSource && s.multires != 0) {
        const bool big = N >= size_t(s.multiresMinVoxels);
        const bool fits = m.nx >= 4 && m.ny >= 4 && m.nz >= 4;
        if (fits && (s.multires == 1 || big)) coarseFrom = s.multiresAfter + 1;
        char buf[240];
        if (coarseFrom > 0)
            std::snprintf(buf, sizeof buf, "multi-resolution: orders >= %d on a 2x coarser grid (%zu stored voxels%s)",
                          coarseFrom, N, s.multires == 1 ? ", requested" : "");
        else
            std::snprintf(buf, sizeof buf, "full resolution for every order: %s",
                          !fits ? "the block is under 4 voxels along an axis"
                                : (std::to_string(N) + " stored voxels < " + std::to_string(s.multiresMinVoxels)).c_str());
        res.decisions.push_back(buf);
    }
    // Rays of the passes after the first. Auto: one per voxel when the two-grid solve runs:
    // there the fine passes after single scattering propagate sums of smooth higher orders
    // (band-0 error against MC unchanged on plume-1M, docs/multires.md).
    const int raysHigher = s.raysHigherOrders > 0 ? s.raysHigherOrders : (coarseFrom > 0 ? 1 : s.raysPerVoxel);
    if (raysHigher != r) {
        r = raysHigher;
        res.decisions.push_back("multiple scattering with " + std::to_string(r) + " ray(s) per voxel" +
                                (s.raysHigherOrders > 0 ? " (requested)" : " (two-grid solve: smooth sources)") +
                                ", single scattering with " + std::to_string(s.raysPerVoxel));
    }
    // Two-grid continuation (docs/multires.md). The remaining sum X of sources solves
    // X = B + K X (B = the current source `next`, K one fine pass). A cycle restricts the
    // source r still to be distributed (first B) to the coarse grid, iterates the orders
    // there, and takes E = r + (coarse sum of the sources it propagated beyond r, injected
    // piecewise constant, which keeps its power) as the sum r gives rise to. One fine pass
    // of E deposits S at full resolution; its new residual r' = r + K E - E = K E - tail is
    // what the coarse grid got wrong, and the next cycle distributes it, until its power
    // falls below the tolerance (at most kCycles cycles).
    auto continueOnCoarse = [&](int firstPass) {
        constexpr int kCycles = 3;
        const auto tp = Clock::now();
        const Medium mc = coarsen(m);
        LpmSettings cs = s;
        cs.multires = 0;
        cs.cache = cache;
        cs.binsPerFace = binsPerFace;  // the restricted source is in these bins
        cs.raysPerVoxel = cs.raysHigherOrders = r;
        // GMRES earlier on the coarse grid: its passes are cheap next to the fine ones and its
        // Krylov vectors 1/8 the size (docs/multires.md).
        cs.krylovAfter = std::min(s.krylovAfter, s.coarseKrylovAfter);
        const int n = s.directionsPerFace, half = n / 2;
        cs.directionsPerFace =
            s.multiresDirections > 0 ? s.multiresDirections
                                     : (half >= 2 && (binsPerFace == 0 || half % binsPerFace == 0) ? half : n);
        auto power = [&](const std::vector<float>& u) {  // source power of [voxel][bin][moment][rgb]
            double p = 0;
            for (size_t v = 0; v < N; ++v)
                for (int d = 0; d < nb; ++d)
                    for (int c = 0; c < 3; ++c)
                        p += double(u[(v * nb + d) * M * 3 + c]) * m.sigmaT[v] * m.albedo[c] * ff.binWeight(d) * V;
            return p / 3.0;
        };
        // Three source-sized buffers: r (also holds E during the fine pass), the tail (the
        // source iteration's `unshot`, no longer needed) and next.
        std::vector<float> r = next;
        std::vector<float>& tail = unshot;
        std::fill(tail.begin(), tail.end(), 0.0f);  // slopes of the tail stay 0
        int cycles = 0, coarsePasses = 0, p = firstPass;
        double rPower = res.passes.back().scattered;
        bool coarseConverged = true;
        for (; cycles < kCycles && p < s.maxOrders; ++cycles) {
            const std::vector<float> uc = restrictSource(m, mc, r, nb, M);
            cs.maxOrders = std::max(1, s.maxOrders - p);
            cs.tolerance = std::fabs(rPower) > 0 ? s.tolerance * res.injected / std::fabs(rPower) : s.tolerance;
            const LpmResult cr = solveImpl(mc, Lights{}, cs, gOut, &uc);
            for (size_t i = 1; i < cr.passes.size(); ++i) {
                PassStats ps = cr.passes[i];
                ps.pass = p++;
                ps.coarse = true;
                res.passes.push_back(ps);
            }
            coarsePasses += int(cr.passes.size()) - 1;
            coarseConverged = coarseConverged && cr.converged;
            res.segments += cr.segments;
            if (cycles == 0)
                for (const std::string& d : cr.decisions) res.decisions.push_back("coarse grid: " + d);
            // tail = coarse sources beyond r, at each fine voxel its coarse parent's value.
            std::vector<float> tailCoarse = cr.sourceSum;
            for (size_t i = 0; i < tailCoarse.size(); ++i) tailCoarse[i] -= uc[i];
            injectCoarse(m, mc, tailCoarse, nb, M, tail);
            for (size_t i = 0; i < r.size(); ++i) r[i] += tail[i];  // r now holds E
            const auto tf = Clock::now();
            std::fill(next.begin(), next.end(), 0.0f);
            Tally t;
            runJobsAny(sourceJobs(r), t, true, next);
            recordPass(p++, t, tf);
            for (size_t i = 0; i < r.size(); ++i) r[i] = next[i] - tail[i];
            rPower = power(r);
            res.passes.back().scattered = std::fabs(rPower);
            if (std::fabs(rPower) <= s.tolerance * res.injected) {
                ++cycles;
                break;
            }
        }
        res.converged = coarseConverged && std::fabs(rPower) <= s.tolerance * res.injected;
        char buf[300];
        std::snprintf(buf, sizeof buf,
                      "two-grid: coarse grid %dx%dx%d with %d directions per face, %d cycle(s) of coarse orders and "
                      "one fine pass, %d coarse passes; source left %.3g of the input",
                      mc.nx, mc.ny, mc.nz, cs.directionsPerFace, cycles, coarsePasses,
                      res.injected > 0 ? std::fabs(rPower) / res.injected : 0.0);
        if (s.progress) s.progress("two-grid: " + std::to_string(secondsSince(tp)) + " s");
        res.decisions.push_back(buf);
        coarseDone = true;
    };

    // Coarse continuation: the sum of every propagated source (means), for the fine pass.
    if (initialSource) res.sourceSum.assign(N * size_t(nb) * 3, 0.0f);
    auto addToSourceSum = [&](const std::vector<float>& src) {
        if (!initialSource) return;
        parallelForChunks(N * size_t(nb), 4096, [&](size_t b, size_t e) {
            for (size_t i = b; i < e; ++i)
                for (int c = 0; c < 3; ++c) res.sourceSum[i * 3 + c] += src[i * M * 3 + c];
        });
    };

    int pass = 1;
    bool useKrylov = false;
    for (;; ++pass) {
        // Stop on the estimated energy still to come: the last pass's scattered power
        // times the geometric tail rho / (1 - rho) of the per-pass ratio (at least 1x).
        const double last = res.passes.back().scattered;
        const double prevP = res.passes.size() >= 2 ? res.passes[res.passes.size() - 2].scattered : 0.0;
        const double ratio = prevP > 0 ? last / prevP : 0.0;
        const double tail = last * std::max(1.0, ratio < 1.0 ? ratio / (1.0 - ratio) : 1e9);
        if (res.injected <= 0 || tail <= s.tolerance * res.injected) {
            res.converged = true;
            break;
        }
        if (pass >= s.maxOrders) break;
        if (coarseFrom > 0 && pass == coarseFrom) {
            continueOnCoarse(pass);
            break;
        }
        if (s.krylov && pass >= 4) {
            const double prev = res.passes[res.passes.size() - 2].scattered;
            const double rho = prev > 0 ? last / prev : 0.0;
            if (rho > 0.8 && rho < 1.0) {
                const double more = std::log(s.tolerance * res.injected / last) / std::log(rho);
                if (more > s.krylovAfter) {
                    char buf[240];
                    std::snprintf(buf, sizeof buf,
                                  "Krylov (GMRES) acceleration after pass %d: energy ratio per pass %.4f, plain "
                                  "source iteration would need about %.0f more passes",
                                  pass - 1, rho, more);
                    res.decisions.push_back(buf);
                    useKrylov = true;
                    break;
                }
            }
        }
        const auto tp = Clock::now();
        std::swap(unshot, next);
        std::fill(next.begin(), next.end(), 0.0f);
        addToSourceSum(unshot);
        Tally t;
        runJobsAny(sourceJobs(unshot), t, true, next);
        recordPass(pass, t, tp);
    }
    if (!useKrylov && !coarseDone) addToSourceSum(next);  // the remainder that was not propagated

    if (useKrylov && !coarseDone) {
        // Remaining sum X = sum_{j >= 1} U_{k+j} solves (I - K) X = B, B = `next`, where K
        // is one propagation pass (source -> next unshot). Restarted GMRES with modified
        // Gram-Schmidt in the inner product <a, b> = sum_d w_d a.b; every reduction is
        // chunked in a fixed order, so the result stays thread-count independent.
        const size_t len = next.size();
        std::vector<double> binW(len);
        // Slopes enter with the weight of their L2 norm over the voxel (Int xi^2 = 1/12).
        for (size_t i = 0; i < len; ++i)
            binW[i] = ff.binWeight(int((i / (3 * M)) % nb)) * ((i / 3) % M == 0 ? 1.0 : 1.0 / 12);
        auto dotW = [&](const std::vector<float>& a, const std::vector<float>& b) {
            const size_t chunk = 1 << 16;
            std::vector<double> part((len + chunk - 1) / chunk, 0.0);
            parallelForChunks(len, chunk, [&](size_t b0, size_t e0) {
                double acc = 0;
                for (size_t i = b0; i < e0; ++i) acc += binW[i] * double(a[i]) * double(b[i]);
                part[b0 / chunk] = acc;
            });
            double sum = 0;
            for (double v : part) sum += v;
            return sum;
        };
        auto axpy = [&](std::vector<float>& y, double a, const std::vector<float>& x) {
            parallelForChunks(len, 1 << 16, [&](size_t b0, size_t e0) {
                for (size_t i = b0; i < e0; ++i) y[i] = float(double(y[i]) + a * double(x[i]));
            });
        };
        // A v = v - K v.
        std::vector<float> kv(len);
        auto apply = [&](const std::vector<float>& v, std::vector<float>& outv) {
            const auto tp = Clock::now();
            std::fill(kv.begin(), kv.end(), 0.0f);
            Tally t;
            runJobsAny(sourceJobs(v), t, false, kv);
            recordPass(pass++, t, tp, false);
            parallelForChunks(len, 1 << 16, [&](size_t b0, size_t e0) {
                for (size_t i = b0; i < e0; ++i) outv[i] = v[i] - kv[i];
            });
        };
        const std::vector<float> B = next;
        const double bNorm = std::sqrt(dotW(B, B));
        // Krylov vectors are the big memory cost: cap their number by the memory budget.
        const size_t vecBytes = len * sizeof(float);
        const int restart = int(std::clamp<size_t>((size_t(2) << 30) / std::max<size_t>(1, vecBytes), 4,
                                                   size_t(std::max(4, s.krylovRestart))));
        const double target = s.tolerance * 0.1 * bNorm;
        std::vector<float> X(len, 0.0f), r = B;  // X0 = 0, r0 = B
        std::vector<std::vector<float>> basis;
        std::vector<float> w(len);
        double rNorm = bNorm;
        int matvecs = 0;
        while (rNorm > target && pass < s.maxOrders) {
            basis.assign(1, r);
            for (float& x : basis[0]) x = float(x / rNorm);
            std::vector<std::vector<double>> H(restart + 1, std::vector<double>(restart, 0.0));
            std::vector<double> cs(restart), sn(restart), g(restart + 1, 0.0);
            g[0] = rNorm;
            int k = 0;
            for (; k < restart && pass < s.maxOrders; ++k) {
                apply(basis[k], w);
                ++matvecs;
                for (int i = 0; i <= k; ++i) {
                    H[i][k] = dotW(w, basis[i]);
                    axpy(w, -H[i][k], basis[i]);
                }
                H[k + 1][k] = std::sqrt(dotW(w, w));
                for (int i = 0; i < k; ++i) {  // previous Givens rotations
                    const double t = cs[i] * H[i][k] + sn[i] * H[i + 1][k];
                    H[i + 1][k] = -sn[i] * H[i][k] + cs[i] * H[i + 1][k];
                    H[i][k] = t;
                }
                const double den = std::hypot(H[k][k], H[k + 1][k]);
                cs[k] = den > 0 ? H[k][k] / den : 1.0;
                sn[k] = den > 0 ? H[k + 1][k] / den : 0.0;
                const double hk1 = H[k + 1][k];
                H[k][k] = cs[k] * H[k][k] + sn[k] * hk1;
                H[k + 1][k] = 0;
                g[k + 1] = -sn[k] * g[k];
                g[k] = cs[k] * g[k];
                if (std::fabs(g[k + 1]) <= target || hk1 <= 1e-30 * bNorm) {
                    ++k;
                    break;
                }
                basis.push_back(w);
                for (float& x : basis.back()) x = float(x / hk1);
            }
            // Solve the triangular system and update X.
            std::vector<double> y(k, 0.0);
            for (int i = k - 1; i >= 0; --i) {
                double acc = g[i];
                for (int j = i + 1; j < k; ++j) acc -= H[i][j] * y[j];
                y[i] = H[i][i] != 0 ? acc / H[i][i] : 0.0;
            }
            for (int i = 0; i < k; ++i) axpy(X, y[i], basis[i]);
            // True residual r = B - A X (one more pass; keeps restarts honest).
            apply(X, w);
            ++matvecs;
            parallelForChunks(len, 1 << 16, [&](size_t b0, size_t e0) {
                for (size_t i = b0; i < e0; ++i) r[i] = B[i] - w[i];
            });
            rNorm = std::sqrt(dotW(r, r));
        }
        // Negative round-off in X would act as a negative source: clamp it.
        for (size_t i = 0; i < len; i += 3 * M)
            for (int c = 0; c < 3; ++c) X[i + c] = std::max(0.0f, X[i + c]);
        // Final physical pass: deposit S from the whole remaining sum.
        const auto tp = Clock::now();
        std::fill(next.begin(), next.end(), 0.0f);
        addToSourceSum(X);
        Tally t;
        runJobsAny(sourceJobs(X), t, true, next);
        recordPass(pass, t, tp);
        // Unshot: the source power that X fails to account for, |B + K X - X| (radiance
        // per bin) times sigma_s V w_d, mean over RGB.
        double miss = 0;
        for (int d = 0; d < nb; ++d)
            for (size_t x = 0; x < N; ++x)
                for (int c = 0; c < 3; ++c) {
                    const size_t i = (x * nb + d) * M * 3 + c;
                    miss += std::fabs(double(B[i]) + next[i] - X[i]) * m.sigmaT[x] * m.albedo[c] * ff.binWeight(d) * V;
                }
        res.passes.back().scattered = miss / 3.0;
        char buf[200];
        std::snprintf(buf, sizeof buf, "GMRES: %d passes (restart %d), relative residual %.3g", matvecs, restart,
                      bNorm > 0 ? rNorm / bNorm : 0.0);
        res.decisions.push_back(buf);
        res.converged = rNorm <= target;
    }
    if (linear) {
        // A linear source can dip below zero in a voxel's corners (no slope limiter: one
        // would break the scheme's linearity, and with it GMRES and the exact white
        // furnace). Voxel averages stay non-negative in every measured case; any that does
        // not is clamped to zero and reported.
        size_t clamped = 0;
        for (size_t x = 0; x < N; ++x)
            for (int c = 0; c < 3; ++c)
                if (res.sh[x * nc * 3 + c] < 0) {
                    res.sh[x * nc * 3 + c] = 0;
                    ++clamped;
                }
        if (clamped) {
            char buf[200];
            std::snprintf(buf, sizeof buf,
                          "warning: %zu negative band-0 values from the linear source clamped to zero", clamped);
            res.decisions.push_back(buf);
        }
    }
    res.unshot = res.passes.back().scattered;
    res.residual = res.injected > 0 ? res.unshot / res.injected : 0.0;
    {
        char buf[200];
        std::snprintf(buf, sizeof buf, "%s after %d passes: residual %.3g (tolerance %.3g)",
                      res.converged ? "converged" : "stopped at the order cap", int(res.passes.size()), res.residual,
                      s.tolerance);
        res.decisions.push_back(buf);
    }
    res.seconds = secondsSince(t0);
    return res;
}

LpmResult solveLpm(const Medium& m, const Lights& lights, const LpmSettings& s) {
    m.validate();
    if (s.deltaM < -1 || s.deltaM > 1) throw Error("LPM", "delta-M must be -1 (auto), 0 or 1, got " + std::to_string(s.deltaM));
    // Subdivision solves the refined medium through solveLpm again: delta-M is applied there.
    if (s.subdivide > 1 || s.deltaM == 0 || m.g <= 0) return solveImpl(m, lights, s, m.g);
    const bool grey = m.albedo.r == m.albedo.g && m.albedo.g == m.albedo.b;
    if (s.deltaM < 0 && !(m.g > s.deltaMAbove)) return solveImpl(m, lights, s, m.g);
    if (!grey) {
        // The scaled extinction sigma_t (1 - c f) would differ per channel; the sweeps share
        // one sigma_t for RGB.
        LpmResult r = solveImpl(m, lights, s, m.g);
        r.decisions.insert(r.decisions.begin(), "no delta-M: the albedo is not grey (the scaled extinction would "
                                                "differ per channel)");
        return r;
    }
    // Delta-M (Wiscombe 1977) with f = g^4: the forward peak's share f of the phase
    // function is treated as unscattered light (g^4 measured best of g^2, g^4, g^6 against
    // MC, docs/accuracy.md; g^2, the delta-Eddington choice, truncates too much of the
    // broad lobes at moderate g for 24 bins). Similarity transform:
    //   sigma_t' = sigma_t (1 - c f),  c' = c (1 - f) / (1 - c f),  g' = (g - f) / (1 - f)
    // keeps sigma_a (so absorption and emission are unchanged) and the transport
    // moments; the propagation then sees a moderate g' that its bins can resolve. S is
    // still that of the true phase function: its SH are g^l times those of the radiance.
    const double g = m.g, f = g * g * g * g, c = m.albedo.r;
    Medium sm = m;
    const float k = float(1 - c * f);
    for (float& sg : sm.sigmaT) sg *= k;
    sm.albedo = RGB(float(c * (1 - f) / (1 - c * f)));
    sm.g = (g - f) / (1 - f);
    LpmResult r = solveImpl(sm, lights, s, g);
    char buf[240];
    std::snprintf(buf, sizeof buf,
                  "delta-M forward-peak truncation (g = %.4g > %.3g): f = g^4 = %.4g of scattering treated as "
                  "unscattered; propagation with g' = %.4g, albedo %.4g, extinction x %.4g",
                  g, s.deltaM > 0 ? 0.0 : s.deltaMAbove, f, sm.g, double(sm.albedo.r), double(k));
    r.decisions.insert(r.decisions.begin(), buf);
    return r;
}

}  // namespace lpm

// The bake's self-check; the estimator is in verify.h, the reasoning in docs/verify.md.
#include "core/verify.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <string>

#include "core/error.h"
#include "core/mc_reference.h"
#include "core/parallel.h"
#include "core/rng.h"

namespace lpm {

void VerifySettings::validate() const {
    if (probes < 8 || probes > 1000000)
        throw SettingError("verify", "probes", "must be in 8..1000000, got " + std::to_string(probes));
    if (pathsPerProbe < 16 || pathsPerProbe > 100000000)
        throw SettingError("verify", "pathsPerProbe", "must be in 16..100000000, got " + std::to_string(pathsPerProbe));
    if (!(confidence >= 0.5 && confidence <= 0.999))
        throw SettingError("verify", "confidence", "must be in [0.5, 0.999], got " + std::to_string(confidence));
}

double studentT(double confidence, int dof) {
    // The normal quantile by bisection on erfc, then the Cornish-Fisher expansion in 1/dof
    // (Abramowitz and Stegun 26.7.5; within 1e-3 of the exact quantile for dof >= 7).
    const double tail = 1.0 - confidence;
    double lo = 0.0, hi = 10.0;
    for (int i = 0; i < 200; ++i) {
        const double mid = 0.5 * (lo + hi);
        (std::erfc(mid / std::sqrt(2.0)) > tail ? lo : hi) = mid;
    }
    const double z = 0.5 * (lo + hi), z2 = z * z, nu = std::max(1, dof);
    const double g1 = (z2 * z + z) / 4.0;
    const double g2 = (5 * z2 * z2 * z + 16 * z2 * z + 3 * z) / 96.0;
    const double g3 = (3 * z2 * z2 * z2 * z + 19 * z2 * z2 * z + 17 * z2 * z - 15 * z) / 384.0;
    return z + g1 / nu + g2 / (nu * nu) + g3 / (nu * nu * nu);
}

namespace {

/// Adds (e^-tau_before + e^-tau_after) / 6 to `t` for every stored voxel, along `axis`: the
/// lines of each column of tiles along the axis, walked through its stored tiles only.
void addAxisTransmittance(const Medium& m, int axis, std::vector<float>& t) {
    const int a = axis, b = (axis + 1) % 3, c = (axis + 2) % 3;
    const int K = Medium::kTile;
    const int na = m.dim(a), nb = m.dim(b), nc = m.dim(c);
    const int tb = (nb + K - 1) / K, tc = (nc + K - 1) / K;
    const double step = a == 0 ? m.voxelSize.x : (a == 1 ? m.voxelSize.y : m.voxelSize.z);
    parallelForChunks(size_t(tb) * tc, 1, [&](size_t begin, size_t end) {
        std::vector<size_t> line(static_cast<size_t>(na));
        for (size_t col = begin; col < end; ++col) {
            const int cb = int(col % size_t(tb)) * K, cc = int(col / size_t(tb)) * K;
            for (int lc = 0; lc < K && cc + lc < nc; ++lc)
                for (int lb = 0; lb < K && cb + lb < nb; ++lb) {
                    double total = 0.0;
                    for (int i = 0; i < na; ++i) {
                        int xyz[3];
                        xyz[a] = i, xyz[b] = cb + lb, xyz[c] = cc + lc;
                        line[size_t(i)] = m.index(xyz[0], xyz[1], xyz[2]);
                        if (line[size_t(i)] != Medium::npos) total += double(m.sigmaT[line[size_t(i)]]) * step;
                    }
                    double before = 0.0;
                    for (int i = 0; i < na; ++i) {
                        const size_t v = line[size_t(i)];
                        if (v == Medium::npos) continue;
                        const double tau = double(m.sigmaT[v]) * step;
                        const double mid = before + 0.5 * tau;
                        t[v] += float((std::exp(-mid) + std::exp(-(total - mid))) / 6.0);
                        before += tau;
                    }
                }
        }
    });
}

/// Draws `n` voxels with probability proportional to `w` (with replacement), ascending.
std::vector<size_t> drawVoxels(const std::vector<double>& w, double total, int n, std::uint64_t seed) {
    Pcg32 rng(seed, 0x7e51f1ULL);
    std::vector<double> u(static_cast<size_t>(n));
    for (double& x : u) x = rng.uniform() * total;
    std::sort(u.begin(), u.end());
    std::vector<size_t> out;
    out.reserve(u.size());
    double acc = 0.0;
    size_t v = 0, last = 0;
    for (const double target : u) {
        while (v < w.size() && acc + w[v] <= target) acc += w[v++];
        if (v < w.size()) last = v;  // else rounding ran past the end: the last voxel with weight
        while (last > 0 && w[last] == 0.0) --last;
        out.push_back(last);
    }
    return out;
}

/// The Monte Carlo band-0 estimates at `voxels` (which may repeat: the k-th repeat of a
/// voxel gets its own seed, so every probe is independent).
std::vector<McVoxelEstimate> probeEstimates(const Medium& m, const Lights& lights, const std::vector<size_t>& voxels,
                                            const VerifySettings& s) {
    std::vector<McVoxelEstimate> out(voxels.size());
    std::vector<int> round(voxels.size(), 0);
    for (size_t i = 1; i < voxels.size(); ++i)
        if (voxels[i] == voxels[i - 1]) round[i] = round[i - 1] + 1;
    for (int r = 0;; ++r) {
        std::vector<size_t> list, where;
        for (size_t i = 0; i < voxels.size(); ++i)
            if (round[i] == r) list.push_back(voxels[i]), where.push_back(i);
        if (list.empty()) break;
        McSettings mc;
        mc.seed = s.seed * 1000003ULL + std::uint64_t(r) + 1;
        std::vector<McVoxelEstimate> est = mcVoxelSH(m, lights, list, s.pathsPerProbe, 0, mc);
        for (size_t j = 0; j < list.size(); ++j) out[where[j]] = std::move(est[j]);
    }
    return out;
}

}  // namespace

std::vector<float> axisTransmittance(const Medium& medium) {
    std::vector<float> t(medium.voxelCount(), 0.0f);
    for (int axis = 0; axis < 3; ++axis) addAxisTransmittance(medium, axis, t);
    // Stored voxels of border tiles outside the block were never visited: nothing hides them.
    for (float& x : t)
        if (x == 0.0f) x = 1.0f;
    return t;
}

VerifyReport verifyBake(const Medium& m, const Lights& lights, const std::vector<float>& sh, int coeffs,
                        const VerifySettings& s) {
    s.validate();
    const auto start = std::chrono::steady_clock::now();
    const size_t count = m.voxelCount();
    if (coeffs < 1 || sh.size() != count * size_t(coeffs) * 3)
        throw Error("verify", "the SH result does not match the medium's voxels");
    VerifyReport rep;
    rep.confidence = s.confidence;
    rep.pathsPerProbe = s.pathsPerProbe;

    std::vector<double> w(count, 0.0);
    {
        const std::vector<float> tOut = axisTransmittance(m);
        for (size_t v = 0; v < count; ++v) {
            const float* S = &sh[v * size_t(coeffs) * 3];
            const double seen = m.albedo.r * S[0] + m.albedo.g * S[1] + m.albedo.b * S[2];
            w[v] = seen > 0.0 ? double(tOut[v]) * m.sigmaT[v] * seen : 0.0;
        }
    }
    double total = 0.0;
    for (const double x : w) total += x;
    if (!(total > 0.0) || !std::isfinite(total)) return rep;

    const std::vector<size_t> voxels = drawVoxels(w, total, s.probes, s.seed);
    const std::vector<McVoxelEstimate> est = probeEstimates(m, lights, voxels, s);
    double sum = 0.0, sumSq = 0.0, noise = 0.0;
    for (size_t i = 0; i < voxels.size(); ++i) {
        const float* S = &sh[voxels[i] * size_t(coeffs) * 3];
        VerifyProbe p;
        p.voxel = voxels[i];
        p.bake = (double(S[0]) + S[1] + S[2]) / 3.0;
        p.mc = (est[i].mean[0] + est[i].mean[1] + est[i].mean[2]) / 3.0;
        double term = 0.0, var = 0.0;
        for (int c = 0; c < 3; ++c) {
            const double d = double(S[c]) - est[i].mean[size_t(c)], se = est[i].stdErr[size_t(c)];
            term += d * d - se * se;
            var += se * se;
        }
        p.term = term / (3.0 * p.bake * p.bake);
        noise += var / (3.0 * p.bake * p.bake);
        sum += p.term;
        sumSq += p.term * p.term;
        rep.probeList.push_back(p);
    }
    const double n = double(voxels.size());
    const double mean = sum / n, sd = std::sqrt(std::max(0.0, (sumSq - n * mean * mean) / (n - 1.0)));
    const double half = studentT(s.confidence, int(n) - 1) * sd / std::sqrt(n);
    rep.probes = int(voxels.size());
    rep.error = std::sqrt(std::max(0.0, mean));
    rep.low = std::sqrt(std::max(0.0, mean - half));
    rep.high = std::sqrt(std::max(0.0, mean + half));
    rep.mcNoise = std::sqrt(noise / n);
    rep.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return rep;
}

}  // namespace lpm

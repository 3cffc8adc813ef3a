// Environment binning (env_binning.h).
#include "core/env_binning.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "core/parallel.h"

namespace lpm {

std::vector<Sun> mergeHotPixels(const std::vector<EnvHotPixel>& hot, int width) {
    // Union-find over at most 16 pixels: neighbours (8-connected, wrapping in longitude).
    std::vector<size_t> group(hot.size());
    for (size_t i = 0; i < hot.size(); ++i) group[i] = i;
    auto root = [&](size_t i) {
        while (group[i] != i) i = group[i];
        return i;
    };
    for (size_t i = 0; i < hot.size(); ++i)
        for (size_t j = i + 1; j < hot.size(); ++j) {
            const int dx = std::abs(hot[i].x - hot[j].x), dy = std::abs(hot[i].y - hot[j].y);
            if (dy <= 1 && (dx <= 1 || dx == width - 1)) group[root(j)] = root(i);
        }
    std::vector<Sun> suns;
    for (size_t g = 0; g < hot.size(); ++g) {
        if (root(g) != g) continue;
        Vec3 mean{0, 0, 0};
        RGB irradiance(0.f);
        double omega = 0;
        for (size_t i = 0; i < hot.size(); ++i) {
            if (root(i) != g) continue;
            const RGB e = hot[i].radiance * float(hot[i].omega);
            mean = mean + hot[i].toward * double(e.r + e.g + e.b);
            irradiance = irradiance + e;
            omega += hot[i].omega;
        }
        mean = normalize(mean);
        // A disc of the group's solid angle, widened to reach its farthest pixel centre.
        double half = std::acos(std::max(-1.0, 1 - omega / (2 * kPi)));
        for (size_t i = 0; i < hot.size(); ++i)
            if (root(i) == g) half = std::max(half, std::acos(std::clamp(dot(mean, hot[i].toward), -1.0, 1.0)));
        suns.push_back({mean, irradiance, 2 * half * 180.0 / kPi});
    }
    return suns;
}

EnvBinning binEnvironment(const EnvMap& env, const CubeQuadrature& quad, const Mat3& Rinv, double hotShare) {
    const int nd = quad.count();
    EnvBinning out;
    out.radiance.assign(nd, RGB(0.f));
    // Sub-pixels fine enough that each direction bin gets >= ~1024 of them; each bin's
    // radiance is the solid-angle-weighted mean over the sub-pixels it received, so a
    // constant environment gives exactly constant bins and a one-pixel hot spot lands
    // in the bin that contains it.
    const double pixels = double(env.width()) * env.height();
    const int sub = std::clamp(int(std::ceil(std::sqrt(1024.0 * nd / pixels))), 1, 256);
    // Hot pixels: binned, their light would travel along the bin's directions, up to half
    // a bin off, and cast shifted shadows (ray effects). Only pixels well inside one
    // direction bin (a quarter of its solid angle) qualify: a larger pixel is resolved by
    // the bins as well as by a disc.
    std::vector<unsigned char> skip;
    if (hotShare > 0) {
        std::vector<EnvHotPixel> hot = env.hotPixels(hotShare, 16);
        const double maxOmega = 0.25 * kFourPi / nd;
        hot.erase(std::remove_if(hot.begin(), hot.end(), [&](const EnvHotPixel& h) { return h.omega > maxOmega; }),
                  hot.end());
        for (const EnvHotPixel& h : hot) {
            if (skip.empty()) skip.assign(size_t(env.width()) * env.height(), 0);
            skip[size_t(h.y) * env.width() + h.x] = 1;
            out.hotShare += h.share;
        }
        out.hotSuns = mergeHotPixels(hot, env.width());
    }
    // Sub-pixel rows in blocks of kRowsPerBlock, each block summed on its own over the
    // threads, the blocks' sums added in block order: the same bins for any thread count.
    constexpr int kRowsPerBlock = 16;
    const int rows = env.height() * sub;
    const int blocks = (rows + kRowsPerBlock - 1) / kRowsPerBlock;
    std::vector<double> blockAcc(size_t(blocks) * size_t(nd) * 4, 0.0);
    parallelForChunks(size_t(blocks), 1, [&](size_t bb, size_t be) {
        for (size_t b = bb; b < be; ++b) {
            double* acc = &blockAcc[b * size_t(nd) * 4];
            const int y0 = int(b) * kRowsPerBlock;
            env.forEachSubPixelInRows(
                sub, y0, y0 + kRowsPerBlock,
                [&](const Vec3& toward, double omega, const RGB& L) {
                    const int i = quad.indexOf(Rinv * (-toward));
                    for (int c = 0; c < 3; ++c) acc[size_t(i) * 4 + c] += L[c] * omega;
                    acc[size_t(i) * 4 + 3] += omega;
                },
                skip.empty() ? nullptr : &skip);
        }
    });
    std::vector<double> acc(size_t(nd) * 4, 0.0);
    for (int b = 0; b < blocks; ++b)
        for (size_t k = 0; k < acc.size(); ++k) acc[k] += blockAcc[size_t(b) * acc.size() + k];
    for (int i = 0; i < nd; ++i) {
        const double om = acc[size_t(i) * 4 + 3];
        for (int c = 0; c < 3; ++c) out.radiance[i][c] = om > 0 ? float(acc[size_t(i) * 4 + c] / om) : 0.0f;
    }
    return out;
}

}  // namespace lpm

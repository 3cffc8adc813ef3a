// Multi-resolution transfer for the higher scattering orders: see multires.h and
// docs/multires.md.
#include "core/multires.h"

#include <cmath>
#include <string>

#include "core/error.h"
#include "core/malloc_policy.h"
#include "core/parallel.h"

namespace lpm {

Medium coarsen(const Medium& f) {
    Medium c;
    c.voxelSize = f.voxelSize * 2.0;
    c.albedo = f.albedo;
    c.g = f.g;
    c.localToWorld = f.localToWorld;
    c.origin = f.origin;
    const int cx = (f.nx + 1) / 2, cy = (f.ny + 1) / 2, cz = (f.nz + 1) / 2;
    if (f.sparse()) {
        Medium probe;
        probe.nx = cx;
        probe.ny = cy;
        probe.nz = cz;
        const int tx = probe.tilesX(), ty = probe.tilesY(), tz = probe.tilesZ();
        std::vector<std::uint8_t> active(size_t(tx) * ty * tz, 0);
        for (int z = 0; z < f.tilesZ(); ++z)
            for (int y = 0; y < f.tilesY(); ++y)
                for (int x = 0; x < f.tilesX(); ++x)
                    if (f.tileSlot[size_t(x) + size_t(f.tilesX()) * (size_t(y) + size_t(f.tilesY()) * z)] >= 0)
                        active[size_t(x / 2) + size_t(tx) * (size_t(y / 2) + size_t(ty) * (z / 2))] = 1;
        c.allocate(cx, cy, cz, &active);
    } else {
        c.allocate(cx, cy, cz);
    }
    parallelForChunks(size_t(cz), 1, [&](size_t zb, size_t ze) {
        for (int z = int(zb); z < int(ze); ++z)
            for (int y = 0; y < cy; ++y)
                for (int x = 0; x < cx; ++x) {
                    const size_t ci = c.index(x, y, z);
                    if (ci == Medium::npos) continue;
                    double sum = 0;
                    for (int k = 0; k < 8; ++k) {
                        const int fx = 2 * x + (k & 1), fy = 2 * y + ((k >> 1) & 1), fz = 2 * z + (k >> 2);
                        if (fx >= f.nx || fy >= f.ny || fz >= f.nz) continue;
                        const size_t fi = f.index(fx, fy, fz);
                        if (fi != Medium::npos) sum += f.sigmaT[fi];
                    }
                    c.sigmaT[ci] = float(sum / 8);
                }
    });
    return c;
}

std::vector<float> restrictSource(const Medium& f, const Medium& c, const std::vector<float>& src, int bins,
                                  int moments) {
    const size_t per = size_t(bins) * 3;
    std::vector<float> out;
    assignZeroed(out, c.voxelCount() * per);
    parallelForChunks(size_t(c.nz), 1, [&](size_t zb, size_t ze) {
        std::vector<double> acc(per);
        for (int z = int(zb); z < int(ze); ++z)
            for (int y = 0; y < c.ny; ++y)
                for (int x = 0; x < c.nx; ++x) {
                    const size_t ci = c.index(x, y, z);
                    if (ci == Medium::npos) continue;
                    std::fill(acc.begin(), acc.end(), 0.0);
                    double sigma = 0;
                    for (int k = 0; k < 8; ++k) {
                        const int fx = 2 * x + (k & 1), fy = 2 * y + ((k >> 1) & 1), fz = 2 * z + (k >> 2);
                        if (fx >= f.nx || fy >= f.ny || fz >= f.nz) continue;
                        const size_t fi = f.index(fx, fy, fz);
                        if (fi == Medium::npos || f.sigmaT[fi] <= 0) continue;
                        const double s = f.sigmaT[fi];
                        sigma += s;
                        for (int d = 0; d < bins; ++d)
                            for (int ch = 0; ch < 3; ++ch)
                                acc[size_t(d) * 3 + ch] += s * src[(fi * bins + d) * size_t(moments) * 3 + ch];
                    }
                    if (sigma <= 0) continue;
                    for (size_t i = 0; i < per; ++i) out[ci * per + i] = float(acc[i] / sigma);
                }
    });
    return out;
}

namespace {

/// out's means = (accumulate ? out's means : 0) + scale * each fine voxel's coarse parent
/// value (times the voxel's weight in `shape`, when given).
void applyCoarse(const Medium& f, const Medium& c, const std::vector<float>& coarseSource, int bins, int moments,
                 bool accumulate, float scale, std::vector<float>& out, const std::vector<float>* shape = nullptr) {
    parallelForChunks(f.voxelCount(), 4096, [&](size_t vb, size_t ve) {
        for (size_t v = vb; v < ve; ++v) {
            int x, y, z;
            f.coord(v, x, y, z);
            const bool inside = x >= 0 && x < f.nx && y < f.ny && z < f.nz;
            const size_t cv = inside ? c.index(x / 2, y / 2, z / 2) : Medium::npos;
            const float weight = shape ? scale * (*shape)[v] : scale;
            for (int d = 0; d < bins; ++d)
                for (int ch = 0; ch < 3; ++ch) {
                    float& o = out[(v * bins + d) * size_t(moments) * 3 + ch];
                    const float p = cv == Medium::npos ? 0.0f : coarseSource[(cv * bins + d) * 3 + ch];
                    o = accumulate ? o + weight * p : p;
                }
        }
    });
}

}  // namespace

void injectCoarse(const Medium& f, const Medium& c, const std::vector<float>& coarseSource, int bins, int moments,
                  std::vector<float>& out) {
    applyCoarse(f, c, coarseSource, bins, moments, false, 1.0f, out);
}

void addCoarse(const Medium& f, const Medium& c, const std::vector<float>& coarseSource, int bins, int moments,
               float scale, std::vector<float>& out, const std::vector<float>* shape) {
    if (shape && shape->size() != f.voxelCount())
        throw Error("addCoarse", "the shape holds " + std::to_string(shape->size()) + " weights for " +
                                     std::to_string(f.voxelCount()) + " fine voxels");
    applyCoarse(f, c, coarseSource, bins, moments, true, scale, out, shape);
}

}  // namespace lpm

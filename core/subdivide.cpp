// Subdivided solves (core/subdivide.h).
#include "core/subdivide.h"

#include <algorithm>
#include <cstdint>

#include "core/parallel.h"

namespace lpm {

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
                    const size_t ct =
                        size_t(tx / k) + size_t(m.tilesX()) * (size_t(ty / k) + size_t(m.tilesY()) * (tz / k));
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

std::vector<float> averageBack(const Medium& m, const Medium& fm, int k, const std::vector<float>& fine, size_t width) {
    std::vector<float> out(m.voxelCount() * width, 0.0f);
    parallelForChunks(size_t(m.nz), 1, [&](size_t zb, size_t ze) {
        std::vector<double> acc(width);
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
                                for (size_t i = 0; i < width; ++i) acc[i] += fine[fv * width + i];
                            }
                    for (size_t i = 0; i < width; ++i) out[v * width + i] = float(acc[i] / (k * k * k));
                }
    });
    return out;
}

}  // namespace lpm

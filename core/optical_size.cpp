#include "core/optical_size.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "core/parallel.h"

namespace lpm {
namespace {

/// Row depths of the block along one axis, indexed by the other two coordinates.
struct RowDepths {
    int axis = 0, n0 = 0;  ///< n0: the block's extent along the first of the other two axes
    std::vector<float> tau;

    size_t row(int x, int y, int z) const {
        const int c[3] = {x, y, z};
        const int a = c[(axis + 1) % 3], b = c[(axis + 2) % 3];
        return size_t(a) + size_t(n0) * size_t(b);
    }
};

/// Units of storage visited in parallel: the stored 8^3 tiles of a sparse block, the z
/// slices of a dense one.
size_t unitCount(const Medium& m) { return m.sparse() ? m.storedTiles : size_t(m.nz); }

/// f(v, x, y, z) for each stored voxel of unit u inside the block (a border tile's fringe
/// lies outside), in storage order.
template <typename F>
void forEachVoxelOfUnit(const Medium& m, size_t u, F&& f) {
    if (!m.sparse()) {
        const int z = int(u);
        for (int y = 0; y < m.ny; ++y)
            for (int x = 0; x < m.nx; ++x) f(m.index(x, y, z), x, y, z);
        return;
    }
    const int k = Medium::kTile;
    const size_t t = size_t(m.slotTile[u]);
    const int x0 = int(t % m.tilesX()) * k, y0 = int((t / m.tilesX()) % m.tilesY()) * k,
              z0 = int(t / (size_t(m.tilesX()) * m.tilesY())) * k;
    size_t v = u * Medium::kTileVoxels;
    for (int z = z0; z < z0 + k; ++z)
        for (int y = y0; y < y0 + k; ++y)
            for (int x = x0; x < x0 + k; ++x, ++v)
                if (x < m.nx && y < m.ny && z < m.nz) f(v, x, y, z);
}

}  // namespace

double opticalSize(const Medium& m) {
    const double edge[3] = {m.voxelSize.x, m.voxelSize.y, m.voxelSize.z};
    RowDepths rows[3];
    for (int a = 0; a < 3; ++a) {
        rows[a].axis = a;
        rows[a].n0 = m.dim((a + 1) % 3);
        rows[a].tau.assign(size_t(m.dim((a + 1) % 3)) * size_t(m.dim((a + 2) % 3)), 0.0f);
    }
    const size_t units = unitCount(m);
    parallelForChunks(3, 1, [&](size_t a, size_t) {  // one axis a task: each row summed in storage order
        RowDepths& r = rows[a];
        const float e = float(edge[a]);
        for (size_t u = 0; u < units; ++u)
            forEachVoxelOfUnit(m, u, [&](size_t v, int x, int y, int z) {
                if (m.sigmaT[v] > 0) r.tau[r.row(x, y, z)] += m.sigmaT[v] * e;
            });
    });
    const size_t grain = 64;
    std::vector<double> leastLeak((units + grain - 1) / grain, std::numeric_limits<double>::infinity());
    parallelForChunks(units, grain, [&](size_t begin, size_t end) {
        double& least = leastLeak[begin / grain];
        for (size_t u = begin; u < end; ++u)
            forEachVoxelOfUnit(m, u, [&](size_t v, int x, int y, int z) {
                if (!(m.sigmaT[v] > 0)) return;
                double leak = 0;
                for (const RowDepths& r : rows) {
                    const double t = r.tau[r.row(x, y, z)];
                    leak += 1.0 / (t * t);
                }
                least = std::min(least, leak);
            });
    });
    const double least = leastLeak.empty() ? std::numeric_limits<double>::infinity()
                                           : *std::min_element(leastLeak.begin(), leastLeak.end());
    return std::isinf(least) ? 0.0 : std::sqrt(3.0 / least);
}

}  // namespace lpm

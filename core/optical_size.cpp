#include "core/optical_size.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

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

template <typename F>
void forEachVoxelInBlock(const Medium& m, F&& f) {
    const size_t n = m.voxelCount();
    for (size_t v = 0; v < n; ++v) {
        int x, y, z;
        m.coord(v, x, y, z);
        if (x < 0 || y < 0 || z < 0 || x >= m.nx || y >= m.ny || z >= m.nz) continue;  // a border tile's fringe
        f(v, x, y, z);
    }
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
    forEachVoxelInBlock(m, [&](size_t v, int x, int y, int z) {
        const float s = m.sigmaT[v];
        if (!(s > 0)) return;
        for (int a = 0; a < 3; ++a) rows[a].tau[rows[a].row(x, y, z)] += float(s * edge[a]);
    });
    double leastLeak = std::numeric_limits<double>::infinity();
    forEachVoxelInBlock(m, [&](size_t v, int x, int y, int z) {
        if (!(m.sigmaT[v] > 0)) return;
        double leak = 0;
        for (const RowDepths& r : rows) {
            const double t = r.tau[r.row(x, y, z)];
            leak += 1.0 / (t * t);
        }
        leastLeak = std::min(leastLeak, leak);
    });
    return leastLeak == std::numeric_limits<double>::infinity() ? 0.0 : std::sqrt(3.0 / leastLeak);
}

}  // namespace lpm

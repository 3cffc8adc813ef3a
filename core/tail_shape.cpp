// Weights that shape the two-grid tail inside each coarse voxel (core/tail_shape.h).
#include "core/tail_shape.h"

#include <algorithm>

#include "core/error.h"
#include "core/parallel.h"

namespace lpm {

std::vector<std::uint32_t> coarseParents(const Medium& fine, const Medium& coarse) {
    std::vector<std::uint32_t> parent(fine.voxelCount(), kNoParent);
    parallelForChunks(fine.voxelCount(), 4096, [&](size_t vb, size_t ve) {
        for (size_t v = vb; v < ve; ++v) {
            int x, y, z;
            fine.coord(v, x, y, z);
            if (x < 0 || y < 0 || z < 0 || x >= fine.nx || y >= fine.ny || z >= fine.nz) continue;
            const size_t c = coarse.index(x / 2, y / 2, z / 2);
            if (c != Medium::npos) parent[v] = std::uint32_t(c);
        }
    });
    return parent;
}

std::vector<float> tailShape(const std::vector<float>& sigmaT, const std::vector<std::uint32_t>& parent, size_t parents,
                             const std::vector<float>& strength) {
    if (parent.size() != sigmaT.size() || strength.size() != sigmaT.size())
        throw Error("tailShape", "parents (" + std::to_string(parent.size()) + ") and strengths (" +
                                     std::to_string(strength.size()) + ") must be given for each of the " +
                                     std::to_string(sigmaT.size()) + " fine voxels");
    // Sums per parent in fine-voxel order (one pass, serial: the same sums for any thread
    // count; about 5 ms for 1.5M voxels, once a bake).
    std::vector<double> mass(parents, 0.0), weighted(parents, 0.0);
    for (size_t f = 0; f < sigmaT.size(); ++f) {
        const std::uint32_t p = parent[f];
        if (p == kNoParent) continue;
        if (p >= parents)
            throw Error("tailShape", "parent index " + std::to_string(p) + " >= " + std::to_string(parents));
        mass[p] += sigmaT[f];
        weighted[p] += double(sigmaT[f]) * std::max(0.0f, strength[f]);
    }
    std::vector<float> w(sigmaT.size(), 1.0f);
    parallelForChunks(sigmaT.size(), 4096, [&](size_t fb, size_t fe) {
        for (size_t f = fb; f < fe; ++f) {
            const std::uint32_t p = parent[f];
            if (p != kNoParent && weighted[p] > 0)
                w[f] = float(double(std::max(0.0f, strength[f])) * mass[p] / weighted[p]);
        }
    });
    return w;
}

}  // namespace lpm

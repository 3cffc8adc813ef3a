// Rows of the voxels with mass (core/mass_rows.h).
#include "core/mass_rows.h"

#include "core/malloc_policy.h"
#include "core/parallel.h"

namespace lpm {

MassRows::MassRows(const Medium& m) : rowOf(m.voxelCount(), kNone) {
    for (size_t v = 0; v < m.sigmaT.size(); ++v)
        if (m.sigmaT[v] > 0) {
            rowOf[v] = std::uint32_t(voxel.size());
            voxel.push_back(std::uint32_t(v));
        }
}

std::vector<float> expandRows(const MassRows& rows, const std::vector<float>& x, size_t width) {
    std::vector<float> out;
    assignZeroed(out, rows.rowOf.size() * width);
    parallelForChunks(rows.size(), 1 << 12, [&](size_t b, size_t e) {
        for (size_t row = b; row < e; ++row)
            for (size_t i = 0; i < width; ++i) out[size_t(rows.voxel[row]) * width + i] = x[row * width + i];
    });
    return out;
}

std::vector<float> gatherRows(const MassRows& rows, const std::vector<float>& x, size_t width) {
    std::vector<float> out;
    assignZeroed(out, rows.size() * width);
    parallelForChunks(rows.size(), 1 << 12, [&](size_t b, size_t e) {
        for (size_t row = b; row < e; ++row)
            for (size_t i = 0; i < width; ++i) out[row * width + i] = x[size_t(rows.voxel[row]) * width + i];
    });
    return out;
}

}  // namespace lpm

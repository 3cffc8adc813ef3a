// The SH result's rows (core/sh_rows.h).
#include "core/sh_rows.h"

#include <cstring>

#include "core/error.h"
#include "core/malloc_policy.h"
#include "core/parallel.h"

namespace lpm {

ShRows::ShRows(const Medium& m, int coeffs) : voxels_(m.voxelCount()), count_(m.voxelCount()) {
    if (coeffs <= 1 || m.wantedS.empty() || voxels_ >= size_t(kNone)) return;
    if (m.wantedS.size() != voxels_)
        throw Error("ShRows", "wantedS has " + std::to_string(m.wantedS.size()) + " flags for " +
                                  std::to_string(voxels_) + " voxels");
    size_t wanted = 0;
    for (std::uint8_t w : m.wantedS) wanted += w != 0;
    if (wanted == voxels_) return;
    row_.resize(voxels_);
    std::uint32_t next = 0;
    for (size_t v = 0; v < voxels_; ++v) row_[v] = m.wantedS[v] ? next++ : kNone;
    count_ = wanted;
}

void ShRows::expand(std::vector<float>& sh, int coeffs) const {
    if (!compact()) return;
    const size_t width = size_t(coeffs) * 3;
    if (sh.size() != count_ * width)
        throw Error("ShRows", "the SH result has " + std::to_string(sh.size()) + " floats for " +
                                  std::to_string(count_) + " rows of " + std::to_string(width));
    // Into new storage, faulted in and filled by all the threads (in place, from the last
    // row down, one thread would fault 2 MiB pages in for 0.1-0.2 s on the 1M plume); the
    // end of a solve is far below its peak, so both copies fit.
    std::vector<float> full;
    assignZeroed(full, voxels_ * width);
    parallelForChunks(voxels_, 4096, [&](size_t b, size_t e) {
        for (size_t v = b; v < e; ++v)
            if (row_[v] != kNone) std::memcpy(&full[v * width], &sh[size_t(row_[v]) * width], width * sizeof(float));
    });
    sh.swap(full);
}

}  // namespace lpm

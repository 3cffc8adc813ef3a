// The SH result's rows (core/sh_rows.h).
#include "core/sh_rows.h"

#include <algorithm>
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
    expandShRows(sh, row_, coeffs);
}

void expandShRows(std::vector<float>& sh, const std::vector<std::uint32_t>& row, int coeffs) {
    if (row.empty()) return;
    const size_t width = size_t(coeffs) * 3, voxels = row.size();
    size_t held = 0;  // one more than the largest row held
    for (std::uint32_t r : row)
        if (r != ShRows::kNone) held = std::max(held, size_t(r) + 1);
    if (held * width > sh.size())
        throw Error("ShRows", "row " + std::to_string(held - 1) + " is beyond the SH result's " +
                                  std::to_string(sh.size() / width) + " rows");
    // Into new storage, faulted in and filled by all the threads (in place, from the last
    // row down, one thread would fault 2 MiB pages in for 0.1-0.2 s on the 1M plume); the
    // end of a solve is far below its peak, so both copies fit.
    std::vector<float> full;
    assignZeroed(full, voxels * width);
    parallelForChunks(voxels, 4096, [&](size_t b, size_t e) {
        for (size_t v = b; v < e; ++v)
            if (row[v] != ShRows::kNone)
                std::memcpy(&full[v * width], &sh[size_t(row[v]) * width], width * sizeof(float));
    });
    sh.swap(full);
}

}  // namespace lpm

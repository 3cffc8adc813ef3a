// A propagation pass of a half-precision source (core/half_source_pass.h).
#include "core/half_source_pass.h"

#include <algorithm>

#include "core/malloc_policy.h"
#include "core/parallel.h"

namespace lpm {

void propagateHalfSource(const PassRunner& runner, const JobFactory& factory, const HalfBuffer& v, int bins,
                         const RGB& albedo, int r, std::vector<std::vector<float>>& slots, Tally& total,
                         std::vector<float>& out) {
    const size_t rowLength = size_t(bins) * 3, voxels = v.size() / rowLength, batch = slots.size();
    for (std::vector<float>& slot : slots)
        if (slot.size() != voxels * 3) assignZeroed(slot, voxels * 3);
    std::vector<int> jobBin;
    const std::vector<Job> jobs = factory.slotJobs(slots, albedo, jobBin);
    // A batch's bins in one pass over v: each voxel's row (bins x 6 bytes) read once for
    // all of them, not once per job (one bin of a row is 6 of its 144 bytes at 24 bins, so
    // a pass per job streamed the whole vector each time: 6.7% of a cumulus bake).
    const auto decodeBatch = [&](size_t b) {
        const size_t j0 = b * batch, j1 = std::min(jobs.size(), (b + 1) * batch);
        parallelForChunks(voxels, 1 << 12, [&](size_t x0, size_t x1) {
            for (size_t j = j0; j < j1; ++j) {
                float* slot = slots[j % batch].data();
                const size_t first = size_t(jobBin[j]) * 3;
                for (size_t x = x0; x < x1; ++x)
                    for (size_t c = 0; c < 3; ++c) slot[x * 3 + c] = v.at(x * rowLength + first + c);
            }
        });
    };
    runner.runFilled(jobs, batch, r, total, decodeBatch, false, out);
}

}  // namespace lpm

// Propagation passes of sources held otherwise than the sweeps read them
// (core/half_source_pass.h).
#include "core/half_source_pass.h"

#include <algorithm>

#include "core/malloc_policy.h"
#include "core/parallel.h"

namespace lpm {

namespace {

/// The slot pass of a source whose voxel x has element i ([bin][rgb]) of its row at
/// value(x, i), over `voxels` voxels.
template <class Value>
void propagateSlots(const PassRunner& runner, const JobFactory& factory, size_t voxels, const RGB& albedo, int r,
                    std::vector<std::vector<float>>& slots, Tally& total, std::vector<float>& out, const Value& value) {
    const size_t batch = slots.size();
    for (std::vector<float>& slot : slots)
        if (slot.size() != voxels * 3) assignZeroed(slot, voxels * 3);
    std::vector<int> jobBin;
    const std::vector<Job> jobs = factory.slotJobs(slots, albedo, jobBin);
    // A batch's bins in one pass over v: each voxel's row (bins x 6 bytes in half) read
    // once for all of them, not once per job (one bin of a row is 6 of its 144 bytes at 24
    // bins, so a pass per job streamed the whole vector each time: 6.7% of a cumulus bake).
    const auto fillBatch = [&](size_t b) {
        const size_t j0 = b * batch, j1 = std::min(jobs.size(), (b + 1) * batch);
        parallelForChunks(voxels, 1 << 12, [&](size_t x0, size_t x1) {
            for (size_t j = j0; j < j1; ++j) {
                float* slot = slots[j % batch].data();
                const size_t first = size_t(jobBin[j]) * 3;
                for (size_t x = x0; x < x1; ++x)
                    for (size_t c = 0; c < 3; ++c) slot[x * 3 + c] = value(x, first + c);
            }
        });
    };
    runner.runFilled(jobs, batch, r, total, fillBatch, false, out);
}

}  // namespace

void propagateHalfSource(const PassRunner& runner, const JobFactory& factory, const HalfBuffer& v, int bins,
                         const RGB& albedo, int r, std::vector<std::vector<float>>& slots, Tally& total,
                         std::vector<float>& out, const MassRows* rows) {
    const size_t rowLength = size_t(bins) * 3;
    if (!rows) {
        propagateSlots(runner, factory, v.size() / rowLength, albedo, r, slots, total, out,
                       [&](size_t x, size_t i) { return v.at(x * rowLength + i); });
        return;
    }
    const std::uint32_t* rowOf = rows->rowOf.data();
    propagateSlots(runner, factory, rows->rowOf.size(), albedo, r, slots, total, out, [&](size_t x, size_t i) {
        return rowOf[x] == MassRows::kNone ? 0.0f : v.at(size_t(rowOf[x]) * rowLength + i);
    });
}

void propagateRowSource(const PassRunner& runner, const JobFactory& factory, const std::vector<float>& v, int bins,
                        const RGB& albedo, int r, std::vector<std::vector<float>>& slots, const MassRows& rows,
                        Tally& total, std::vector<float>& out) {
    const size_t rowLength = size_t(bins) * 3;
    const std::uint32_t* rowOf = rows.rowOf.data();
    propagateSlots(runner, factory, rows.rowOf.size(), albedo, r, slots, total, out, [&](size_t x, size_t i) {
        return rowOf[x] == MassRows::kNone ? 0.0f : v[size_t(rowOf[x]) * rowLength + i];
    });
}

}  // namespace lpm

// A propagation pass whose source is held in half precision (core/half_buffer.h): GMRES's
// Krylov vectors on a two-grid solve's coarse grid (core/krylov_pass.cpp). The pass never
// forms the source in float: each batch of jobs reads its bins from float slots, decoded
// just before the batch is swept.
#pragma once

#include <vector>

#include "core/half_buffer.h"
#include "core/job_factory.h"
#include "core/pass_runner.h"

namespace lpm {

/// Sweeps of the voxel-constant source `v` ([voxel][bin][rgb], `bins` bins) with r rays per
/// voxel: the jobs of factory.sourceJobs, in its order, in batches of slots.size() (the
/// slots, [voxel][rgb] each, are sized here and may be kept from call to call). Deposits
/// go to `out` ([voxel][bin][rgb]), tallies to `total`, no SH. The same sums in the same
/// order as runner.run(factory.sourceJobs(v decoded), ...): bit for bit that result.
void propagateHalfSource(const PassRunner& runner, const JobFactory& factory, const HalfBuffer& v, int bins,
                         const RGB& albedo, int r, std::vector<std::vector<float>>& slots, Tally& total,
                         std::vector<float>& out);

}  // namespace lpm

// Propagation passes whose source is not held as the sweeps read it ([voxel][bin][rgb] in
// float): GMRES's Krylov vectors in half precision (core/half_buffer.h) on a two-grid
// solve's coarse grid (core/krylov_pass.cpp), and the coarse solve's sources held by rows
// with mass (core/mass_rows.h). The pass never forms the source in float per voxel: each
// batch of jobs reads its bins from float slots ([voxel][rgb]), filled just before the
// batch is swept.
#pragma once

#include <vector>

#include "core/half_buffer.h"
#include "core/job_factory.h"
#include "core/mass_rows.h"
#include "core/pass_runner.h"

namespace lpm {

/// Sweeps of the voxel-constant source `v` ([row][bin][rgb], `bins` bins; a voxel's row is
/// rows->rowOf[voxel], or the voxel when rows is null, and a voxel without one has no
/// source) with r rays per voxel: the jobs of factory.sourceJobs, in its order, in batches
/// of slots.size() (the slots, [voxel][rgb] each, are sized here and may be kept from call
/// to call). Deposits go to `out` (as the runner folds them), tallies to `total`, no SH.
/// The same sums in the same order as runner.run(factory.sourceJobs(v decoded and
/// expanded), ...): bit for bit that result.
void propagateHalfSource(const PassRunner& runner, const JobFactory& factory, const HalfBuffer& v, int bins,
                         const RGB& albedo, int r, std::vector<std::vector<float>>& slots, Tally& total,
                         std::vector<float>& out, const MassRows* rows = nullptr);

/// The same for a source `v` in float held by `rows`.
void propagateRowSource(const PassRunner& runner, const JobFactory& factory, const std::vector<float>& v, int bins,
                        const RGB& albedo, int r, std::vector<std::vector<float>>& slots, const MassRows& rows,
                        Tally& total, std::vector<float>& out);

}  // namespace lpm

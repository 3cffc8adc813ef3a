// Solving on voxels split k x k x k (LpmSettings::subdivide): the same piecewise-constant
// medium on a finer grid, for optically thick voxels where a voxel-constant source leaks
// light; the result is averaged back over each voxel (the voxel average of S is what the
// result means at any resolution).
#pragma once

#include <vector>

#include "core/medium.h"

namespace lpm {

/// Every voxel of `m` split into k^3 copies of itself (sparsity kept: a fine tile is
/// stored when its coarse tile is).
Medium subdivided(const Medium& m, int k);

/// Per-voxel values ([voxel][width]) of the k-fold subdivided medium `fm`, averaged back
/// onto `m`'s voxels.
std::vector<float> averageBack(const Medium& m, const Medium& fm, int k, const std::vector<float>& fine,
                               size_t width = 1);

}  // namespace lpm

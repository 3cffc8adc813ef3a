// The shape of the two-grid cycle's coarse tail inside each coarse voxel (docs/multires.md,
// "Shaped tail"). The cycle sums the higher orders on the coarse grid and brings that tail
// back to the fine voxels. Brought back flat (each child its parent's value), it gives the
// dim, deep children of a thick coarse voxel the mean of its lit ones: on a smoke whose
// coarse voxels reach optical depth 5 the voxels' own band-0 error against Monte Carlo was
// 24% (60% on a thick plume), where the full-resolution solve gives 4%. Shaped, the tail
// is spread over the children in proportion to the first residual they hold (the source
// the coarse grid first distributes, the light of the second order):
//     w_f = s_f sum_{f' in C} sigma_f' / sum_{f' in C} sigma_f' s_f'      (s_f >= 0)
// so sum_C sigma_f w_f = sum_C sigma_f: the tail's restriction is still the coarse value,
// and no power moves between coarse voxels. A parent whose children hold no source keeps
// the flat tail (w = 1).
#pragma once

#include <cstdint>
#include <vector>

#include "core/medium.h"

namespace lpm {

/// Marks a fine voxel without a coarse parent (outside the block, or under a coarse voxel
/// that is not stored or holds no mass).
constexpr std::uint32_t kNoParent = ~std::uint32_t(0);

/// The coarse medium's index of each stored fine voxel's parent (core/multires.h's
/// convention: fine voxel (x, y, z) is the child of coarse voxel (x/2, y/2, z/2)).
std::vector<std::uint32_t> coarseParents(const Medium& fine, const Medium& coarse);

/// The weights w_f above for every stored fine voxel: `parent` its parent's index (below
/// `parents`, or kNoParent: weight 1), `strength` its s_f (negative values count as 0).
std::vector<float> tailShape(const std::vector<float>& sigmaT, const std::vector<std::uint32_t>& parent, size_t parents,
                             const std::vector<float>& strength);

}  // namespace lpm

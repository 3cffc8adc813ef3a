// The optical size of a medium's thickest region: how many mean free paths across the
// region is where light stays longest. The planner compares it with the diffusion length
// (core/solve_plan.cpp, planDiffusionTail): a medium many diffusion lengths across keeps
// its scattered light for many orders however thin its voxels are.
//
// Through each voxel v run three rows of the block, one along each axis; T_a(v) is the
// optical depth of the whole row along axis a (sigma_t times the voxel edge, summed). The
// slowest diffusion mode of a box of optical sides (X, Y, Z) leaks as
// pi^2 (1/X^2 + 1/Y^2 + 1/Z^2) / 3 per collision; the size reported is
//
//     T = sqrt(3 / min_v sum_a 1 / T_a(v)^2)
//
// over the voxels with extinction: a cube of optical side T gives T, a slab of optical
// thickness T gives sqrt(3) T. Rows pass through gaps in the medium, so two clouds on one
// row count as one thicker cloud. Design note: docs/multires.md, "When".
#pragma once

#include "core/medium.h"

namespace lpm {

/// T above; 0 for a medium without extinction. Visits every stored voxel twice and holds
/// three planes of row depths (one float per row); the same result for any thread count.
double opticalSize(const Medium& m);

}  // namespace lpm

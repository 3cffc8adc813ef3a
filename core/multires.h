// Multi-resolution transfer for the higher scattering orders (docs/multires.md).
//
// After the first orders are solved on the full grid, what remains to be scattered is
// smooth in space: lpmbake solves the remaining orders on a grid twice as coarse per axis
// (1/8 of the voxels) and adds their S back, interpolated, to the full-resolution result.
//   coarsen:        sigma_t of a coarse voxel = the mean of its 8 children (optical mass kept)
//   restrictSource: U_c = sum sigma_f U_f / sum sigma_f per bin and channel, so the source
//                   power sigma_s U V of every coarse voxel equals that of its children
//   prolongAdd:     S_fine += trilinear interpolation of S_coarse at fine voxel centres,
//                   over stored coarse voxels only (weights renormalised at sparse borders)
#pragma once

#include <vector>

#include "core/medium.h"

namespace lpm {

/// The medium on voxels twice as large per axis (block dimensions rounded up), sparse where
/// the fine medium is: a coarse tile is stored when any of its 8 fine child tiles is.
/// Emission is not carried (the coarse grid propagates scattered light only).
Medium coarsen(const Medium& fine);

/// Restricts an unshot source [fine voxel][bin][moment][rgb] (moments M, means used) to
/// the coarse medium's [coarse voxel][bin][rgb].
std::vector<float> restrictSource(const Medium& fine, const Medium& coarse, const std::vector<float>& fineSource,
                                  int bins, int moments);

/// fineSh [fine voxel][coeff][rgb] += trilinear interpolation of coarseSh [coarse voxel][coeff][rgb].
void prolongAdd(const Medium& fine, const Medium& coarse, const std::vector<float>& coarseSh, int coeffs,
                std::vector<float>& fineSh);

}  // namespace lpm

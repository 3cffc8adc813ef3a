// Multi-resolution transfer for the higher scattering orders (docs/multires.md).
//
// After the first orders are solved on the full grid, what remains to be scattered is
// smooth in space: lpmbake iterates the remaining orders on a grid twice as coarse per axis
// (1/8 of the voxels) and brings the sum of their sources back to the full grid.
//   coarsen:        sigma_t of a coarse voxel = the mean of its 8 children (optical mass kept)
//   restrictSource: U_c = sum sigma_f U_f / sum sigma_f per bin and channel, so the source
//                   power sigma_s U V of every coarse voxel equals that of its children
//   injectCoarse:   a coarse source back on the fine grid, each fine voxel its coarse
//                   parent's value: with sigma_c = the mean of the children, the power
//                   sigma_s U V of every coarse voxel is kept exactly
// The solver uses them in a two-grid iteration (core/two_grid.cpp, LpmSolve::continueOnCoarse).
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

/// Writes the coarse source [coarse voxel][bin][rgb] into out [fine voxel][bin][moment][rgb]
/// (means; moments M, slopes left as they are): each fine voxel gets its parent's value,
/// 0 outside the block or under an unallocated coarse tile.
void injectCoarse(const Medium& fine, const Medium& coarse, const std::vector<float>& coarseSource, int bins,
                  int moments, std::vector<float>& out);

/// out's means += scale * each fine voxel's coarse parent value (as injectCoarse, added;
/// slopes untouched): the two-grid cycle adds and removes its coarse tail this way instead
/// of holding it in a third fine-grid buffer. With `shape` (core/tail_shape.h: a weight
/// per stored fine voxel) each voxel adds scale * weight * its parent's value.
void addCoarse(const Medium& fine, const Medium& coarse, const std::vector<float>& coarseSource, int bins, int moments,
               float scale, std::vector<float>& out, const std::vector<float>* shape = nullptr);

}  // namespace lpm

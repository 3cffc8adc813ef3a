// Where the lighting grids of a bake (sh_*, scatter, emission) are active: the density's
// active voxels dilated by the footprint of trilinear interpolation, so that a renderer
// interpolating S finds the solver's value at every voxel it reads wherever the
// interpolated density is non-zero (docs/output_format.md, "Topology").
//
// Why one voxel of 26-neighbour dilation is enough: trilinear (BoxSampler) interpolation at
// an index-space point p reads the 8 voxels of the cell floor(p) + {0,1}^3. The
// interpolated density at p is non-zero only if one of those 8 carries weight and is
// active. Any two voxels of one cell differ by at most 1 along every axis (Chebyshev
// distance 1), so all 8 lie in the 3x3x3 neighbourhood of that active voxel: the 26-
// neighbour dilation by 1 holds every voxel S is read from at such a point. (Face-only
// dilation, the 6-neighbourhood, would miss the cell's edge- and corner-diagonal voxels.)
// A renderer with a wider kernel (tricubic: 4^3 voxels) would need kLightingShell = 2.
#pragma once

#include <cstdint>
#include <vector>

#include <openvdb/openvdb.h>

#include "core/medium.h"

namespace lpm {

struct DenseBake;

/// Voxels of dilation around the density's active voxels (the trilinear footprint).
constexpr int kLightingShell = 1;

struct LightingTopology {
    /// The active voxels (voxelised) on the density's transform: a mask, whose leaves hold
    /// bits only (a Vec3f grid's hold a 6 KiB value buffer each: 19 MiB on the 1M plume).
    openvdb::MaskGrid::Ptr grid;
    std::uint64_t shellVoxels = 0;   ///< active voxels added around the density's
    std::uint64_t shellDropped = 0;  ///< shell voxels left inactive: the solver has no S there
};

/// The density's active voxels (tiles voxelised) plus every voxel of the kLightingShell
/// dilation at which `bake` holds values the solver computed (see hasSolvedValue). The
/// bake's block is built so that none is dropped (vdb_io/volume_reader.h); a count other
/// than 0 means a hand-made DenseBake too small for the shell. Empty bake (sh null): the
/// density's topology.
LightingTopology lightingTopology(const openvdb::FloatGrid& density, const DenseBake& bake);

/// True when the value written at input voxel `c` comes from solved voxels only: at
/// scale 1, c lies in the block and in an allocated tile; otherwise c's centre lies within
/// the span of the block's voxel centres (interpolated, not clamped) and every voxel of its
/// trilinear stencil is stored.
bool hasSolvedValue(const DenseBake& bake, const openvdb::Coord& c);

/// Medium::wantedS for a bake solved at scale 1: a flag per stored voxel of `m` (block
/// voxel (0,0,0) at input index `blockMin`), set on the voxels lightingTopology() makes
/// active there: the density's active voxels and their kLightingShell dilation, where
/// stored (hasSolvedValue at scale 1).
std::vector<std::uint8_t> lightingVoxelFlags(const openvdb::FloatGrid& density, const openvdb::Coord& blockMin,
                                             const Medium& m);

/// Voxels of the density's kLightingShell dilation (density's own included) that are not
/// active in `lighting`: 0 for a bake written by this lpmbake; bakes written before the
/// shell existed hold S on the density's voxels only and render dark at the edge.
std::uint64_t missingShellVoxels(const openvdb::FloatGrid& density, const openvdb::Vec3SGrid& lighting);

}  // namespace lpm

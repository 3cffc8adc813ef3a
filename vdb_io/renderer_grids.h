// The constant-free grids (--renderer-grids, docs/output_format.md "Renderer grids"): a
// shader that reads them needs no number from the metadata.
//   extinction  float  sigma_t = density * density_scale, per world unit
//   source      Vec3f  sigma_s * scatter + sigma_a * L_e: the radiance a renderer adds per
//                      unit length for isotropic viewing (sigma_s = albedo sigma_t,
//                      sigma_a = (1 - albedo) sigma_t; L_e the baked emission, if any)
// A renderer then shades with absorption = extinction (its "density") and emission =
// source, stock nodes only; only the directional part (g != 0, the SH and sun terms) needs
// the metadata. `extinction` holds the density's active voxels (tiles voxelised); `source`
// the lighting grids' voxels (the density's plus the one-voxel shell, where it is 0).
#pragma once

#include <openvdb/openvdb.h>

#include "core/math.h"

namespace lpm {

struct RendererGrids {
    openvdb::FloatGrid::Ptr extinction;
    openvdb::Vec3SGrid::Ptr source;
};

/// `scatter` and `emission` (may be null) are the bake's grids, on density's transform.
RendererGrids makeRendererGrids(const openvdb::FloatGrid& density, const openvdb::Vec3SGrid& scatter,
                                const openvdb::Vec3SGrid* emission, double densityScale, const RGB& albedo);

}  // namespace lpm

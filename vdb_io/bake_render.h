// The preview ray march of a bake (`lpmbake render`, the render tests), as a library
// function the way OpenVDB's vdb_render calls tools::rayTrace. Single scattering from the
// baked S only: along a camera ray with direction v it accumulates
//   L += T * albedo * S(x, -v) * (1 - exp(-sigma_t dt))        (in-scattering)
//      + T * (1 - albedo) * L_e * (1 - exp(-sigma_t dt))        (emission, if baked)
// with density and S trilinearly interpolated (S from the SH grids, clamped at zero, plus
// the exact sun terms E T p_HG of format 2, core/sun_term.h), and adds T * environment(v)
// behind the volume. Shading parameters come from the bake's metadata (bake_schema.h).
// The march samples only where the interpolated density is non-zero, i.e. within one voxel
// of an active density voxel; the lighting grids hold solved S on that whole footprint
// (lighting_topology.h), so no lookup there reads the zero background.
#pragma once

#include <vector>

#include "core/camera.h"
#include "core/envmap.h"
#include "vdb_io/bake_file.h"

namespace lpm {

/// A camera that frames the bake's active density: looking at its world-space centre from
/// +Z, a little above and to the right (-Y and above for a Z-up bake), far enough for the
/// bounding sphere to fill the vertical field of view; up is the bake's up axis. Throws
/// InputError for a bake without active density.
PinholeCamera framingCamera(const BakeFile& bake, double fovYDeg, int width, int height);

/// Scene-linear RGB per pixel ([pixel][rgb], row 0 at the top) in the bake's working
/// colour space. `env` (may be null) is drawn behind the volume. Needs bake.density and
/// a valid bake (validateBake). Runs in parallel over rows; non-finite results become 0.
std::vector<float> renderBake(const BakeFile& bake, const PinholeCamera& camera, const EnvMap* env, double stepVoxels);

}  // namespace lpm

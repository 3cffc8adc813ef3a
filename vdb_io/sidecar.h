// The bake's metadata beside it as JSON (docs/output_format.md, "Sidecar"), for renderers
// and DCC scripts that cannot read VDB file metadata (Blender's bpy cannot). Made from the
// same schema as the VDB metadata (bake_schema.h):
//   "bake": the VDB's file name, "format_version", "grids": the grid names in file order,
//   "shader": every key a shader needs (the schema's shader keys without "lpm:", plus
//             "sun_terms": [{grid, toward, irradiance, angle_deg}]),
//   "metadata": every lpm:* key with its value (vectors as arrays).
#pragma once

#include <string>
#include <vector>

#include <openvdb/openvdb.h>
#include <nlohmann/json.hpp>

namespace lpm {

/// The sidecar's JSON object.
nlohmann::json sidecarJson(const std::string& bakePath, const std::vector<std::string>& grids,
                           const openvdb::MetaMap& meta);

/// Writes sidecarJson() atomically to `path`, never over one of `protect`; throws OutputError.
void writeSidecar(const std::string& path, const std::string& bakePath, const std::vector<std::string>& grids,
                  const openvdb::MetaMap& meta, const std::vector<std::string>& protect);

}  // namespace lpm

// The bake's metadata beside it as JSON (docs/output_format.md, "Sidecar"): for renderers
// and DCC scripts that cannot read VDB file metadata (Blender's bpy cannot), the same
// lpm:* keys with the same values, and the grid names the file holds.
#pragma once

#include <string>
#include <vector>

#include <openvdb/openvdb.h>

namespace lpm {

/// JSON object of every lpm:* key of `meta` (strings, numbers, booleans; vectors as arrays).
std::string metadataJson(const openvdb::MetaMap& meta, const std::string& indent);

/// Writes {"bake": file name, "grids": [...], "metadata": {...}} atomically to `path`;
/// throws OutputError.
void writeSidecar(const std::string& path, const std::string& bakePath, const std::vector<std::string>& grids,
                  const openvdb::MetaMap& meta, const std::vector<std::string>& protect);

}  // namespace lpm

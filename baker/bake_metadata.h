// What a bake records about itself (docs/output_format.md): the conventions a consumer
// needs to use it without this tool, the lights and settings it was made with, and the
// settings digest that --skip-existing compares (docs/farm.md).
#pragma once

#include <cstdint>
#include <string>

#include <openvdb/openvdb.h>

#include "baker/options.h"
#include "vdb_io/env_reader.h"

namespace lpm {

/// Every option that changes the bake's content, one `key=value` line each, numbers with
/// all their digits, plus the tool version: two bakes with the same canonical settings
/// (and the same input files) hold the same values. Leaves out what does not change the
/// result (--threads, --stats, verbosity, --max-voxels).
std::string canonicalSettings(const BakeOptions& o);

/// 16 hex digits: the digest of canonicalSettings(o), stored as lpm:settings_digest.
std::string settingsDigest(const BakeOptions& o);

/// The file metadata of a bake (lpm:* keys).
openvdb::MetaMap bakeMetadata(const BakeOptions& o, const BakeSummary& sum, const LpmResult& res, const EnvInput& env,
                              std::uint64_t sanitizedValues);

}  // namespace lpm

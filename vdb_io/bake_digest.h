// Content digest of a bake: what a farm compares to tell that two bakes of a frame are
// the same (docs/farm.md). It covers every grid (name, type, transform, the coordinates
// and bytes of every active value) and the file metadata except the volatile keys (how
// long the bake took, the command line that ran it), so a frame baked alone, inside a
// sequence, with any --threads or on another node gives the same digest.
#pragma once

#include <cstdint>
#include <string>

#include "vdb_io/bake_file.h"

namespace lpm {

/// 64-bit FNV-1a over bytes; `h` continues a running digest.
std::uint64_t fnv1a(const void* data, size_t bytes, std::uint64_t h = 0xcbf29ce484222325ull);

/// True for the metadata keys the digest leaves out (lpm:time_*, lpm:timings, lpm:command_line).
bool isVolatileBakeMeta(const std::string& key);

/// Digest of `f`'s content (above); throws InputError for a grid type a bake never holds.
std::uint64_t bakeContentDigest(const BakeFile& f);

/// 16 lower-case hex digits.
std::string hex64(std::uint64_t v);

}  // namespace lpm

// Opening OpenVDB files defensively. OpenVDB trusts the lengths and offsets it reads:
// a corrupt length field makes it allocate gigabytes, and a truncated file makes it
// read a chunk length past the end of the stream into an uninitialised variable (a
// random allocation size). openVdbFile() rules both out before any grid is read.
#pragma once

#include <string>

#include <openvdb/io/File.h>

namespace lpm {

/// Opens `path` for reading (no delayed loading). Throws InputError naming the file when
/// it is missing, not a VDB, corrupt (a header field asks for more memory than the file
/// could hold) or truncated (a grid's recorded extent runs past the end of the file).
openvdb::io::File openVdbFile(const std::string& path);

}  // namespace lpm

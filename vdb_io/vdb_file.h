// Reading OpenVDB files defensively. OpenVDB trusts every length, count and offset it
// reads: a corrupt string length makes it allocate gigabytes, a corrupt chunk length
// makes it read past the end of a heap buffer (a fuzzing finding in OpenVDB 10's Blosc
// reader), and past the end of a truncated file it reads chunk lengths into
// uninitialised variables. VdbFile walks the layout first, without trusting anything,
// and hands a grid to OpenVDB only when every field it will read fits. Design note:
// docs/vdb_input.md.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <openvdb/io/File.h>

namespace lpm {

/// An OpenVDB file opened for reading, whose header, file metadata and grid list have been
/// checked against the file's size. Errors are InputError naming the file (and the grid).
class VdbFile {
public:
    /// Opens `path` (no delayed loading). Throws when it is missing, empty, not a VDB,
    /// truncated, or a header field is corrupt.
    explicit VdbFile(const std::string& path);
    ~VdbFile();
    VdbFile(const VdbFile&) = delete;
    VdbFile& operator=(const VdbFile&) = delete;

    const std::string& path() const { return path_; }
    /// File-level metadata.
    openvdb::MetaMap::Ptr fileMetadata();
    /// Every grid's metadata and transform, without topology or values.
    openvdb::GridPtrVecPtr gridMetadata();
    /// Reads one grid ("name", or "name[N]" for the N-th of several with that name) after
    /// checking its stored topology and values: every count, mask and compressed chunk
    /// must fit inside the grid's part of the file.
    openvdb::GridBase::Ptr readGrid(const std::string& name);
    /// Reads every grid (each checked as in readGrid).
    openvdb::GridPtrVec readAllGrids();

    struct GridExtent {
        std::string uniqueName;  ///< OpenVDB's unique name ("name" or "name\x1eN")
        std::string type;        ///< tree type, e.g. "Tree_float_5_4_3"
        bool half = false;       ///< stored as 16-bit half floats
        bool instance = false;   ///< shares another grid's tree (no topology of its own)
        std::int64_t gridPos = 0, blockPos = 0, endPos = 0;
    };

private:
    void checkGridData(const GridExtent& g);

    std::string path_;
    std::uint64_t size_ = 0;
    std::uint32_t version_ = 0;
    std::uint32_t libMajor_ = 0, libMinor_ = 0;
    bool checked_ = false;  ///< false for layouts the checker does not know (pre-2014 files, streams)
    std::vector<GridExtent> grids_;
    openvdb::io::File file_;
};

}  // namespace lpm

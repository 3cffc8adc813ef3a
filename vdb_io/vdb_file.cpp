#include "vdb_io/vdb_file.h"

#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <vector>

#include <openvdb/Grid.h>
#include <openvdb/io/Compression.h>
#include <openvdb/io/DelayedLoadMetadata.h>
#include <openvdb/io/GridDescriptor.h>
#include <openvdb/io/io.h>
#include <openvdb/math/Transform.h>

#include "vdb_io/io_error.h"
#include "vdb_io/volume_reader.h"  // initOpenVdb

namespace lpm {

namespace {

const char* kComp = "input";

// While OpenVDB parses a file's header and grid descriptors, caps the process's address
// space at its current size + 256 MiB + 8x the file: a corrupt length field then fails as
// std::bad_alloc instead of making OpenVDB allocate (and zero) gigabytes (a fuzzing
// finding: a 75 kB file drove the reader to 5.9 GB). Not under AddressSanitizer, whose
// shadow memory needs the address space.
#if defined(__SANITIZE_ADDRESS__)
#define LPM_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define LPM_ASAN 1
#endif
#endif

class AddressSpaceCap {
public:
    explicit AddressSpaceCap(std::uint64_t fileBytes) {
#if !defined(LPM_ASAN)
        std::ifstream statm("/proc/self/statm");
        std::uint64_t pages = 0;
        if (!(statm >> pages) || ::getrlimit(RLIMIT_AS, &old_) != 0) return;
        const std::uint64_t cap =
            pages * std::uint64_t(::sysconf(_SC_PAGESIZE)) + (std::uint64_t(256) << 20) + 8 * fileBytes;
        if (old_.rlim_cur != RLIM_INFINITY && old_.rlim_cur <= cap) return;
        rlimit lim = old_;
        lim.rlim_cur = cap;
        set_ = ::setrlimit(RLIMIT_AS, &lim) == 0;
#else
        (void)fileBytes;
#endif
    }
    ~AddressSpaceCap() {
        if (set_) ::setrlimit(RLIMIT_AS, &old_);
    }
    AddressSpaceCap(const AddressSpaceCap&) = delete;
    AddressSpaceCap& operator=(const AddressSpaceCap&) = delete;

private:
    rlimit old_{};
    bool set_ = false;
};

/// What a read is of, for error messages. Built into text only when a read fails: the
/// tree walk reads several fields per leaf, and formatting each name up front cost as
/// much as the reads. Holds pointers: use it within the call it is passed to.
class What {
public:
    What(const std::string& text) : text_(&text) {}  // NOLINT(google-explicit-constructor)
    What(const char* text) : part_(text) {}          // NOLINT(google-explicit-constructor)
    What(const char* part, const std::string& grid) : part_(part), grid_(&grid) {}
    std::string str() const {
        if (text_) return *text_;
        return grid_ ? std::string(part_) + " of grid '" + *grid_ + "'" : std::string(part_);
    }

private:
    const std::string* text_ = nullptr;
    const char* part_ = nullptr;
    const std::string* grid_ = nullptr;
};

/// Reads an untrusted file: every read states what it is reading and the byte where that
/// part of the file ends, and fails (naming the file) instead of reading past it. Keeps
/// its own position and skips short gaps by reading through a 64 KiB buffer: tellg and
/// seekg on a filebuf each cost a system call (and seekg drops the buffer), which per
/// leaf doubled the time of reading a grid.
class Reader {
public:
    Reader(const std::string& path, std::uint64_t size) : path_(path), size_(size), buffer_(kBuffer) {
        is_.rdbuf()->pubsetbuf(buffer_.data(), std::streamsize(buffer_.size()));  // before open
        is_.open(path, std::ios::binary);
    }

    [[noreturn]] void fail(const std::string& why) const {
        throw InputError(kComp, "cannot read '" + path_ + "' as an OpenVDB file: " + why);
    }
    bool ok() const { return bool(is_); }
    std::uint64_t size() const { return size_; }
    std::uint64_t pos() const { return pos_; }
    void seek(std::uint64_t at) {
        is_.seekg(std::streamoff(at));
        pos_ = at;
    }
    /// The stream, for OpenVDB to parse a part itself; call resync() afterwards.
    std::istream& stream() { return is_; }
    void resync(const What& what) {
        const std::streamoff at = is_.tellg();
        if (at < 0) fail("the file is truncated (it ends inside " + what.str() + ")");
        pos_ = std::uint64_t(at);
    }

    /// Fails unless `n` more bytes lie before `limit` (the file's end or the part's end).
    void need(std::uint64_t n, const What& what, std::uint64_t limit) {
        limit = std::min(limit, size_);
        if (!is_) fail("the file is truncated (it ends inside " + what.str() + ")");
        if (pos_ <= limit && n <= limit - pos_) return;
        if (limit == size_)
            fail("it is corrupt or truncated (" + what.str() + " at byte " + std::to_string(pos_) + " needs " +
                 std::to_string(n) + " bytes; the file has " + std::to_string(size_) + ")");
        fail("it is corrupt (" + what.str() + " at byte " + std::to_string(pos_) + " needs " + std::to_string(n) +
             " bytes, past the end of its part at byte " + std::to_string(limit) + ")");
    }
    template <typename T>
    T get(const What& what, std::uint64_t limit = ~std::uint64_t(0)) {
        T v{};
        read(&v, sizeof(T), what, limit);
        return v;
    }
    void read(void* dst, std::uint64_t n, const What& what, std::uint64_t limit = ~std::uint64_t(0)) {
        need(n, what, limit);
        is_.read(static_cast<char*>(dst), std::streamsize(n));
        pos_ += n;
    }
    void skip(std::uint64_t n, const What& what, std::uint64_t limit = ~std::uint64_t(0)) {
        need(n, what, limit);
        if (n <= kBuffer) is_.ignore(std::streamsize(n));
        else is_.seekg(std::streamoff(n), std::ios::cur);
        pos_ += n;
    }
    /// OpenVDB's string: a 32-bit length, then the bytes.
    std::string string(const What& what, std::uint64_t limit = ~std::uint64_t(0)) {
        const auto n = get<std::uint32_t>(what, limit);
        need(n, what, limit);  // before the allocation
        std::string s(n, '\0');
        if (n) read(&s[0], n, what, limit);
        return s;
    }
    /// A MetaMap: a count, then (name, type name, byte count, value) per entry, read the
    /// way MetaMap::readMeta reads it: registered fixed-size types read their own size
    /// (whatever the byte count says, so it must agree), strings and unknown types read
    /// the byte count, and OpenVDB's delayed-load table has a layout of its own.
    void metaMap(const std::string& what, std::uint64_t limit) {
        const auto count = get<std::uint32_t>(what, limit);
        for (std::uint32_t i = 0; i < count; ++i) {
            const std::string name = string(what, limit);
            const std::string type = string(what, limit);
            const auto bytes = get<std::uint32_t>(what, limit);
            const std::string entry = "metadata '" + name + "' (" + type + ") in " + what;
            if (type == openvdb::io::DelayedLoadMetadata::staticTypeName()) {
                delayedLoadTable(bytes, entry, limit);
            } else if (type != "string" && openvdb::Metadata::isRegisteredType(type)) {
                const std::uint32_t fixed = openvdb::Metadata::createMetadata(type)->size();
                if (bytes != fixed)
                    fail("it is corrupt (" + entry + " says " + std::to_string(bytes) + " bytes; the type has " +
                         std::to_string(fixed) + ")");
                skip(fixed, entry, limit);
            } else {
                skip(bytes, entry, limit);
            }
        }
    }
    /// io::DelayedLoadMetadata::readValue: a leaf count, then a mask byte and a 64-bit
    /// compressed size per leaf, each array stored raw or as one Blosc buffer. The counts
    /// size allocations, so they are bounded by the file (a leaf takes at least a byte).
    void delayedLoadTable(std::uint32_t bytes, const std::string& what, std::uint64_t limit) {
        if (bytes == 0) return;
        const std::uint64_t start = pos();
        const auto count = get<std::uint32_t>(what, limit);
        if (count > size_) fail("it is corrupt (" + what + " lists " + std::to_string(count) + " leaves)");
        auto array = [&](std::uint32_t stored, std::uint64_t rawBytes) {
            if (stored == 0) {
                skip(rawBytes, what, limit);
                return;
            }
            need(stored, what, limit);
            const std::uint64_t at = pos();
            std::uint32_t header[4] = {0, 0, 0, 0};
            if (stored >= 16) read(header, 16, what, limit);
            if (stored < 16 || header[3] != stored || header[1] > rawBytes + 1024)
                fail("it is corrupt (a Blosc buffer of " + what + " at byte " + std::to_string(at) + ")");
            skip(stored - 16, what, limit);
        };
        array(get<std::uint32_t>(what, limit), count);
        const auto sizes = get<std::uint32_t>(what, limit);
        if (sizes != 0xFFFFFFFFu) array(sizes, std::uint64_t(count) * 8);
        const std::uint64_t used = pos() - start;
        if (used < bytes) skip(bytes - used, what, limit);
    }
    /// A node mask of `bytes` bytes; returns the number of bits on and keeps the words.
    std::uint32_t mask(std::vector<std::uint64_t>& words, std::uint64_t bytes, const What& what, std::uint64_t limit) {
        need(bytes, what, limit);
        words.assign(bytes / 8, 0);
        read(words.data(), bytes, what, limit);
        std::uint32_t on = 0;
        for (std::uint64_t w : words) on += std::uint32_t(__builtin_popcountll(w));
        return on;
    }

private:
    std::string path_;
    std::uint64_t size_;
    static constexpr std::size_t kBuffer = std::size_t(1) << 16;
    std::vector<char> buffer_;
    std::ifstream is_;
    std::uint64_t pos_ = 0;
};

/// Value layout of the tree types whose stored data the checker walks: the standard
/// 5-4-3 trees of fixed-size values (the only ones lpmbake reads).
struct ValueLayout {
    std::uint64_t bytes = 0;      ///< sizeof(ValueType)
    std::uint64_t halfBytes = 0;  ///< stored size per value when saved as half floats
};

bool valueLayout(const std::string& type, ValueLayout& v) {
    static const std::map<std::string, ValueLayout> known = {
        {"Tree_float_5_4_3", {4, 2}},   {"Tree_double_5_4_3", {8, 2}}, {"Tree_vec3s_5_4_3", {12, 6}},
        {"Tree_vec3d_5_4_3", {24, 6}},  {"Tree_int32_5_4_3", {4, 4}},  {"Tree_int64_5_4_3", {8, 8}},
        {"Tree_vec3i_5_4_3", {12, 12}},
    };
    const auto it = known.find(type);
    if (it == known.end()) return false;
    v = it->second;
    return true;
}

/// Walks a 5-4-3 tree's topology and buffers exactly as OpenVDB 10 reads them
/// (RootNode/InternalNode/LeafNode::readTopology and readBuffers, io::readCompressedValues,
/// io::readData), checking every count against the bytes left in the grid's part of the
/// file and every compressed chunk's length against the values it must hold. File format
/// 222 and later (per-node mask compression, OpenVDB 3.0+).
class TreeCheck {
public:
    TreeCheck(Reader& r, const std::string& grid, ValueLayout v, bool halfFloats, std::uint32_t compression)
        : r_(r), grid_(grid), v_(v), half_(halfFloats), compression_(compression) {}

    void run(std::uint64_t blockPos, std::uint64_t endPos) {
        limit_ = blockPos;
        r_.get<std::int32_t>(what("its buffer count"), limit_);
        r_.skip(v_.bytes, what("its background value"), limit_);
        const auto tiles = r_.get<std::uint32_t>(what("its tile count"), limit_);
        const auto children = r_.get<std::uint32_t>(what("its child count"), limit_);
        r_.skip(std::uint64_t(tiles) * (12 + v_.bytes + 1), what("its root tiles"), limit_);
        std::map<std::array<std::int32_t, 3>, Upper> root;  // buffers are read in key order
        for (std::uint32_t i = 0; i < children; ++i) {
            std::array<std::int32_t, 3> c{};
            for (auto& x : c) x = r_.get<std::int32_t>(what("a root child"), limit_);
            root[c] = upper();
        }
        // OpenVDB's writer records blockPos right after the topology and endPos right after
        // the values, so a part that ends anywhere else was read with the wrong layout
        // (half vs full floats, a value count) and its values would be garbage.
        endsAt(blockPos, "its topology");
        limit_ = endPos;
        for (const auto& [origin, node] : root)
            for (const Lower& lower : node.children)
                for (std::uint16_t active : lower.leaves) {
                    r_.skip(64, what("a leaf mask"), limit_);
                    values(active, 512, 64);
                }
        endsAt(endPos, "its values");
    }

private:
    struct Lower {
        std::vector<std::uint16_t> leaves;  ///< active voxels of each child leaf, in mask order
    };
    struct Upper {
        std::vector<Lower> children;
    };

    What what(const char* part) const { return What(part, grid_); }
    void endsAt(std::uint64_t expected, const char* part) const {
        if (r_.pos() != expected)
            r_.fail("it is corrupt (grid '" + grid_ + "' has " + part + " ending at byte " + std::to_string(r_.pos()) +
                    " where the grid list says byte " + std::to_string(expected) + ")");
    }

    /// InternalNode<InternalNode<Leaf, 4>, 5>::readTopology.
    Upper upper() {
        Upper n;
        const std::uint32_t childCount = r_.mask(words_, 4096, what("a node mask"), limit_);
        const std::uint32_t active = r_.mask(words_, 4096, what("a node mask"), limit_);
        values(active, 32768, 4096);
        n.children.reserve(childCount);
        for (std::uint32_t i = 0; i < childCount; ++i) n.children.push_back(lower());
        return n;
    }
    /// InternalNode<Leaf, 4>::readTopology, then each leaf's value mask.
    Lower lower() {
        Lower n;
        const std::uint32_t childCount = r_.mask(words_, 512, what("a node mask"), limit_);
        const std::uint32_t active = r_.mask(words_, 512, what("a node mask"), limit_);
        values(active, 4096, 512);
        r_.need(std::uint64_t(childCount) * 64, what("its leaf masks"), limit_);
        n.leaves.reserve(childCount);
        for (std::uint32_t i = 0; i < childCount; ++i)
            n.leaves.push_back(std::uint16_t(r_.mask(words_, 64, what("a leaf mask"), limit_)));
        return n;
    }

    /// io::readCompressedValues for a node of `count` values, `active` of them active,
    /// whose selection mask has `maskBytes` bytes.
    void values(std::uint32_t active, std::uint32_t count, std::uint64_t maskBytes) {
        const std::int8_t meta = r_.get<std::int8_t>(what("a compression flag"), limit_);
        using namespace openvdb::io;
        if (meta == NO_MASK_AND_ONE_INACTIVE_VAL || meta == MASK_AND_ONE_INACTIVE_VAL ||
            meta == MASK_AND_TWO_INACTIVE_VALS)
            r_.skip(v_.bytes * (meta == MASK_AND_TWO_INACTIVE_VALS ? 2 : 1), what("an inactive value"), limit_);
        if (meta == MASK_AND_NO_INACTIVE_VALS || meta == MASK_AND_ONE_INACTIVE_VAL ||
            meta == MASK_AND_TWO_INACTIVE_VALS)
            r_.skip(maskBytes, what("a selection mask"), limit_);
        std::uint64_t n = count;
        if ((compression_ & COMPRESS_ACTIVE_MASK) && meta != NO_MASK_AND_ALL_VALS) n = active;
        if (half_ && v_.halfBytes != v_.bytes) {
            if (n < 1) return;  // HalfReader reads nothing for no values
            chunk(n * v_.halfBytes);
        } else {
            chunk(n * v_.bytes);
        }
    }

    /// io::readData: a Blosc or zlib chunk (64-bit length; negative for stored bytes), or
    /// the raw bytes.
    void chunk(std::uint64_t bytes) {
        using namespace openvdb::io;
        if (!(compression_ & (COMPRESS_BLOSC | COMPRESS_ZIP))) {
            r_.skip(bytes, what("its values"), limit_);
            return;
        }
        const auto n = r_.get<std::int64_t>(what("a chunk length"), limit_);
        if (n <= 0) {
            if (std::uint64_t(-n) != bytes)
                r_.fail("it is corrupt (grid '" + grid_ + "' stores " + std::to_string(-n) + " bytes where " +
                        std::to_string(bytes) + " are expected, at byte " + std::to_string(r_.pos() - 8) + ")");
            r_.skip(bytes, what("its values"), limit_);
            return;
        }
        const std::uint64_t at = r_.pos();
        r_.need(std::uint64_t(n), what("a compressed chunk"), limit_);
        if (compression_ & COMPRESS_BLOSC) {
            // Blosc trusts the compressed size in its own header: it must be the chunk's.
            if (n < 16)
                r_.fail("it is corrupt (grid '" + grid_ + "' has a " + std::to_string(n) +
                        "-byte Blosc chunk at byte " + std::to_string(at) + ")");
            std::uint32_t header[4];
            r_.read(header, 16, what("a compressed chunk"), limit_);
            if (header[3] != std::uint64_t(n))
                r_.fail("it is corrupt (a Blosc chunk of grid '" + grid_ + "' at byte " + std::to_string(at) +
                        " says it holds " + std::to_string(header[3]) + " bytes, its length field " +
                        std::to_string(n) + ")");
            r_.skip(std::uint64_t(n) - 16, what("a compressed chunk"), limit_);
            return;
        }
        r_.skip(std::uint64_t(n), what("a compressed chunk"), limit_);
    }

    Reader& r_;
    std::string grid_;
    ValueLayout v_;
    bool half_;
    std::uint32_t compression_;
    std::uint64_t limit_ = 0;
    std::vector<std::uint64_t> words_;
};

}  // namespace

VdbFile::VdbFile(const std::string& path) : path_(path), file_(path) {
    initOpenVdb();
    std::error_code ec;
    size_ = std::filesystem::file_size(path, ec);
    if (!ec) {
        Reader r(path, size_);
        if (!r.ok()) r.fail(std::string("it cannot be opened (") + std::strerror(errno) + ")");
        if (size_ < 8)
            r.fail(size_ == 0 ? "the file is empty"
                              : "it is not an OpenVDB file (" + std::to_string(size_) + " bytes)");
        if (r.get<std::int64_t>("the magic number") != std::int64_t(openvdb::OPENVDB_MAGIC))
            r.fail("it is not an OpenVDB file (no VDB magic number)");
        version_ = r.get<std::uint32_t>("the format version");
        // Files older than OpenVDB 3.0 (2014) and streamed files (no grid offsets; io::File
        // would parse every grid while opening) use layouts the checker does not walk.
        if (version_ < openvdb::OPENVDB_FILE_VERSION_NODE_MASK_COMPRESSION)
            r.fail("it uses VDB file format " + std::to_string(version_) +
                   " (OpenVDB before 3.0), which lpmbake does not read; re-save it with a current OpenVDB");
        {
            libMajor_ = r.get<std::uint32_t>("the library version");
            libMinor_ = r.get<std::uint32_t>("the library version");
            const auto hasOffsets = r.get<char>("the header");
            r.skip(36, "the header");
            if (!hasOffsets)
                r.fail(
                    "it is a streamed VDB (written without grid offsets), which lpmbake does not read; "
                    "re-save it as a regular .vdb file");
            {
                checked_ = true;
                r.metaMap("the file metadata", size_);
                const auto count = r.get<std::int32_t>("the grid count");
                if (count < 0) r.fail("it is corrupt (grid count " + std::to_string(count) + ")");
                for (std::int32_t i = 0; i < count; ++i) {
                    GridExtent g;
                    g.uniqueName = r.string("a grid name");
                    const std::string name = openvdb::io::GridDescriptor::nameAsString(g.uniqueName);
                    g.type = r.string("the type of grid '" + name + "'");
                    const std::string halfSuffix = "_HalfFloat";
                    if (g.type.size() > halfSuffix.size() &&
                        g.type.compare(g.type.size() - halfSuffix.size(), halfSuffix.size(), halfSuffix) == 0)
                    {
                        g.half = true;
                        g.type.resize(g.type.size() - halfSuffix.size());
                    }
                    g.instance = !r.string("the instance parent of grid '" + name + "'").empty();
                    g.gridPos = r.get<std::int64_t>("the grid list");
                    g.blockPos = r.get<std::int64_t>("the grid list");
                    g.endPos = r.get<std::int64_t>("the grid list");
                    if (g.gridPos <= 0 || g.blockPos < g.gridPos || g.endPos < g.blockPos)
                        r.fail("it is corrupt (grid '" + name + "' has byte offsets " + std::to_string(g.gridPos) +
                               ", " + std::to_string(g.blockPos) + ", " + std::to_string(g.endPos) + ")");
                    if (std::uint64_t(g.endPos) > size_)
                        r.fail("the file is truncated (grid '" + name + "' ends at byte " + std::to_string(g.endPos) +
                               " but the file has " + std::to_string(size_) + " bytes)");
                    r.seek(std::uint64_t(g.endPos));
                    grids_.push_back(g);
                }
            }
        }
    }
    try {
        AddressSpaceCap cap(ec ? 0 : size_);
        // No delayed loading: we read only the grids we need, and never keep the input
        // memory-mapped while the output is written.
        file_.open(false);
    } catch (const std::bad_alloc&) {
        throw InputError(kComp, "cannot read '" + path +
                                    "' as an OpenVDB file: it is corrupt (a header field asks "
                                    "for far more memory than the file could hold)");
    } catch (const std::exception& e) {
        throw InputError(kComp, "cannot read '" + path + "' as an OpenVDB file: " + e.what());
    }
}

VdbFile::~VdbFile() {
    try {
        if (file_.isOpen()) file_.close();
    } catch (...) {
    }
}

openvdb::MetaMap::Ptr VdbFile::fileMetadata() {
    try {
        return file_.getMetadata();
    } catch (const std::exception& e) {
        throw InputError(kComp, "cannot read the metadata of '" + path_ + "': " + e.what());
    }
}

openvdb::GridPtrVecPtr VdbFile::gridMetadata() {
    if (checked_)
        for (const GridExtent& g : grids_) {
            Reader r(path_, size_);
            r.seek(std::uint64_t(g.gridPos));
            const std::string name = openvdb::io::GridDescriptor::nameAsString(g.uniqueName);
            r.skip(4, "the compression flags of grid '" + name + "'", std::uint64_t(g.blockPos));
            r.metaMap("the metadata of grid '" + name + "'", std::uint64_t(g.blockPos));
            const std::uint64_t at = r.pos();
            r.string("the transform of grid '" + name + "'", std::uint64_t(g.blockPos));
            r.seek(at);
        }
    try {
        return file_.readAllGridMetadata();
    } catch (const std::exception& e) {
        throw InputError(kComp, "cannot read the grid list of '" + path_ + "': " + e.what());
    }
}

void VdbFile::checkGridData(const GridExtent& g) {
    if (!checked_) return;
    const std::string name = openvdb::io::GridDescriptor::nameAsString(g.uniqueName);
    Reader r(path_, size_);
    const std::uint64_t blockPos = std::uint64_t(g.blockPos), endPos = std::uint64_t(g.endPos);
    r.seek(std::uint64_t(g.gridPos));
    const auto compression = r.get<std::uint32_t>("the compression flags of grid '" + name + "'", blockPos);
    const std::uint64_t metaAt = r.pos();
    r.metaMap("the metadata of grid '" + name + "'", blockPos);
    // The transform: a map type name, then that map's fixed-size fields.
    const std::uint64_t at = r.pos();
    r.string("the transform of grid '" + name + "'", blockPos);
    r.seek(at);
    openvdb::io::setVersion(r.stream(), openvdb::VersionId(libMajor_, libMinor_), version_);
    try {
        openvdb::math::Transform xform;
        xform.read(r.stream());
    } catch (const std::exception& e) {
        r.fail("it is corrupt (the transform of grid '" + name + "': " + e.what() + ")");
    }
    r.resync("the transform of grid '" + name + "'");
    r.need(0, "the transform of grid '" + name + "'", blockPos);
    if (g.instance) return;
    ValueLayout v;
    if (!valueLayout(g.type, v))
        r.fail("grid '" + name + "' has tree type '" + g.type + "', which lpmbake does not read");
    // Half or full floats, decided as io::File::readGrid decides: the descriptor's
    // "_HalfFloat" suffix, overridden by the grid's own is_saved_as_half_float metadata
    // read through MetaMap::readMeta, whatever its type (a fuzzing finding: metadata
    // retyped from "bool" to an unknown type reads as true, and OpenVDB then read a
    // full-float chunk of 8182 bytes into a 20-byte half buffer). The metadata was
    // checked above, so OpenVDB can parse it here.
    const std::uint64_t treeAt = r.pos();
    bool halfFloats = g.half;
    r.seek(metaAt);
    try {
        const openvdb::GridBase::Ptr probe = openvdb::GridBase::createGrid(g.type);
        probe->setSaveFloatAsHalf(g.half);
        probe->readMeta(r.stream());
        halfFloats = probe->saveFloatAsHalf();
    } catch (const std::exception& e) {
        r.fail("it is corrupt (the metadata of grid '" + name + "': " + e.what() + ")");
    }
    r.seek(treeAt);
    TreeCheck(r, name, v, halfFloats, compression).run(blockPos, endPos);
}

openvdb::GridBase::Ptr VdbFile::readGrid(const std::string& name) {
    // io::File's lookup: the exact unique name, else the first grid with that base name.
    const std::string unique = openvdb::io::GridDescriptor::stringAsUniqueName(name);
    const GridExtent* found = nullptr;
    for (const GridExtent& g : grids_)
        if (g.uniqueName == unique) found = found ? found : &g;
    if (!found)
        for (const GridExtent& g : grids_)
            if (openvdb::io::GridDescriptor::stripSuffix(g.uniqueName) == name) found = found ? found : &g;
    if (found) checkGridData(*found);
    try {
        return file_.readGrid(name);
    } catch (const std::exception& e) {
        throw InputError(kComp, "cannot read grid '" + name + "' from '" + path_ + "': " + e.what());
    }
}

openvdb::GridPtrVec VdbFile::readAllGrids() {
    for (const GridExtent& g : grids_) checkGridData(g);
    try {
        return *file_.getGrids();
    } catch (const std::exception& e) {
        throw InputError(kComp, "cannot read the grids of '" + path_ + "': " + e.what());
    }
}

}  // namespace lpm

#include "vdb_io/vdb_file.h"

#include <sys/resource.h>
#include <unistd.h>

#include <cerrno>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <vector>

#include <openvdb/io/GridDescriptor.h>

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
        const std::uint64_t cap = pages * std::uint64_t(::sysconf(_SC_PAGESIZE)) + (std::uint64_t(256) << 20) + 8 * fileBytes;
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

/// Walks an OpenVDB file's layout the way io::File reads it (file format 219 and later,
/// seekable files; older or streamed layouts are left to OpenVDB) without trusting any
/// length in it: the header, the file metadata, every grid descriptor, and each grid's
/// compression flags and metadata. Every string, metadata value and grid extent must fit
/// inside the file. OpenVDB itself allocates whatever a length field says (a corrupt
/// string length became a multi-gigabyte allocation) and, at the end of a truncated
/// stream, reads chunk lengths into uninitialised variables.
class LayoutCheck {
public:
    LayoutCheck(const std::string& path, std::uint64_t bytes) : path_(path), size_(bytes), is_(path, std::ios::binary) {}

    void run() {
        if (!is_) fail(std::string("it cannot be opened (") + std::strerror(errno) + ")");
        if (size_ < 8) fail(size_ == 0 ? "the file is empty" : "it is not an OpenVDB file (" + std::to_string(size_) + " bytes)");
        const std::int64_t magic = get<std::int64_t>("the magic number");
        if (magic != std::int64_t(openvdb::OPENVDB_MAGIC)) fail("it is not an OpenVDB file (no VDB magic number)");
        const auto version = get<std::uint32_t>("the format version");
        if (version < openvdb::OPENVDB_FILE_VERSION_NO_GRIDMAP) return;
        skip(8, "the library version");
        const auto hasOffsets = get<char>("the header");
        if (version >= openvdb::OPENVDB_FILE_VERSION_SELECTIVE_COMPRESSION &&
            version < openvdb::OPENVDB_FILE_VERSION_NODE_MASK_COMPRESSION)
            skip(1, "the header");
        skip(36, "the header");
        if (!hasOffsets) return;
        metaMap("the file metadata", size_);
        const auto count = get<std::int32_t>("the grid count");
        if (count < 0) fail("it is corrupt (grid count " + std::to_string(count) + ")");
        struct Extent {
            std::string name;
            std::int64_t grid, block, end;
        };
        std::vector<Extent> grids;
        for (std::int32_t i = 0; i < count; ++i) {
            Extent e;
            e.name = openvdb::io::GridDescriptor::nameAsString(string("a grid name", size_));
            string("a grid type", size_);
            if (version >= openvdb::OPENVDB_FILE_VERSION_GRID_INSTANCING) string("a grid name", size_);
            e.grid = get<std::int64_t>("the grid list");
            e.block = get<std::int64_t>("the grid list");
            e.end = get<std::int64_t>("the grid list");
            if (e.grid <= 0 || e.block < e.grid || e.end < e.block)
                fail("it is corrupt (grid '" + e.name + "' has byte offsets " + std::to_string(e.grid) + ", " +
                     std::to_string(e.block) + ", " + std::to_string(e.end) + ")");
            if (std::uint64_t(e.end) > size_)
                fail("the file is truncated (grid '" + e.name + "' ends at byte " + std::to_string(e.end) +
                     " but the file has " + std::to_string(size_) + " bytes)");
            is_.seekg(e.end);
            grids.push_back(e);
        }
        for (const Extent& e : grids) {
            is_.seekg(e.grid);
            if (version >= openvdb::OPENVDB_FILE_VERSION_NODE_MASK_COMPRESSION)
                skip(4, "grid '" + e.name + "'", std::uint64_t(e.block));
            metaMap("the metadata of grid '" + e.name + "'", std::uint64_t(e.block));
        }
    }

private:
    [[noreturn]] void fail(const std::string& why) const {
        throw InputError(kComp, "cannot read '" + path_ + "' as an OpenVDB file: " + why);
    }
    std::uint64_t pos() { return std::uint64_t(std::streamoff(is_.tellg())); }
    /// Fails unless `n` more bytes lie before `limit` (the file's end or the part's end).
    void need(std::uint64_t n, const std::string& what, std::uint64_t limit) {
        if (!is_) fail("the file is truncated (it ends inside " + what + ")");
        const std::uint64_t at = pos();
        if (at > limit || n > limit - at) {
            if (limit == size_)
                fail("it is corrupt or truncated (" + what + " at byte " + std::to_string(at) + " needs " +
                     std::to_string(n) + " bytes; the file has " + std::to_string(size_) + ")");
            fail("it is corrupt (" + what + " at byte " + std::to_string(at) + " needs " + std::to_string(n) +
                 " bytes, past the end of its part at byte " + std::to_string(limit) + ")");
        }
    }
    template <typename T>
    T get(const std::string& what, std::uint64_t limit = ~std::uint64_t(0)) {
        need(sizeof(T), what, std::min(limit, size_));
        T v{};
        is_.read(reinterpret_cast<char*>(&v), sizeof(T));
        return v;
    }
    void skip(std::uint64_t n, const std::string& what, std::uint64_t limit = ~std::uint64_t(0)) {
        need(n, what, std::min(limit, size_));
        is_.seekg(std::streamoff(n), std::ios::cur);
    }
    std::string string(const std::string& what, std::uint64_t limit) {
        const auto n = get<std::uint32_t>(what, limit);
        need(n, what, limit);
        std::string s(n, '\0');
        if (n) is_.read(&s[0], n);
        return s;
    }
    /// A MetaMap: a count, then (name, type name, byte count, bytes) per entry.
    void metaMap(const std::string& what, std::uint64_t limit) {
        const auto count = get<std::uint32_t>(what, limit);
        for (std::uint32_t i = 0; i < count; ++i) {
            string(what, limit);
            string(what, limit);
            skip(get<std::uint32_t>(what, limit), what, limit);
        }
    }

    std::string path_;
    std::uint64_t size_;
    std::ifstream is_;
};

}  // namespace

openvdb::io::File openVdbFile(const std::string& path) {
    initOpenVdb();
    openvdb::io::File file(path);
    std::error_code ec;
    const std::uint64_t bytes = std::filesystem::file_size(path, ec);
    try {
        if (!ec) LayoutCheck(path, bytes).run();
        AddressSpaceCap cap(ec ? 0 : bytes);
        // No delayed loading: we read only the grids we need, and never keep the input
        // memory-mapped while the output is written.
        file.open(false);
    } catch (const InputError&) {
        throw;
    } catch (const std::bad_alloc&) {
        throw InputError(kComp, "cannot read '" + path + "' as an OpenVDB file: it is corrupt (a header field asks "
                                "for far more memory than the file could hold)");
    } catch (const std::exception& e) {
        throw InputError(kComp, "cannot read '" + path + "' as an OpenVDB file: " + e.what());
    }
    return file;
}

}  // namespace lpm

#include "vdb_io/vdb_file.h"

#include <sys/resource.h>
#include <unistd.h>

#include <cstdint>
#include <filesystem>
#include <fstream>

#include <openvdb/io/GridDescriptor.h>
#include <openvdb/io/io.h>

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

/// Re-reads the header and grid descriptors the way OpenVDB's io::File does (file format
/// 219 and later, seekable files; older or streamed layouts are left to OpenVDB) and
/// checks that every grid's recorded byte range lies inside the file. A truncated file
/// otherwise reaches OpenVDB's chunk reader, which reads a length past the end of the
/// stream into an uninitialised variable and allocates that many bytes.
void checkGridExtents(const std::string& path, std::uint64_t fileBytes) {
    std::ifstream is(path, std::ios::binary);
    auto raw = [&](void* p, std::streamsize n) {
        is.read(static_cast<char*>(p), n);
        if (!is) throw InputError(kComp, "cannot read '" + path + "': the file is truncated (it ends inside its header)");
    };
    std::int64_t magic = 0;
    std::uint32_t version = 0, major = 0, minor = 0;
    char hasOffsets = 0, compressed = 0, uuid[36];
    raw(&magic, 8);
    raw(&version, 4);
    if (version < openvdb::OPENVDB_FILE_VERSION_NO_GRIDMAP) return;
    raw(&major, 4);
    raw(&minor, 4);
    raw(&hasOffsets, 1);
    if (version >= openvdb::OPENVDB_FILE_VERSION_SELECTIVE_COMPRESSION &&
        version < openvdb::OPENVDB_FILE_VERSION_NODE_MASK_COMPRESSION)
        raw(&compressed, 1);
    raw(uuid, 36);
    if (!hasOffsets) return;
    openvdb::io::setVersion(is, openvdb::VersionId(major, minor), version);
    openvdb::MetaMap fileMeta;
    fileMeta.readMeta(is);
    std::int32_t count = 0;
    raw(&count, 4);
    for (std::int32_t i = 0; i < count; ++i) {
        openvdb::io::GridDescriptor gd;
        gd.read(is);
        if (!is) throw InputError(kComp, "cannot read '" + path + "': the file is truncated (it ends inside its grid list)");
        const std::string name = openvdb::io::GridDescriptor::nameAsString(gd.uniqueName());
        const std::int64_t g = gd.getGridPos(), b = gd.getBlockPos(), e = gd.getEndPos();
        if (g <= 0 || b < g || e < b)
            throw InputError(kComp, "cannot read '" + path + "': it is corrupt (grid '" + name +
                                        "' has byte offsets " + std::to_string(g) + ", " + std::to_string(b) + ", " +
                                        std::to_string(e) + ")");
        if (std::uint64_t(e) > fileBytes)
            throw InputError(kComp, "cannot read '" + path + "': the file is truncated (grid '" + name +
                                        "' ends at byte " + std::to_string(e) + " but the file has " +
                                        std::to_string(fileBytes) + " bytes)");
        gd.seekToEnd(is);
    }
}

}  // namespace

openvdb::io::File openVdbFile(const std::string& path) {
    initOpenVdb();
    openvdb::io::File file(path);
    std::error_code ec;
    const std::uint64_t bytes = std::filesystem::file_size(path, ec);
    try {
        AddressSpaceCap cap(ec ? 0 : bytes);
        // No delayed loading: we read only the grids we need, and never keep the input
        // memory-mapped while the output is written.
        file.open(false);
        if (!ec) checkGridExtents(path, bytes);
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

// libFuzzer target for the VDB reader (vdb_io/volume_reader): any byte string is written
// to a temporary .vdb file and read. lpm::Error (a clear, named refusal) is the expected
// outcome for bad input; anything else (crash, other exception, sanitizer report, hang)
// is a finding. Build with -DLPM_FUZZ=ON and clang (scripts/fuzz.sh).
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <string>

#include "core/error.h"
#include "vdb_io/volume_reader.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
    static const std::string path = "/tmp/lpm_fuzz_" + std::to_string(::getpid()) + ".vdb";
    FILE* f = std::fopen(path.c_str(), "wb");
    if (!f) return 0;
    std::fwrite(data, 1, size, f);
    std::fclose(f);
    lpm::VolumeReadOptions o;
    o.path = path;
    o.maxDenseVoxels = 1u << 22;  // keep each run small: a valid giant grid is refused, not solved
    try {
        (void)lpm::readVolume(o);
    } catch (const lpm::Error&) {
    }
    return 0;
}

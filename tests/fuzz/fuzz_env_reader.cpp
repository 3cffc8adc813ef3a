// libFuzzer target for the environment loader (vdb_io/env_reader): the first byte picks
// the file extension (.exr or .hdr), the rest is written to a temporary file and loaded.
// lpm::Error is the expected outcome for bad input; anything else is a finding.
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <string>

#include "core/error.h"
#include "vdb_io/env_reader.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
    if (size < 1) return 0;
    const char* ext = (data[0] & 1) ? ".hdr" : ".exr";
    const std::string path = "/tmp/lpm_fuzz_env_" + std::to_string(::getpid()) + ext;
    FILE* f = std::fopen(path.c_str(), "wb");
    if (!f) return 0;
    std::fwrite(data + 1, 1, size - 1, f);
    std::fclose(f);
    lpm::EnvReadOptions o;
    o.path = path;
    try {
        (void)lpm::readEnvironment(o);
    } catch (const lpm::Error&) {
    }
    return 0;
}

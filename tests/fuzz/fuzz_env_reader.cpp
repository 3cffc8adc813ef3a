// libFuzzer target for the environment image decoder (vdb_io/image_codec, what the helper
// lpmbake-image runs for vdb_io/env_reader): the first byte picks the file extension
// (.exr or .hdr), the rest is written to a temporary file and decoded in this process.
// std::runtime_error is the expected outcome for bad input; anything else is a finding.
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <string>

#include <stdexcept>

#include "vdb_io/image_codec.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
    if (size < 1) return 0;
    const char* ext = (data[0] & 1) ? ".hdr" : ".exr";
    const std::string path = "/tmp/lpm_fuzz_env_" + std::to_string(::getpid()) + ext;
    FILE* f = std::fopen(path.c_str(), "wb");
    if (!f) return 0;
    std::fwrite(data + 1, 1, size - 1, f);
    std::fclose(f);
    try {
        (void)lpm::decodeImageFile(path);
    } catch (const std::runtime_error&) {
    }
    return 0;
}

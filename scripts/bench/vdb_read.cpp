// What the VDB layout walk (vdb_io/vdb_file) costs: reads one float grid of N^3 active
// voxels (a noisy fog block, so Blosc cannot collapse it) with plain io::File and with
// VdbFile, best of 5 each, for each compression.
//   lpm_bench_vdb_read [--n 256] [--dir /tmp]
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>

#include <openvdb/io/File.h>

#include "vdb_io/vdb_file.h"
#include "vdb_io/volume_reader.h"

namespace {

double seconds(const std::chrono::steady_clock::time_point& t0) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

template <typename F>
double best(F f) {
    double b = 1e30;
    for (int i = 0; i < 5; ++i) {
        const auto t0 = std::chrono::steady_clock::now();
        f();
        b = std::min(b, seconds(t0));
    }
    return b;
}

}  // namespace

int main(int argc, char** argv) {
    int n = 256;
    std::string dir = std::filesystem::temp_directory_path().string();
    for (int i = 1; i + 1 < argc; i += 2) {
        if (!std::strcmp(argv[i], "--n")) n = std::atoi(argv[i + 1]);
        if (!std::strcmp(argv[i], "--dir")) dir = argv[i + 1];
    }
    lpm::initOpenVdb();
    auto g = openvdb::FloatGrid::create(0.f);
    g->setName("density");
    auto acc = g->getAccessor();
    for (int x = 0; x < n; ++x)
        for (int y = 0; y < n; ++y)
            for (int z = 0; z < n; ++z)
                acc.setValue(openvdb::Coord(x, y, z), 0.5f + 0.5f * std::sin(0.37f * x + 0.61f * y * z));
    std::printf("grid: %d^3 active voxels, %zu leaves\n", n, size_t(g->tree().leafCount()));
    std::printf("| compression | file MiB | io::File read | VdbFile read | walk overhead |\n|---|---|---|---|---|\n");
    const struct {
        const char* name;
        std::uint32_t flags;
    } modes[] = {{"none", openvdb::io::COMPRESS_NONE},
                 {"zip+mask", openvdb::io::COMPRESS_ZIP | openvdb::io::COMPRESS_ACTIVE_MASK},
                 {"blosc+mask", openvdb::io::COMPRESS_BLOSC | openvdb::io::COMPRESS_ACTIVE_MASK}};
    for (const auto& m : modes) {
        const std::string path = dir + "/lpm_bench_vdb_read_" + m.name + ".vdb";
        openvdb::io::File out(path);
        out.setCompression(m.flags);
        out.write(openvdb::GridPtrVec{g});
        out.close();
        const double plain = best([&] {
            openvdb::io::File f(path);
            f.open(false);
            f.readGrid("density");
        });
        const double checked = best([&] { lpm::VdbFile(path).readGrid("density"); });
        std::printf("| %s | %.1f | %.3f s | %.3f s | %+.1f%% |\n", m.name,
                    double(std::filesystem::file_size(path)) / (1 << 20), plain, checked,
                    100.0 * (checked - plain) / plain);
        std::filesystem::remove(path);
    }
    return 0;
}

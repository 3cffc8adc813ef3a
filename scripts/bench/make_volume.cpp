// Procedural benchmark volumes written as OpenVDB fog volumes (no large files in the repo):
//   lpm_make_volume plume OUT.vdb [--res N] [--seed S]
//       a rising turbulent smoke plume in an N x 2N x N box (Y up); N = 112 gives about
//       1M active voxels in a 2.8M-voxel box, like a production Mantaflow smoke
//   lpm_make_volume puffs OUT.vdb [--res N] [--count 1|2] [--radius R] [--corner near|far]
//       one small noisy puff (radius R, default N/16), or two at opposite corners of an
//       N^3 box: time must follow the active voxels, not the box. With --count 1,
//       --corner far writes the pair's second puff alone (default near: its first)
//   lpm_make_volume cloud OUT.vdb [--res N]
//       a dense cumulus-like cloud filling most of an N^3 box (about 0.25 N^3 active voxels:
//       N = 256: 4.2M, N = 585: 50M, N = 1024: 268M)
//   --box B (any kind): also one faint voxel at (0,0,0) and one at (B-1,B-1,B-1), so the
//       active bounding box is B^3 (cloud --res 585 --box 1024: 50M voxels in a 1024^3 box)
// Density is fBm value noise shaped by an envelope; voxels below 1e-3 stay inactive.
#include <openvdb/openvdb.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

namespace {

// Value noise on the integer lattice, smoothly interpolated; hash by a 64-bit mix.
float latticeValue(int x, int y, int z, std::uint64_t seed) {
    std::uint64_t h = seed ^ (std::uint64_t(std::uint32_t(x)) * 0x9E3779B97F4A7C15ull) ^
                      (std::uint64_t(std::uint32_t(y)) * 0xC2B2AE3D27D4EB4Full) ^
                      (std::uint64_t(std::uint32_t(z)) * 0x165667B19E3779F9ull);
    h ^= h >> 33;
    h *= 0xFF51AFD7ED558CCDull;
    h ^= h >> 33;
    return float(h >> 40) / float(1 << 24);
}

float valueNoise(float x, float y, float z, std::uint64_t seed) {
    const int ix = int(std::floor(x)), iy = int(std::floor(y)), iz = int(std::floor(z));
    auto fade = [](float t) { return t * t * (3 - 2 * t); };
    const float fx = fade(x - ix), fy = fade(y - iy), fz = fade(z - iz);
    float c[2][2];
    for (int dz = 0; dz < 2; ++dz)
        for (int dy = 0; dy < 2; ++dy) {
            const float a = latticeValue(ix, iy + dy, iz + dz, seed), b = latticeValue(ix + 1, iy + dy, iz + dz, seed);
            c[dz][dy] = a + (b - a) * fx;
        }
    const float y0 = c[0][0] + (c[0][1] - c[0][0]) * fy, y1 = c[1][0] + (c[1][1] - c[1][0]) * fy;
    return y0 + (y1 - y0) * fz;
}

float fbm(float x, float y, float z, std::uint64_t seed, int octaves = 5) {
    float sum = 0, amp = 0.5f, f = 1;
    for (int o = 0; o < octaves; ++o) {
        sum += amp * valueNoise(x * f, y * f, z * f, seed + std::uint64_t(o) * 1013);
        amp *= 0.5f;
        f *= 2.03f;
    }
    return sum;  // about [0, 1)
}

// Plume: a column rising from the floor, widening and breaking up with height.
float plumeDensity(int x, int y, int z, int n, std::uint64_t seed) {
    const float h = float(y) / (2.0f * n);  // 0 at the floor, 1 at the top
    const float cx = (x + 0.5f) / n - 0.5f, cz = (z + 0.5f) / n - 0.5f;
    const float sway = 0.08f * std::sin(6.0f * h) * h;
    const float radius = 0.06f + 0.34f * std::sqrt(h);
    const float d = std::sqrt((cx - sway) * (cx - sway) + cz * cz) / radius;
    const float turb = fbm(x * 0.06f, y * 0.045f, z * 0.06f, seed);
    const float body = 1.0f - d + 0.9f * (turb - 0.5f);
    if (body <= 0 || h > 0.97f) return 0;
    const float fade = std::min(1.0f, (0.97f - h) * 10.0f) * (1.0f - 0.5f * h);
    return std::min(1.0f, body * 2.5f) * fade;
}

float puffDensity(float x, float y, float z, float cx, float cy, float cz, float radius, std::uint64_t seed) {
    const float dx = x - cx, dy = y - cy, dz = z - cz;
    const float d = std::sqrt(dx * dx + dy * dy + dz * dz) / radius;
    const float body = 1.0f - d + 0.6f * (fbm(x * 0.15f, y * 0.15f, z * 0.15f, seed) - 0.5f);
    return body > 0 ? std::min(1.0f, body * 3.0f) : 0.0f;
}

// Cumulus: a flattened blob with a billowy top filling most of the box.
float cloudDensity(int x, int y, int z, int n, std::uint64_t seed) {
    const float px = (x + 0.5f) / n - 0.5f, py = (y + 0.5f) / n - 0.4f, pz = (z + 0.5f) / n - 0.5f;
    const float d = std::sqrt(px * px / 0.2f + py * py / 0.09f + pz * pz / 0.2f);
    const float s = 8.0f / n;
    const float body = 1.0f - d + 0.8f * (fbm(x * s, y * s, z * s, seed) - 0.5f);
    return body > 0 ? std::min(1.0f, body * 4.0f) : 0.0f;
}

int usage() {
    std::fprintf(stderr,
                 "usage: lpm_make_volume plume|puffs|cloud OUT.vdb [--res N] [--count 1|2] [--radius R] [--corner "
                 "near|far] [--seed S] [--box B]\n");
    return 2;
}

}  // namespace

int main(int argc, char** argv) {
    if (argc < 3) return usage();
    const std::string kind = argv[1], out = argv[2];
    int n = kind == "plume" ? 112 : (kind == "puffs" ? 512 : 256), count = 2, boxSide = 0;
    float puffRadius = 0;         // 0: N / 16
    std::string corner = "near";  // which of the pair's puffs --count 1 writes
    std::uint64_t seed = 7;
    for (int i = 3; i + 1 < argc; i += 2) {
        const std::string k = argv[i];
        if (k == "--res") n = std::atoi(argv[i + 1]);
        else if (k == "--count") count = std::atoi(argv[i + 1]);
        else if (k == "--seed") seed = std::strtoull(argv[i + 1], nullptr, 10);
        else if (k == "--box") boxSide = std::atoi(argv[i + 1]);
        else if (k == "--radius") puffRadius = float(std::atof(argv[i + 1]));
        else if (k == "--corner") corner = argv[i + 1];
        else return usage();
    }
    if (n < 8 || n > 4096 || count < 1 || count > 2 || boxSide < 0 || boxSide > 8192) return usage();
    if (!(puffRadius >= 0) || puffRadius * 4 > n) return usage();  // two puffs must fit apart
    if (corner != "near" && corner != "far") return usage();
    openvdb::initialize();
    auto grid = openvdb::FloatGrid::create(0.0f);
    grid->setName("density");
    grid->setGridClass(openvdb::GRID_FOG_VOLUME);
    auto acc = grid->getAccessor();
    if (kind == "plume") {
        for (int z = 0; z < n; ++z)
            for (int y = 0; y < 2 * n; ++y)
                for (int x = 0; x < n; ++x) {
                    const float d = plumeDensity(x, y, z, n, seed);
                    if (d > 1e-3f) acc.setValue(openvdb::Coord(x, y, z), d);
                }
    } else if (kind == "puffs") {
        const float radius = puffRadius > 0 ? puffRadius : n / 16.0f, lo = radius * 1.5f, hi = n - radius * 1.5f;
        const float centres[2][3] = {{lo, lo, lo}, {hi, hi, hi}};
        const int first = count == 1 && corner == "far" ? 1 : 0;
        for (int p = first; p < first + count; ++p) {
            const float* c = centres[p];
            const int r = int(std::ceil(radius * 1.4f));
            for (int z = int(c[2]) - r; z <= int(c[2]) + r; ++z)
                for (int y = int(c[1]) - r; y <= int(c[1]) + r; ++y)
                    for (int x = int(c[0]) - r; x <= int(c[0]) + r; ++x) {
                        const float d = puffDensity(float(x), float(y), float(z), c[0], c[1], c[2], radius, seed);
                        if (d > 1e-3f) acc.setValue(openvdb::Coord(x, y, z), d);
                    }
        }
    } else if (kind == "cloud") {
        for (int z = 0; z < n; ++z)
            for (int y = 0; y < n; ++y)
                for (int x = 0; x < n; ++x) {
                    const float d = cloudDensity(x, y, z, n, seed);
                    if (d > 1e-3f) acc.setValue(openvdb::Coord(x, y, z), d);
                }
    } else {
        return usage();
    }
    if (boxSide > 0) {
        acc.setValue(openvdb::Coord(0, 0, 0), 0.01f);
        acc.setValue(openvdb::Coord(boxSide - 1, boxSide - 1, boxSide - 1), 0.01f);
    }
    grid->pruneGrid();
    const openvdb::CoordBBox box = grid->evalActiveVoxelBoundingBox();
    std::printf("%s: %llu active voxels in a %dx%dx%d box\n", out.c_str(), (unsigned long long)grid->activeVoxelCount(),
                box.dim().x(), box.dim().y(), box.dim().z());
    openvdb::io::File file(out);
    file.setCompression(openvdb::io::COMPRESS_BLOSC);
    file.write({grid});
    return 0;
}

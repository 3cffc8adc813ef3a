// Sparse tiled storage: index/coord round trip, memory follows the allocated tiles, and
// the solver and the MC reference give the same answer on sparse and dense storage.
#include "core/medium.h"

#include <gtest/gtest.h>

#include <cstring>

#include "core/lpm_solver.h"
#include "core/mc_reference.h"
#include "test_scenes.h"

using namespace lpm;
using namespace lpm::test;

namespace {
// Two blobs in opposite corners of a 32^3 block: most tiles are empty.
Medium twoBlobs(bool sparse) {
    const int n = 32;
    std::vector<std::uint8_t> active;
    Medium probe;
    probe.nx = probe.ny = probe.nz = n;
    active.assign(size_t(probe.tilesX()) * probe.tilesY() * probe.tilesZ(), 0);
    auto density = [](int x, int y, int z) {
        auto blob = [](double dx, double dy, double dz, double r) {
            return std::max(0.0, 1.0 - (dx * dx + dy * dy + dz * dz) / (r * r));
        };
        return 0.6 * blob(x - 6.5, y - 7.5, z - 6.5, 6) + 0.4 * blob(x - 25.5, y - 24.5, z - 26.5, 5);
    };
    for (int z = 0; z < n; ++z)
        for (int y = 0; y < n; ++y)
            for (int x = 0; x < n; ++x)
                if (density(x, y, z) > 0)
                    active[size_t(x / 8) +
                           size_t(probe.tilesX()) * (size_t(y / 8) + size_t(probe.tilesY()) * (z / 8))] = 1;
    Medium m;
    m.allocate(n, n, n, sparse ? &active : nullptr, true);
    for (int z = 0; z < n; ++z)
        for (int y = 0; y < n; ++y)
            for (int x = 0; x < n; ++x) {
                const double d = density(x, y, z);
                if (d <= 0) continue;
                m.sigmaT[m.index(x, y, z)] = float(d);
                if (x < 12) m.emission[m.index(x, y, z)] = RGB(0.5f, 0.2f, 0.1f);
            }
    m.albedo = RGB(0.7f, 0.6f, 0.5f);
    m.g = 0.4;
    return m;
}
}  // namespace

TEST(Medium, SparseIndexRoundTripAndMemory) {
    const Medium s = twoBlobs(true), d = twoBlobs(false);
    EXPECT_TRUE(s.sparse());
    EXPECT_FALSE(d.sparse());
    EXPECT_EQ(d.voxelCount(), 32u * 32 * 32);
    EXPECT_LT(s.voxelCount(), d.voxelCount() / 3);  // memory follows the active tiles (8 of 64)
    EXPECT_EQ(s.voxelCount() % Medium::kTileVoxels, 0u);
    for (int z = 0; z < 32; z += 3)
        for (int y = 0; y < 32; y += 5)
            for (int x = 0; x < 32; x += 7) {
                const size_t v = s.index(x, y, z);
                if (v == Medium::npos) continue;
                int a, b, c;
                s.coord(v, a, b, c);
                EXPECT_EQ(a, x);
                EXPECT_EQ(b, y);
                EXPECT_EQ(c, z);
            }
    EXPECT_EQ(s.index(20, 20, 0), Medium::npos);
    const std::vector<std::uint8_t> wrong(3, 1);
    EXPECT_THROW(Medium().allocate(9, 9, 9, &wrong), Error);
}

TEST(Medium, SparseAndDenseSolvesAgree) {
    const Medium s = twoBlobs(true), d = twoBlobs(false);
    const EnvMap sky = makeSky(32);
    Lights lights;
    lights.env = &sky;
    lights.suns.push_back({normalize(Vec3{0.3, 1, -0.2}), RGB(2.0f), 0.5});
    LpmSettings quick;  // storage equivalence, not accuracy: a cheap angular setting
    quick.directionsPerFace = 2;
    const LpmResult rs = solveLpm(s, lights, quick), rd = solveLpm(d, lights, quick);
    EXPECT_EQ(rs.passes.size(), rd.passes.size());
    EXPECT_NEAR(rs.injected, rd.injected, 1e-9 * rd.injected);
    size_t compared = 0;
    for (int z = 0; z < 32; ++z)
        for (int y = 0; y < 32; ++y)
            for (int x = 0; x < 32; ++x) {
                const size_t vs = s.index(x, y, z), vd = d.index(x, y, z);
                if (vs == Medium::npos || d.sigmaT[vd] <= 0) continue;
                for (int k = 0; k < rs.coeffs; ++k)
                    for (int c = 0; c < 3; ++c)
                        ASSERT_EQ(rs.coeff(vs, k)[c], rd.coeff(vd, k)[c]) << x << "," << y << "," << z;
                ++compared;
            }
    EXPECT_GT(compared, 800u);
    // Subdivision keeps sparsity and agrees too.
    LpmSettings two = quick;
    two.subdivide = 2;
    two.maxOrders = 2;
    const LpmResult ss = solveLpm(s, lights, two), sd = solveLpm(d, lights, two);
    const size_t vs = s.index(6, 7, 6), vd = d.index(6, 7, 6);
    EXPECT_EQ(ss.coeff(vs, 0)[0], sd.coeff(vd, 0)[0]);
}

TEST(Medium, SparseAndDenseMonteCarloAgree) {
    const Medium s = twoBlobs(true), d = twoBlobs(false);
    const EnvMap sky = makeSky(32);
    Lights lights;
    lights.env = &sky;
    const auto es = mcVoxelSH(s, lights, {s.index(6, 7, 6), s.index(25, 24, 26)}, 200, 1);
    const auto ed = mcVoxelSH(d, lights, {d.index(6, 7, 6), d.index(25, 24, 26)}, 200, 1);
    // Streams are seeded by storage index, which differs: compare statistically.
    for (int i = 0; i < 2; ++i)
        EXPECT_NEAR(es[i].mean[0], ed[i].mean[0], 5 * std::hypot(es[i].stdErr[0], ed[i].stdErr[0]));
}

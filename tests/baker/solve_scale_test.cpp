// lpmbake --solve-scale end to end: S = 1 is today's bake bit for bit, other scales agree
// with it inside a homogeneous cube, keep the input's topology, record the solve grid, and
// bad values are one-line usage errors.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <cstring>
#include <filesystem>

#include "../vdb_io/test_helpers.h"
#include "run_helpers.h"
#include "vdb_io/bake_file.h"

using namespace lpm;
using lpmtest::dataPath;
using lpmtest::runLpmbake;

namespace {

const std::vector<std::string> kCheap = {"--directions-per-face", "2", "--tolerance", "1e-2", "--rays-per-voxel", "1"};

std::vector<std::string> torusArgs(const std::string& out, const std::vector<std::string>& more = {}) {
    std::vector<std::string> a = {dataPath("vdb/torus01.vdb"),
                                  "--grid",
                                  "voxel_fog_density",
                                  "--env",
                                  dataPath("env/rooftop_small.hdr"),
                                  "--sun",
                                  "0.3,0.8,0.5",
                                  "-o",
                                  out};
    a.insert(a.end(), kCheap.begin(), kCheap.end());
    a.insert(a.end(), more.begin(), more.end());
    return a;
}

openvdb::FloatGrid::Ptr readTorus() {
    initOpenVdb();
    openvdb::io::File in(dataPath("vdb/torus01.vdb"));
    in.open(false);
    return openvdb::gridPtrCast<openvdb::FloatGrid>(in.readGrid("voxel_fog_density"));
}

/// Largest and mean |a - b| / |b| over the voxels of `b` (red channel of sh_0) whose
/// index lies in [lo, hi]^3.
struct RelDiff {
    double max = 0, mean = 0;
    size_t n = 0;
};
RelDiff relDiff(const openvdb::Vec3SGrid& a, const openvdb::Vec3SGrid& b, int lo, int hi) {
    RelDiff d;
    auto acc = a.getConstAccessor();
    for (auto it = b.cbeginValueOn(); it; ++it) {
        const openvdb::Coord c = it.getCoord();
        if (c.x() < lo || c.y() < lo || c.z() < lo || c.x() > hi || c.y() > hi || c.z() > hi) continue;
        for (int k = 0; k < 3; ++k) {
            const double r = std::fabs(double(acc.getValue(c)[k]) - (*it)[k]) / std::fabs(double((*it)[k]));
            d.max = std::max(d.max, r);
            d.mean += r;
            ++d.n;
        }
    }
    if (d.n) d.mean /= double(d.n);
    return d;
}

}  // namespace

// (a) --solve-scale 1 is the default: the same code path, bit-identical SH.
TEST(SolveScale, OneIsBitIdenticalToNoFlag) {
    const std::string dir = lpmtest::scratchDir();
    auto r = runLpmbake(torusArgs(dir + "/none.vdb"), dir);
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(r.err.find("solve grid"), std::string::npos) << "no resampling note at S = 1";
    r = runLpmbake(torusArgs(dir + "/one.vdb", {"--solve-scale", "1"}), dir);
    ASSERT_EQ(r.code, 0) << r.err;
    const BakeFile a = readBakeFile(dir + "/none.vdb"), b = readBakeFile(dir + "/one.vdb");
    ASSERT_EQ(a.sh.size(), b.sh.size());
    for (size_t k = 0; k < a.sh.size(); ++k) {
        ASSERT_TRUE(a.sh[k]->tree().hasSameTopology(b.sh[k]->tree()));
        auto acc = b.sh[k]->getConstAccessor();
        size_t n = 0;
        for (auto it = a.sh[k]->cbeginValueOn(); it; ++it, ++n)
            ASSERT_EQ(std::memcmp(&*it, &acc.getValue(it.getCoord()), sizeof(openvdb::Vec3s)), 0) << it.getCoord();
        EXPECT_GT(n, 0u);
    }
    EXPECT_EQ(metaDouble(*b.meta, "lpm:solve_scale", 0), 1.0);
}

// (b) A homogeneous cube under a uniform sky and a sun: the interior (3 voxels and more
// from the surface) agrees with the S = 1 bake at S = 0.5 and S = 2. The differences are
// the solver's discretisation error at the other voxel size plus the interpolation back.
// Measured (default solver settings, deterministic for any thread count), |a - b| / |b| of
// sh_0 over 1000 interior voxels x RGB:
//   S = 0.5: max 0.0299, mean 0.0205      S = 2: max 0.0041, mean 0.0029
// The bounds leave about a third on top of that for solver changes in core/.
TEST(SolveScale, HomogeneousCubeAgreesAcrossScales) {
    const std::string dir = lpmtest::scratchDir();
    // 16^3 voxels of 0.25: a 4-unit cube, sigma_t 1 -> optical depth 4 edge to edge.
    lpmtest::writeVdb(dir + "/cube.vdb", {lpmtest::cubeGrid(16, 1.f, 0.25)});
    lpmtest::writeLatLong(dir + "/sky.exr", 64, 32, [](const Vec3&) { return RGB(1.f); });
    auto bake = [&](const std::string& s) {
        const std::string out = dir + "/cube_" + s + ".vdb";
        const auto r = runLpmbake({dir + "/cube.vdb", "--env", dir + "/sky.exr", "--sun", "0.3,0.8,0.5",
                                   "--sun-irradiance", "2", "--solve-scale", s, "-o", out},
                                  dir);
        EXPECT_EQ(r.code, 0) << r.err;
        return readBakeFile(out);
    };
    const BakeFile ref = bake("1"), halved = bake("0.5"), twice = bake("2");
    ASSERT_EQ(ref.sh.size(), 1u) << "g = 0: band 0 only";
    ASSERT_EQ(halved.sh.size(), 1u);
    ASSERT_EQ(twice.sh.size(), 1u);
    const RelDiff dh = relDiff(*halved.sh[0], *ref.sh[0], 3, 12), d2 = relDiff(*twice.sh[0], *ref.sh[0], 3, 12);
    EXPECT_EQ(dh.n, 10u * 10 * 10 * 3);
    EXPECT_LT(dh.max, 0.04);
    EXPECT_LT(dh.mean, 0.028);
    EXPECT_LT(d2.max, 0.0055);
    EXPECT_LT(d2.mean, 0.004);
    // The solve grids: (16 * S) + 2 pad voxels per axis, 2 x 2 at S = 2 (the lighting
    // shell's centres must fall between solve-voxel centres).
    auto dims = [](const BakeFile& f) { return f.meta->metaValue<openvdb::Vec3i>("lpm:solve_grid_dims"); };
    EXPECT_EQ(dims(ref), openvdb::Vec3i(18, 18, 18));
    EXPECT_EQ(dims(halved), openvdb::Vec3i(10, 10, 10));
    EXPECT_EQ(dims(twice), openvdb::Vec3i(36, 36, 36));
    EXPECT_NEAR(halved.meta->metaValue<openvdb::Vec3d>("lpm:solve_voxel_size").x(), 0.5, 1e-12);
    EXPECT_NEAR(twice.meta->metaValue<openvdb::Vec3d>("lpm:solve_voxel_size").z(), 0.125, 1e-12);
}

// (d) Whatever the solve grid, the output lives on the input's transform, the density on
// its active voxels and the lighting grids on those plus the one-voxel shell (docs/
// output_format.md); the solve grid is recorded in the metadata, the stats and a stderr note.
TEST(SolveScale, OutputKeepsInputTopologyAndRecordsTheGrid) {
    const std::string dir = lpmtest::scratchDir();
    auto src = readTorus();
    ASSERT_TRUE(src);
    for (const std::string s : {"0.5", "2", "0.3"}) {
        const std::string out = dir + "/t" + s + ".vdb", stats = dir + "/s" + s + ".json";
        const auto r =
            runLpmbake(torusArgs(out, {"--solve-scale", s, "--g", "0.5", "--sh-order", "1", "--stats", stats}), dir);
        ASSERT_EQ(r.code, 0) << r.err;
        EXPECT_NE(r.err.find("lpmbake: solve grid "), std::string::npos) << r.err;
        EXPECT_NE(r.err.find("(--solve-scale " + s), std::string::npos) << r.err;
        const BakeFile b = readBakeFile(out);
        EXPECT_TRUE(validateBake(b).empty());
        ASSERT_EQ(b.sh.size(), 4u);
        for (const auto& g : b.sh) {
            lpmtest::expectLightingTopology(*g, *src);  // the density's voxels and the shell, none dropped
            EXPECT_TRUE(g->transform() == src->transform());
        }
        lpmtest::expectLightingTopology(*b.scatter, *src);
        ASSERT_TRUE(b.density);
        EXPECT_TRUE(b.density->tree().hasSameTopology(src->tree()));
        double maxS = 0;
        for (auto it = b.scatter->cbeginValueOn(); it; ++it) {
            for (int c = 0; c < 3; ++c) ASSERT_TRUE(std::isfinite((*it)[c]) && (*it)[c] >= 0);
            maxS = std::max(maxS, double((*it)[0]));
        }
        EXPECT_GT(maxS, 0);
        EXPECT_DOUBLE_EQ(metaDouble(*b.meta, "lpm:solve_scale", 0), std::stod(s));
        const openvdb::Vec3d vs = b.meta->metaValue<openvdb::Vec3d>("lpm:solve_voxel_size");
        EXPECT_NEAR(vs.x(), src->voxelSize().x() / std::stod(s), 1e-9);
        const openvdb::Vec3i d = b.meta->metaValue<openvdb::Vec3i>("lpm:solve_grid_dims");
        const std::string dimsText = std::to_string(d.x()) + "x" + std::to_string(d.y()) + "x" + std::to_string(d.z());
        EXPECT_NE(r.err.find("solve grid " + dimsText), std::string::npos) << r.err;
        const nlohmann::json js = nlohmann::json::parse(lpmtest::readAll(stats));
        EXPECT_EQ(js["solve_grid"]["solve_scale"].get<double>(), std::stod(s));
        EXPECT_EQ(js["solve_grid"]["dims"], nlohmann::json::array({d.x(), d.y(), d.z()})) << js.dump();
        EXPECT_EQ(js["voxels"]["stored"].get<std::uint64_t>(), std::uint64_t(d.x()) * d.y() * d.z());
    }
    EXPECT_EQ(runLpmbake({"info", dir + "/t0.5.vdb"}, dir).code, 0);
}

// (e) Out-of-range or non-numeric scales: exit 1 with one error line naming the value.
TEST(SolveScale, BadValuesAreUsageErrors) {
    const std::string dir = lpmtest::scratchDir();
    const std::string out = dir + "/o.vdb";
    for (const std::string v : {"0", "-1", "nan", "20", "inf", "0.01", "abc", "1,2"}) {
        const auto r = runLpmbake(torusArgs(out, {"--solve-scale", v}), dir);
        EXPECT_EQ(r.code, 1) << v << ": " << r.err;
        EXPECT_EQ(r.signal, 0);
        EXPECT_EQ(r.errLines(), 1) << r.err;
        EXPECT_EQ(r.err.rfind("lpmbake: error: usage: --solve-scale", 0), 0u) << r.err;
        EXPECT_NE(r.err.find(v), std::string::npos) << "names the value: " << r.err;
    }
    EXPECT_FALSE(std::filesystem::exists(out));
    EXPECT_NE(runLpmbake({"--help"}, dir).out.find("--solve-scale"), std::string::npos);
    // The largest scale passes validation, and the solve block is held to --max-voxels:
    // the torus's 24x11x24 block at S = 1 fits in 100000 voxels, its ~178x74x178 at S = 8
    // does not.
    const auto r = runLpmbake(torusArgs(out, {"--solve-scale", "8", "--max-voxels", "100000"}), dir);
    EXPECT_EQ(r.code, 2) << r.err;
    EXPECT_EQ(r.errLines(), 1) << r.err;
    EXPECT_NE(r.err.find("--max-voxels"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("smaller --solve-scale"), std::string::npos) << r.err;
}

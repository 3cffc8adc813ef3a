// lpmbake end to end: exit codes, one-line errors, a real bake with its metadata and
// stats, info, render, atomic output. Cheap solver settings keep it fast.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cstdlib>
#include <fstream>

#include <sys/stat.h>

#include <openvdb/tools/LevelSetSphere.h>

#include "../vdb_io/test_helpers.h"
#include "core/blackbody.h"
#include "run_helpers.h"
#include "vdb_io/bake_file.h"
#include "vdb_io/bake_schema.h"

using namespace lpm;
using lpmtest::dataPath;
using lpmtest::runLpmbake;
namespace fs = std::filesystem;

namespace {

const std::vector<std::string> kCheap = {"--directions-per-face", "2", "--tolerance", "1e-2", "--rays-per-voxel", "1"};

std::vector<std::string> torusArgs(const std::string& out) {
    std::vector<std::string> a = {dataPath("vdb/torus01.vdb"),
                                  "--grid",
                                  "voxel_fog_density",
                                  "--env",
                                  dataPath("env/rooftop_small.hdr"),
                                  "-o",
                                  out};
    a.insert(a.end(), kCheap.begin(), kCheap.end());
    return a;
}

/// Every failure is exactly one line "lpmbake: error: <component>: ...".
void expectOneLineError(const lpmtest::RunResult& r, int code, const std::string& component,
                        std::initializer_list<std::string> parts = {}) {
    EXPECT_EQ(r.code, code) << r.err;
    EXPECT_EQ(r.signal, 0);
    const std::string prefix = "lpmbake: error: " + component + ": ";
    const size_t at = r.err.find(prefix);
    ASSERT_NE(at, std::string::npos) << r.err;
    const std::string line = r.err.substr(at, r.err.find('\n', at) - at);
    EXPECT_EQ(r.err.find("lpmbake: error:", at + 1), std::string::npos) << "one error line only: " << r.err;
    for (const auto& p : parts) EXPECT_NE(line.find(p), std::string::npos) << "'" << p << "' not in: " << line;
}

size_t tempFilesIn(const std::string& dir) {
    size_t n = 0;
    for (auto& e : fs::directory_iterator(dir)) n += e.path().filename().string().find(".lpmtmp-") != std::string::npos;
    return n;
}

}  // namespace

TEST(Cli, HelpReadsLikeAManPage) {
    const std::string dir = lpmtest::scratchDir();
    const auto r = runLpmbake({"--help"}, dir);
    EXPECT_EQ(r.code, 0);
    for (const char* s : {"NAME", "SYNOPSIS", "DESCRIPTION", "CONVENTIONS", "EXIT STATUS", "EXAMPLES", "--sun",
                          "--env-rotate", "--sh-order", "--stats", "render", "info", "TOWARD the sun"})
        EXPECT_NE(r.out.find(s), std::string::npos) << s;
    EXPECT_EQ(runLpmbake({"render", "--help"}, dir).code, 0);
    EXPECT_NE(runLpmbake({"--version"}, dir).out.find("lpmbake"), std::string::npos);
}

TEST(Cli, UsageErrorsExit1) {
    const std::string dir = lpmtest::scratchDir();
    const std::string out = dir + "/o.vdb";
    expectOneLineError(runLpmbake({"--bogus"}, dir), 1, "usage", {"--bogus"});
    expectOneLineError(runLpmbake({"-o", out, "--sun", "0,1,0"}, dir), 1, "usage", {"no input"});
    expectOneLineError(runLpmbake({dataPath("vdb/torus01.vdb"), "-o", out}, dir), 1, "usage", {"no light"});
    expectOneLineError(
        runLpmbake({dataPath("vdb/torus01.vdb"), "-o", out, "--sun", "0,1", "--sun-irradiance", "1"}, dir), 1, "usage",
        {"--sun", "X,Y,Z"});
    expectOneLineError(runLpmbake({dataPath("vdb/torus01.vdb"), "-o", out, "--sun", "0,1,0", "--sun", "1,0,0",
                                   "--sun-irradiance", "1", "--sun-irradiance", "1", "--sun-irradiance", "1"},
                                  dir),
                       1, "usage", {"--sun-irradiance", "3 times", "2 --sun"});
    expectOneLineError(runLpmbake({dataPath("vdb/torus01.vdb"), "-o", out, "--sun", "0,1,0", "--albedo", "1.5"}, dir),
                       1, "usage", {"--albedo"});
    expectOneLineError(runLpmbake({dataPath("vdb/torus01.vdb"), "-o", out, "--sun", "0,1,0", "--g", "1"}, dir), 1,
                       "usage", {"--g"});
    expectOneLineError(runLpmbake({dataPath("vdb/torus01.vdb"), "-o", out, "--sun", "0,1,0", "--source", "cubic"}, dir),
                       1, "usage", {"--source", "cubic"});
    expectOneLineError(
        runLpmbake({dataPath("vdb/torus01.vdb"), "-o", out, "--sun", "0,1,0", "--rays-higher-orders", "0"}, dir), 1,
        "usage", {"--rays-higher-orders", "got 0"});
    expectOneLineError(
        runLpmbake({dataPath("vdb/torus01.vdb"), "-o", out, "--sun", "0,1,0", "--directions-per-face", "65"}, dir), 1,
        "usage", {"--directions-per-face", "got 65"});
    expectOneLineError(
        runLpmbake({dataPath("vdb/torus01.vdb"), "-o", out, "--sun", "0,1,0", "--krylov-restart", "0"}, dir), 1,
        "usage", {"--krylov-restart", "got 0"});
    expectOneLineError(runLpmbake({"render", dataPath("vdb/torus01.vdb"), "-o", dir + "/x.jpg"}, dir), 1, "usage",
                       {".exr", ".png"});
    expectOneLineError(runLpmbake({dataPath("vdb/torus01.vdb"), "-o", out, "--sun", "0,1,0", "--up-axis", "x"}, dir), 1,
                       "usage", {"--up-axis", "x"});
    EXPECT_FALSE(fs::exists(out));
}

// --renderer-grids: extinction and source, so that a shader needs no constant; the grids
// agree with the density, the constants and scatter.
TEST(Cli, RendererGridsAreConstantFree) {
    const std::string dir = lpmtest::scratchDir();
    auto a = torusArgs(dir + "/out.vdb");
    a.insert(a.end(), {"--renderer-grids", "--density-scale", "2", "--albedo", "0.8,0.6,0.4"});
    const auto r = runLpmbake(a, dir);
    ASSERT_EQ(r.code, 0) << r.err;
    const BakeFile b = readBakeFile(dir + "/out.vdb");
    EXPECT_TRUE(validateBake(b).empty());
    EXPECT_TRUE(getBool(*b.meta, bakekey::rendererGrids, false));
    openvdb::FloatGrid::Ptr ext;
    openvdb::Vec3SGrid::Ptr src;
    for (const auto& g : b.grids) {
        if (g->getName() == "extinction") ext = openvdb::gridPtrCast<openvdb::FloatGrid>(g);
        if (g->getName() == "source") src = openvdb::gridPtrCast<openvdb::Vec3SGrid>(g);
    }
    ASSERT_TRUE(ext && src);
    EXPECT_EQ(ext->activeVoxelCount(), b.density->activeVoxelCount());
    int checked = 0;
    auto sAcc = b.scatter->getConstAccessor();
    auto srcAcc = src->getConstAccessor();
    for (auto it = b.density->cbeginValueOn(); it && checked < 500; ++it, ++checked) {
        const float sigmaT = 2 * *it;
        EXPECT_FLOAT_EQ(ext->tree().getValue(it.getCoord()), sigmaT);
        const float rgb[3] = {0.8f, 0.6f, 0.4f};
        for (int c = 0; c < 3; ++c)
            EXPECT_NEAR(srcAcc.getValue(it.getCoord())[c], sigmaT * rgb[c] * sAcc.getValue(it.getCoord())[c],
                        1e-6 * (1 + std::abs(srcAcc.getValue(it.getCoord())[c])));
    }
    EXPECT_EQ(checked, 500);
    // Without the flag, neither grid.
    ASSERT_EQ(runLpmbake(torusArgs(dir + "/plain.vdb"), dir).code, 0);
    for (const auto& g : readBakeFile(dir + "/plain.vdb").grids)
        EXPECT_TRUE(g->getName() != "extinction" && g->getName() != "source") << g->getName();
}

// --compression: none by default, zip on request: the content is the same (equal digests)
// and zip's file is smaller (0.987 of the size on this torus, 0.94 on the 1M smoke; without
// the zip both files are the same size).
TEST(Cli, CompressionNoneByDefaultZipOnRequest) {
    const std::string dir = lpmtest::scratchDir();
    ASSERT_EQ(runLpmbake(torusArgs(dir + "/none.vdb"), dir).code, 0);
    auto a = torusArgs(dir + "/zip.vdb");
    a.insert(a.end(), {"--compression", "zip"});
    ASSERT_EQ(runLpmbake(a, dir).code, 0);
    std::string digest[2];
    for (int k = 0; k < 2; ++k) {
        const auto r = runLpmbake({"info", "--digest", dir + (k ? "/zip.vdb" : "/none.vdb")}, dir);
        ASSERT_EQ(r.code, 0) << r.err;
        digest[k] = r.out;
    }
    EXPECT_EQ(digest[0], digest[1]);
    const double ratio = double(fs::file_size(dir + "/zip.vdb")) / double(fs::file_size(dir + "/none.vdb"));
    EXPECT_LT(ratio, 1.0);
    expectOneLineError(
        runLpmbake({dataPath("vdb/torus01.vdb"), "-o", dir + "/x.vdb", "--sun", "0,1,0", "--compression", "blosc"},
                   dir),
        1, "usage", {"--compression", "blosc"});
}

TEST(Cli, InputErrorsExit2) {
    const std::string dir = lpmtest::scratchDir();
    const std::string out = dir + "/o.vdb";
    std::vector<std::string> a = {dir + "/missing.vdb", "--sun", "0,1,0", "-o", out};
    expectOneLineError(runLpmbake(a, dir), 2, "input", {"missing.vdb"});
    a = {dataPath("vdb/torus01.vdb"), "--sun", "0,1,0", "-o", out};
    expectOneLineError(runLpmbake(a, dir), 2, "input", {"'density'", "voxel_fog_density"});
    a = {dataPath("vdb/smoke_seq.0001.vdb"), "--grid", "velocity", "--sun", "0,1,0", "-o", out};
    expectOneLineError(runLpmbake(a, dir), 2, "input", {"velocity", "vec3s"});
    a = torusArgs(out);
    a[4] = dataPath("env/BrightRingsNanInf.exr");
    expectOneLineError(runLpmbake(a, dir), 2, "env", {"BrightRingsNanInf.exr", "NaN"});
    a.push_back("--sanitize");
    expectOneLineError(runLpmbake(a, dir), 2, "env", {"800x800", "lat-long"});
    // A corrupted VDB: truncated and with flipped bytes.
    std::string bytes = lpmtest::readAll(dataPath("vdb/torus01.vdb"));
    for (size_t i = 200; i < bytes.size(); i += 97) bytes[i] = char(~bytes[i]);
    std::ofstream(dir + "/bad.vdb", std::ios::binary) << bytes.substr(0, bytes.size() * 2 / 3);
    a = {dir + "/bad.vdb", "--grid", "voxel_fog_density", "--sun", "0,1,0", "-o", out};
    const auto r = runLpmbake(a, dir);
    EXPECT_EQ(r.signal, 0) << "no crash on a corrupted file";
    EXPECT_EQ(r.code, 2) << r.err;
    // A level set is refused with the conversion hint, and accepted when asked to convert.
    initOpenVdb();
    auto ls = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(2.0f, openvdb::Vec3f(0.f), 0.5f);
    ls->setName("density");
    lpmtest::writeVdb(dir + "/ls.vdb", {ls});
    a = {dir + "/ls.vdb", "--sun", "0,1,0", "-o", out};
    a.insert(a.end(), kCheap.begin(), kCheap.end());
    expectOneLineError(runLpmbake(a, dir), 2, "input", {"level set", "sdfToFogVolume"});
    a.push_back("--convert-level-set");
    EXPECT_EQ(runLpmbake(a, dir).code, 0);
    EXPECT_TRUE(fs::exists(out));
}

TEST(Cli, BakeInfoAndStats) {
    const std::string dir = lpmtest::scratchDir();
    const std::string out = dir + "/torus_lit.vdb", stats = dir + "/stats.json";
    auto a = torusArgs(out);
    a.insert(a.end(), {"--sun", "0.3,0.8,0.5", "--sun-irradiance", "2,2,1.5", "--g", "0.4", "--sh-order", "1",
                       "--albedo", "0.8,0.85,0.9", "--density-scale", "0.5", "--stats", stats});
    const auto r = runLpmbake(a, dir);
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.err.find("solver: "), std::string::npos) << "solver decisions go to stderr";
    EXPECT_NE(r.err.find("source inside voxels"), std::string::npos) << "the source-shape decision is reported";
    EXPECT_EQ(tempFilesIn(dir), 0u);

    const BakeFile b = readBakeFile(out);
    EXPECT_TRUE(validateBake(b).empty());
    EXPECT_EQ(b.shOrder, 1);
    ASSERT_EQ(b.sh.size(), 4u);
    ASSERT_TRUE(b.density);
    // The density copy keeps the input's topology; the lighting grids add the shell.
    openvdb::io::File in(dataPath("vdb/torus01.vdb"));
    in.open(false);
    auto src = openvdb::gridPtrCast<openvdb::FloatGrid>(in.readGrid("voxel_fog_density"));
    lpmtest::expectLightingTopology(*b.sh[3], *src);
    lpmtest::expectLightingTopology(*b.scatter, *src);
    EXPECT_TRUE(b.density->tree().hasSameTopology(src->tree()));
    EXPECT_TRUE(b.scatter->transform() == src->transform());
    // Lit: positive direction-average everywhere it is defined, finite everywhere.
    double maxS = 0;
    for (auto it = b.scatter->cbeginValueOn(); it; ++it) {
        for (int c = 0; c < 3; ++c) ASSERT_TRUE(std::isfinite((*it)[c]) && (*it)[c] >= 0);
        maxS = std::max(maxS, double((*it)[0]));
    }
    EXPECT_GT(maxS, 0);
    // Metadata a consumer needs, all under the lpm: prefix.
    for (const char* k : {"lpm:format_version",
                          "lpm:version",
                          "lpm:sh_order",
                          "lpm:sh_basis",
                          "lpm:quantity",
                          "lpm:usage",
                          "lpm:units",
                          "lpm:working_colorspace",
                          "lpm:density_scale",
                          "lpm:albedo",
                          "lpm:g",
                          "lpm:lights",
                          "lpm:suns",
                          "lpm:env_file",
                          "lpm:env_colorspace",
                          "lpm:directions_per_face",
                          "lpm:rays_per_voxel",
                          "lpm:tolerance",
                          "lpm:max_orders",
                          "lpm:passes",
                          "lpm:residual",
                          "lpm:input_file",
                          "lpm:input_grid",
                          "lpm:timings",
                          "lpm:storage",
                          "lpm:decisions",
                          "lpm:source_shape"})
        EXPECT_TRUE((*b.meta)[k]) << k;
    EXPECT_DOUBLE_EQ(metaDouble(*b.meta, "lpm:density_scale", 0), 0.5);
    EXPECT_FLOAT_EQ(metaRgb(*b.meta, "lpm:albedo", RGB(0.f)).g, 0.85f);
    EXPECT_EQ(metaString(*b.meta, "lpm:working_colorspace"), "ACEScg");
    EXPECT_EQ(metaString(*b.meta, "lpm:input_grid"), "voxel_fog_density");
    EXPECT_GT(metaInt(*b.meta, "lpm:passes", 0), 0);

    const std::string js = lpmtest::readAll(stats);
    for (const char* k : {"\"timings_s\"", "\"solve\"", "\"write\"", "\"voxels\"", "\"active\"", "\"passes\"",
                          "\"residual\"", "\"peak_rss_mib\"", "\"ray_segments_per_second\"", "\"decisions\""})
        EXPECT_NE(js.find(k), std::string::npos) << k;

    const auto info = runLpmbake({"info", out}, dir);
    EXPECT_EQ(info.code, 0) << info.err;
    for (const char* s :
         {"sh_0", "sh_3", "scatter", "density", "lpm:sh_basis", "NaN/Inf voxels 0", "valid lpmbake bake: yes"})
        EXPECT_NE(info.out.find(s), std::string::npos) << s;
}

TEST(Cli, InfoRejectsNonBakes) {
    const std::string dir = lpmtest::scratchDir();
    auto r = runLpmbake({"info", dataPath("vdb/torus01.vdb")}, dir);
    EXPECT_NE(r.out.find("valid lpmbake bake: no"), std::string::npos);
    expectOneLineError(r, 2, "info", {"torus01.vdb", "not a valid lpmbake bake"});
    expectOneLineError(runLpmbake({"info", dataPath("env/rooftop_small.hdr")}, dir), 2, "input", {"rooftop_small.hdr"});
    // A bake whose SH grid holds NaN is not valid either.
    const std::string out = dir + "/b.vdb";
    ASSERT_EQ(runLpmbake(torusArgs(out), dir).code, 0);
    BakeFile b = readBakeFile(out);
    b.sh[0]->tree().setValue(b.sh[0]->cbeginValueOn().getCoord(), openvdb::Vec3s(NAN, 0, 0));
    openvdb::io::File f(dir + "/nan.vdb");
    f.write(b.grids, *b.meta);
    f.close();
    r = runLpmbake({"info", dir + "/nan.vdb"}, dir);
    expectOneLineError(r, 2, "info", {"NaN"});
}

TEST(Cli, EmptyFrameGivesValidEmptyBake) {
    const std::string dir = lpmtest::scratchDir();
    const std::string out = dir + "/empty.vdb";
    const auto r =
        runLpmbake({dataPath("vdb/smoke_seq.0001.vdb"), "--env", dataPath("env/rooftop_small.hdr"), "-o", out}, dir);
    EXPECT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.err.find("warning:"), std::string::npos);
    EXPECT_NE(r.err.find("no active voxels"), std::string::npos);
    EXPECT_EQ(runLpmbake({"info", out}, dir).code, 0);
}

TEST(Cli, DuplicateGridNamesWarnAndSelect) {
    const std::string dir = lpmtest::scratchDir();
    std::vector<std::string> a = {dataPath("vdb/grids_same_name.vdb"), "--sun", "0,1,0", "-o", dir + "/a.vdb"};
    a.insert(a.end(), kCheap.begin(), kCheap.end());
    auto r = runLpmbake(a, dir);
    EXPECT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.err.find("3 grids named 'density'"), std::string::npos) << r.err;
    a[4] = dir + "/b.vdb";
    a.insert(a.end(), {"--grid-index", "2"});
    r = runLpmbake(a, dir);
    EXPECT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(r.err.find("grids named"), std::string::npos);
    EXPECT_FALSE(readBakeFile(dir + "/a.vdb").sh[0]->transform() == readBakeFile(dir + "/b.vdb").sh[0]->transform());
}

TEST(Cli, OutputErrorsExit3AndInputUntouched) {
    const std::string dir = lpmtest::scratchDir();
    const std::string in = dir + "/in.vdb";
    fs::copy_file(dataPath("vdb/torus01.vdb"), in);
    const auto size = fs::file_size(in);
    auto a = torusArgs(in);
    a[0] = in;
    expectOneLineError(runLpmbake(a, dir), 3, "output", {"in.vdb", "input"});
    EXPECT_EQ(fs::file_size(in), size);
    a = torusArgs(dir + "/no/such/dir/out.vdb");
    expectOneLineError(runLpmbake(a, dir), 3, "output", {"does not exist"});
}

// A full disk: the bake is written to a 64 KiB tmpfs. Mounting needs root (as in CI);
// elsewhere the test says why it skips. Also a read-only output directory.
TEST(Cli, FullDiskAndReadOnlyDirExit3WithoutPartialFile) {
    const std::string dir = lpmtest::scratchDir();
    const std::string small = dir + "/small_fs";
    fs::create_directories(small);
    const std::string mnt = "mount -t tmpfs -o size=64k lpmbake_test_full " + small + " 2>/dev/null";
    if (std::system(mnt.c_str()) != 0) GTEST_SKIP() << "cannot mount a small tmpfs here (needs root)";
    struct Unmount {
        std::string path;
        ~Unmount() { (void)std::system(("umount " + path + " 2>/dev/null").c_str()); }
    } unmount{small};
    expectOneLineError(runLpmbake(torusArgs(small + "/out.vdb"), dir), 3, "output", {"out.vdb", "no space left"});
    EXPECT_FALSE(fs::exists(small + "/out.vdb"));
    EXPECT_EQ(tempFilesIn(small), 0u) << "the temporary file is removed";
    EXPECT_TRUE(fs::is_empty(small));

    // Read-only directory (chmod does not bind root: remount the tmpfs read-only).
    const std::string ro = "mount -o remount,ro " + small + " 2>/dev/null";
    if (std::system(ro.c_str()) == 0) {
        // Refused before any work: the probe at start-up names the directory and the reason.
        const auto r = runLpmbake(torusArgs(small + "/out.vdb"), dir);
        expectOneLineError(r, 3, "output", {"out.vdb", "Read-only file system"});
        EXPECT_EQ(r.err.find("solver:"), std::string::npos) << "no solve before the refusal";
        EXPECT_TRUE(fs::is_empty(small));
    }
}

// A farm kills the job after the data is written but before the rename: nothing may
// appear at the output path, and an older output there stays as it was.
TEST(Cli, KilledWhileWritingLeavesNoFile) {
    const std::string dir = lpmtest::scratchDir();
    const std::string out = dir + "/out.vdb";
    auto r = runLpmbake(torusArgs(out), dir, {{"LPM_TEST_KILL_BEFORE_RENAME", "1"}});
    EXPECT_EQ(r.signal, SIGKILL);
    EXPECT_FALSE(fs::exists(out));
    std::ofstream(out) << "older output";
    r = runLpmbake(torusArgs(out), dir, {{"LPM_TEST_KILL_BEFORE_RENAME", "1"}});
    EXPECT_EQ(r.signal, SIGKILL);
    EXPECT_EQ(lpmtest::readAll(out), "older output");
    // The same run without the hook replaces it with a valid bake.
    r = runLpmbake(torusArgs(out), dir);
    EXPECT_EQ(r.code, 0);
    EXPECT_EQ(runLpmbake({"info", out}, dir).code, 0);
}

TEST(Cli, RenderPngAndExr) {
    const std::string dir = lpmtest::scratchDir();
    const std::string bake = dir + "/b.vdb";
    auto a = torusArgs(bake);
    a.insert(a.end(), {"--sun", "0,1,0", "--sun-irradiance", "3"});
    ASSERT_EQ(runLpmbake(a, dir).code, 0);
    auto r = runLpmbake(
        {"render", bake, "--size", "48x32", "--env", dataPath("env/rooftop_small.hdr"), "-o", dir + "/p.png"}, dir);
    ASSERT_EQ(r.code, 0) << r.err;
    r = runLpmbake(
        {"render", bake, "--size", "48x32", "-o", dir + "/p.exr", "--eye", "-5.8,4,14", "--target", "-5.8,0,4.7"}, dir);
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(tempFilesIn(dir), 0u);

    auto png = OIIO::ImageInput::open(dir + "/p.png");
    ASSERT_TRUE(png);
    EXPECT_EQ(png->spec().width, 48);
    EXPECT_EQ(png->spec().height, 32);
    auto exr = OIIO::ImageInput::open(dir + "/p.exr");
    ASSERT_TRUE(exr);
    EXPECT_EQ(exr->spec().get_string_attribute("lpm:colorspace"), "ACEScg");
    std::vector<float> px(48 * 32 * 3);
    ASSERT_TRUE(exr->read_image(0, 0, 0, 3, OIIO::TypeDesc::FLOAT, px.data()));
    double sum = 0;
    for (float v : px) {
        ASSERT_TRUE(std::isfinite(v));
        sum += v;
    }
    EXPECT_GT(sum, 0) << "the lit torus is in view (black background: no --env)";
    expectOneLineError(runLpmbake({"render", dataPath("vdb/torus01.vdb"), "-o", dir + "/x.png"}, dir), 2, "render",
                       {"not an lpmbake bake"});
}

// OpenImageIO (260 libraries, 95 MiB resident, 0.4 s to load) runs only in the helper
// lpmbake-image (docs/image_helper.md): the dynamic linker's log of a bake with an
// environment and of a PNG render names OpenVDB but never OpenImageIO.
TEST(Cli, ASingleBakeFreesTheSkysPixelsOnceBinned) {
    // The solve reads the environment through its binning only: a single bake frees the
    // pixels before solving (-v says so) and bakes what it baked with them; --verify's
    // Monte Carlo reads them, so there they stay.
    const std::string dir = lpmtest::scratchDir();
    std::vector<std::string> a = torusArgs(dir + "/a.vdb");
    a.push_back("-v");
    auto r = runLpmbake(a, dir);
    ASSERT_EQ(r.code, 0) << r.err.substr(0, 2000);
    EXPECT_NE(r.err.find("environment: binned, its pixels (0.514984 MiB) freed before the solve"), std::string::npos)
        << r.err;
    a = torusArgs(dir + "/b.vdb");
    a.insert(a.end(), {"-v", "--verify", "8"});
    r = runLpmbake(a, dir);
    ASSERT_EQ(r.code, 0) << r.err.substr(0, 2000);
    EXPECT_EQ(r.err.find("freed before the solve"), std::string::npos);
    // The same scattered radiance, voxel for voxel (the files differ in --verify's metadata).
    const BakeFile freed = readBakeFile(dir + "/a.vdb"), kept = readBakeFile(dir + "/b.vdb");
    ASSERT_TRUE(freed.scatter && kept.scatter);
    EXPECT_EQ(freed.scatter->activeVoxelCount(), kept.scatter->activeVoxelCount());
    size_t compared = 0;
    auto keptAcc = kept.scatter->getConstAccessor();
    for (auto v = freed.scatter->cbeginValueOn(); v; ++v, ++compared)
        ASSERT_EQ(*v, keptAcc.getValue(v.getCoord())) << v.getCoord();
    EXPECT_GT(compared, 1000u);
}

TEST(Cli, BakeNeverLoadsOpenImageIO) {
    const std::string dir = lpmtest::scratchDir();
    const std::string bake = dir + "/b.vdb";
    const std::vector<std::pair<std::string, std::string>> ldDebug = {{"LD_DEBUG", "files"}};
    auto r = runLpmbake(torusArgs(bake), dir, ldDebug);
    ASSERT_EQ(r.code, 0) << r.err.substr(0, 2000);
    EXPECT_NE(r.err.find("libopenvdb"), std::string::npos) << "no loader log: the check would mean nothing";
    EXPECT_EQ(r.err.find("libOpenImageIO"), std::string::npos);
    r = runLpmbake(
        {"render", bake, "--size", "24x16", "--env", dataPath("env/rooftop_small.hdr"), "-o", dir + "/p.png"}, dir,
        ldDebug);
    ASSERT_EQ(r.code, 0) << r.err.substr(0, 2000);
    EXPECT_EQ(r.err.find("libOpenImageIO"), std::string::npos);
    EXPECT_TRUE(fs::exists(dir + "/p.png"));

    // Without its helper, lpmbake says so in one line, and writes nothing.
    const std::vector<std::pair<std::string, std::string>> noHelper = {{"LPMBAKE_IMAGE_HELPER", "/nonexistent/helper"}};
    expectOneLineError(runLpmbake(torusArgs(dir + "/c.vdb"), dir, noHelper), 2, "env",
                       {"cannot run /nonexistent/helper"});
    EXPECT_FALSE(fs::exists(dir + "/c.vdb"));
    expectOneLineError(runLpmbake({"render", bake, "--size", "24x16", "-o", dir + "/q.png"}, dir, noHelper), 3,
                       "render", {"cannot run /nonexistent/helper"});
    EXPECT_FALSE(fs::exists(dir + "/q.png"));
    EXPECT_EQ(tempFilesIn(dir), 0u);
}

TEST(Cli, ThreadsDefaultToSlurmAllocation) {
    const std::string dir = lpmtest::scratchDir();
    auto a = torusArgs(dir + "/o.vdb");
    a.insert(a.end(), {"--stats", dir + "/s.json"});
    ASSERT_EQ(runLpmbake(a, dir, {{"SLURM_CPUS_PER_TASK", "1"}}).code, 0);
    EXPECT_NE(lpmtest::readAll(dir + "/s.json").find("\"threads\": 1,"), std::string::npos);
}

// densityAndHeat.vdb: emission from the `heat` grid as the only light.
TEST(Cli, EmissionGridIsALight) {
    const std::string dir = lpmtest::scratchDir();
    const std::string out = dir + "/h.vdb";
    std::vector<std::string> a = {dataPath("vdb/densityAndHeat.vdb"),
                                  "--emission-grid",
                                  "heat",
                                  "--emission-scale",
                                  "2",
                                  "--albedo",
                                  "0.5",
                                  "-o",
                                  out};
    a.insert(a.end(), kCheap.begin(), kCheap.end());
    const auto r = runLpmbake(a, dir);
    ASSERT_EQ(r.code, 0) << r.err;
    const BakeFile b = readBakeFile(out);
    ASSERT_TRUE(b.emission);
    EXPECT_EQ(metaString(*b.meta, "lpm:emission_grid"), "heat");
    // L_e = heat * 2 where the heat grid is sampled at a voxel centre.
    openvdb::io::File in(dataPath("vdb/densityAndHeat.vdb"));
    in.open(false);
    auto heat = openvdb::gridPtrCast<openvdb::FloatGrid>(in.readGrid("heat"));
    ASSERT_TRUE(heat);
    ASSERT_TRUE(heat->transform() == b.emission->transform()) << "same transform in this file: values line up";
    size_t checked = 0;
    for (auto it = b.emission->cbeginValueOn(); it && checked < 200; ++it, ++checked)
        ASSERT_NEAR((*it)[0], 2 * heat->tree().getValue(it.getCoord()), 1e-5);
    float maxS = 0;
    for (auto it = b.scatter->cbeginValueOn(); it; ++it) maxS = std::max(maxS, (*it)[0]);
    EXPECT_GT(maxS, 0) << "scattered light from the emission";
    a[2] = "velocity";
    expectOneLineError(runLpmbake(a, dir), 2, "input", {"'velocity'"});
}

TEST(Cli, TemperatureGridEmitsBlackBody) {
    // A cube at 1800 K (stored as 1.8 kK): black-body emission, red above green above blue,
    // brighter than the same cube at 1500 K; both grids at once is refused.
    const std::string dir = lpmtest::scratchDir();
    auto dens = lpmtest::cubeGrid(6, 1.0f, 1.0, "density");
    auto temp = lpmtest::cubeGrid(6, 1.8f, 1.0, "temperature");
    lpmtest::writeVdb(dir + "/fire.vdb", {dens, temp});
    std::vector<std::string> a = {dir + "/fire.vdb",
                                  "--temperature-grid",
                                  "temperature",
                                  "--temperature-scale",
                                  "1000",
                                  "--temperature-intensity",
                                  "1e4",
                                  "--working-space",
                                  "lin_rec709",
                                  "-o",
                                  dir + "/f.vdb"};
    a.insert(a.end(), kCheap.begin(), kCheap.end());
    auto r = runLpmbake(a, dir);
    ASSERT_EQ(r.code, 0) << r.err;
    const BakeFile b = readBakeFile(dir + "/f.vdb");
    ASSERT_TRUE(b.emission);
    EXPECT_EQ(metaString(*b.meta, "lpm:temperature_grid"), "temperature");
    const openvdb::Vec3s e = b.emission->tree().getValue(openvdb::Coord(3, 3, 3));
    const RGB expect = blackbodyRec709(1800.0) * 1e4f;
    EXPECT_NEAR(e[0], expect.r, 2e-3 * expect.r);
    EXPECT_GT(e[0], e[1]);
    EXPECT_GT(e[1], e[2]);
    // Cooler is dimmer.
    a[4] = "833.3333";  // 1.8 * 833.33 = 1500 K
    a[a.size() - 1 - kCheap.size()] = dir + "/g.vdb";
    r = runLpmbake(a, dir);
    ASSERT_EQ(r.code, 0) << r.err;
    const BakeFile c = readBakeFile(dir + "/g.vdb");
    EXPECT_LT(c.emission->tree().getValue(openvdb::Coord(3, 3, 3))[0], e[0]);
    // Emission and temperature together: one clear error.
    std::vector<std::string> both = a;
    both.insert(both.begin() + 1, {"--emission-grid", "temperature"});
    expectOneLineError(runLpmbake(both, dir), 2, "input", {"--temperature-grid"});
}

TEST(Cli, ShearedTransformIsResampledAndMappedBack) {
    // Index axes (1,0,0), (0.5,1,0), (0,0,1): a slanted box. A vertical sun into an
    // absorbing medium gives S = E/(4 pi) exp(-sigma d), d = distance up to the horizontal
    // top face, so each index layer j has a known value at voxels whose vertical column
    // leaves through the top (index i >= 8: the slanted side is out of the way).
    const std::string dir = lpmtest::scratchDir();
    initOpenVdb();
    auto g = openvdb::FloatGrid::create(0.f);
    g->setName("density");
    openvdb::math::Mat4d mat = openvdb::math::Mat4d::identity();
    mat(1, 0) = 0.5;  // row-vector convention: index y adds 0.5 to world x
    g->setTransform(openvdb::math::Transform::createLinearTransform(mat));
    g->fill(openvdb::CoordBBox(openvdb::Coord(0), openvdb::Coord(15)), 0.3f, true);
    g->tree().voxelizeActiveTiles();
    ASSERT_NEAR(g->transform().indexToWorld(openvdb::Vec3d(0, 1, 0)).x(), 0.5, 1e-12);
    lpmtest::writeVdb(dir + "/shear.vdb", {g});
    const auto r = runLpmbake({dir + "/shear.vdb", "--sun", "0,1,0", "--sun-irradiance", "1", "--sun-angle", "0",
                               "--albedo", "0", "--directions-per-face", "2", "-o", dir + "/s.vdb"},
                              dir);
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.err.find("sheared transform: resampled"), std::string::npos) << r.err;
    const BakeFile b = readBakeFile(dir + "/s.vdb");
    ASSERT_TRUE(b.sh[0]);
    lpmtest::expectLightingTopology(*b.sh[0], *g);  // the sheared block holds the shell too
    double worst = 0;
    for (int j = 0; j < 15; ++j)
        for (int i = 9; i <= 13; ++i)
            for (int k = 5; k <= 10; ++k) {
                const double got =
                    b.sh[0]->tree().getValue(openvdb::Coord(i, j, k))[0] * 0.28209479177387814 * 4 * M_PI;
                const double expect = std::exp(-0.3 * (15.5 - j)) * std::sinh(0.15) / 0.15;  // layer average
                worst = std::max(worst, std::fabs(got / expect - 1));
            }
    EXPECT_LT(worst, 0.02);
}

// The multi-resolution decision: forced on, it is reported, recorded and visible per pass;
// a bad value is a usage error.
TEST(Cli, MultiresIsReportedAndRecorded) {
    const std::string dir = lpmtest::scratchDir();
    const std::string out = dir + "/torus_mr.vdb", stats = dir + "/stats.json";
    auto a = torusArgs(out);
    a.insert(a.end(), {"--sun", "0.3,0.8,0.5", "--multires", "on", "--stats", stats});
    const auto r = runLpmbake(a, dir);
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.err.find("multi-resolution: orders >= 2 on a 2x coarser grid"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("two-grid:"), std::string::npos) << r.err;
    const BakeFile b = readBakeFile(out);
    EXPECT_TRUE(validateBake(b).empty());
    EXPECT_EQ(metaString(*b.meta, "lpm:multires"), "on");
    const std::string js = lpmtest::readAll(stats);
    EXPECT_NE(js.find("\"coarse\": true"), std::string::npos);
    EXPECT_NE(js.find("\"coarse\": false"), std::string::npos);
    expectOneLineError(
        runLpmbake({dataPath("vdb/torus01.vdb"), "-o", dir + "/x.vdb", "--sun", "0,1,0", "--multires", "maybe"}, dir),
        1, "usage", {"--multires", "maybe"});
}

// A bake that misses --tolerance warns, and says what would help: the two-grid solve's
// cycles ran out (more orders would not help), or --max-orders did.
TEST(Cli, UnconvergedBakeSaysWhichCapStoppedIt) {
    const std::string dir = lpmtest::scratchDir();
    // torusArgs' --tolerance 1e-2 -> 1e-4: out of reach of the two-grid cycle on the torus
    // (voxels up to optical depth 40: it stops at residual 4.9%).
    const auto strict = [](std::vector<std::string> a) {
        *(std::find(a.begin(), a.end(), "--tolerance") + 1) = "1e-4";
        return a;
    };
    auto cycles = strict(torusArgs(dir + "/cycles.vdb"));
    cycles.insert(cycles.end(), {"--sun", "0.3,0.8,0.5", "--multires", "on"});
    const auto rc = runLpmbake(cycles, dir);
    ASSERT_EQ(rc.code, 0) << rc.err;
    EXPECT_NE(rc.err.find("the two-grid solve ran its cycles out, so more orders would not help; --multires off"),
              std::string::npos)
        << rc.err;
    auto orders = strict(torusArgs(dir + "/orders.vdb"));
    orders.insert(orders.end(), {"--sun", "0.3,0.8,0.5", "--max-orders", "3"});
    const auto ro = runLpmbake(orders, dir);
    ASSERT_EQ(ro.code, 0) << ro.err;
    EXPECT_NE(ro.err.find("above --tolerance 0.0001 (raise --max-orders)"), std::string::npos) << ro.err;
}

// The torus's voxels reach optical depth 40: the planner shapes the two-grid tail, and
// --two-grid-tail flat / shaped forces either (the plan in the file says which); a value
// outside the three is a one-line error naming the flag.
TEST(Cli, TwoGridTailFollowsThePlanOrTheFlag) {
    const std::string dir = lpmtest::scratchDir();
    const auto decisions = [&](const std::string& name, std::vector<std::string> extra) {
        auto a = torusArgs(dir + "/" + name + ".vdb");
        a.insert(a.end(), {"--sun", "0.3,0.8,0.5", "--multires", "on"});
        a.insert(a.end(), extra.begin(), extra.end());
        const auto r = runLpmbake(a, dir);
        EXPECT_EQ(r.code, 0) << r.err;
        return metaString(*readBakeFile(dir + "/" + name + ".vdb").meta, "lpm:decisions");
    };
    const std::string automatic = decisions("auto", {});
    EXPECT_NE(automatic.find("two-grid tail shaped inside coarse voxels: coarse voxels up to optical depth"),
              std::string::npos)
        << automatic;
    EXPECT_NE(automatic.find("tail shaped by the fine source"), std::string::npos) << automatic;
    const std::string flat = decisions("flat", {"--two-grid-tail", "flat"});
    EXPECT_NE(flat.find("flat two-grid tail: requested"), std::string::npos) << flat;
    EXPECT_NE(flat.find("tail flat"), std::string::npos) << flat;
    auto bad = torusArgs(dir + "/bad.vdb");
    bad.insert(bad.end(), {"--two-grid-tail", "round"});
    const auto rb = runLpmbake(bad, dir);
    EXPECT_NE(rb.code, 0);
    EXPECT_NE(rb.err.find("--two-grid-tail"), std::string::npos) << rb.err;
    EXPECT_FALSE(std::ifstream(dir + "/bad.vdb").good());
}

// At SH order >= 1 the solver holds SH rows only for the voxels the bake writes
// (core/sh_rows.h): the plan names their count, which is the written grids' (at scale 1;
// a resampled solve keeps every row, its output interpolates).
TEST(Cli, DirectionalShIsHeldForTheWrittenVoxels) {
    const std::string dir = lpmtest::scratchDir();
    const std::vector<std::string> lit = {"--sun", "0.3,0.8,0.5", "--g", "0.5", "--density-scale", "0.1"};
    auto a = torusArgs(dir + "/g5.vdb");
    a.insert(a.end(), lit.begin(), lit.end());
    const auto r = runLpmbake(a, dir);
    ASSERT_EQ(r.code, 0) << r.err;
    const BakeFile b = readBakeFile(dir + "/g5.vdb");
    const std::string held = "held for the " + std::to_string(b.scatter->activeVoxelCount()) + " voxels written of ";
    EXPECT_NE(metaString(*b.meta, "lpm:decisions").find(held), std::string::npos)
        << metaString(*b.meta, "lpm:decisions");
    auto h = torusArgs(dir + "/half.vdb");
    h.insert(h.end(), lit.begin(), lit.end());
    h.insert(h.end(), {"--solve-scale", "0.5"});
    const auto resampled = runLpmbake(h, dir);
    ASSERT_EQ(resampled.code, 0) << resampled.err;
    EXPECT_EQ(metaString(*readBakeFile(dir + "/half.vdb").meta, "lpm:decisions").find("voxels written of"),
              std::string::npos);
}

// The exact sun term (docs/sun_term.md): on for g != 0, off for g = 0 (SH order 0 holds
// isotropic single scattering exactly) or --sun-term off; recorded, validated, and the
// SH then hold S without the sun's single scattering while `scatter` keeps it.
TEST(Cli, SunTermIsChosenRecordedAndValidated) {
    const std::string dir = lpmtest::scratchDir();
    auto bake = [&](const std::string& name, std::vector<std::string> extra) {
        auto a = torusArgs(dir + "/" + name);
        a.insert(a.end(), {"--sun", "0.3,0.8,0.5", "--sun-irradiance", "4", "--density-scale", "0.1"});
        a.insert(a.end(), extra.begin(), extra.end());
        const auto r = runLpmbake(a, dir);
        EXPECT_EQ(r.code, 0) << r.err;
        return std::make_pair(r, readBakeFile(dir + "/" + name));
    };
    const auto [iso, isoBake] = bake("g0.vdb", {});
    EXPECT_EQ(metaInt(*isoBake.meta, "lpm:sun_term_count", -1), 0);
    EXPECT_NE(metaString(*isoBake.meta, "lpm:decisions").find("no exact sun term: g = 0"), std::string::npos);
    EXPECT_TRUE(isoBake.sunTransmittance.empty());

    const auto [on, onBake] = bake("g5.vdb", {"--g", "0.5"});
    EXPECT_NE(on.err.find("exact sun term: 1 sun(s) kept out of the SH"), std::string::npos) << on.err;
    ASSERT_EQ(onBake.sunTransmittance.size(), 1u);
    EXPECT_TRUE(validateBake(onBake).empty());
    EXPECT_EQ(metaInt(*onBake.meta, "lpm:format_version", 0), 2);
    EXPECT_EQ(metaString(*onBake.meta, "lpm:sun_term_0_source"), "--sun");
    EXPECT_NEAR(metaDouble(*onBake.meta, "lpm:sun_term_g", 0), 0.5, 1e-12);
    EXPECT_EQ(metaRgb(*onBake.meta, "lpm:sun_term_0_irradiance", RGB(0.f)).g, 4.0f);
    EXPECT_EQ(onBake.sunTransmittance[0]->activeVoxelCount(), onBake.scatter->activeVoxelCount());
    float lo = 2, hi = -1;
    for (auto it = onBake.sunTransmittance[0]->cbeginValueOn(); it; ++it)
        lo = std::min(lo, *it), hi = std::max(hi, *it);
    EXPECT_GE(lo, 0.0f);
    EXPECT_LE(hi, 1.0f);
    EXPECT_GT(hi, 0.5f);

    // Off: the same S through SH. scatter (direction-averaged S) is the same either way;
    // band 0 of the SH differs by the sun's single scattering E T Y00 exactly.
    const auto [off, offBake] = bake("g5off.vdb", {"--g", "0.5", "--sun-term", "off"});
    EXPECT_EQ(metaInt(*offBake.meta, "lpm:sun_term_count", -1), 0);
    auto sAcc = onBake.scatter->getConstAccessor(), sOff = offBake.scatter->getConstAccessor();
    auto h0 = onBake.sh[0]->getConstAccessor(), h0off = offBake.sh[0]->getConstAccessor();
    auto tAcc = onBake.sunTransmittance[0]->getConstAccessor();
    int checked = 0;
    for (auto it = onBake.density->cbeginValueOn(); it && checked < 200; ++it, ++checked) {
        const openvdb::Coord c = it.getCoord();
        EXPECT_NEAR(sAcc.getValue(c)[1], sOff.getValue(c)[1], 1e-5 + 1e-5 * sOff.getValue(c)[1]);
        EXPECT_NEAR(h0off.getValue(c)[1] - h0.getValue(c)[1], 4.0 * tAcc.getValue(c) * 0.28209479,
                    1e-4 * h0off.getValue(c)[1] + 1e-6);
    }
    EXPECT_EQ(checked, 200);

    // A file whose sun grid went missing is not a valid bake.
    BakeFile broken = onBake;
    broken.grids.erase(
        std::remove_if(broken.grids.begin(), broken.grids.end(),
                       [](const openvdb::GridBase::Ptr& g) { return g->getName() == "sun_transmittance_0"; }),
        broken.grids.end());
    openvdb::io::File f(dir + "/broken.vdb");
    f.write(broken.grids, *broken.meta);
    f.close();
    const auto info = runLpmbake({"info", dir + "/broken.vdb"}, dir);
    EXPECT_EQ(info.code, 2);
    EXPECT_NE(info.out.find("lpm:sun_term_count is 1 but the file has 0"), std::string::npos) << info.out;
}

// --sidecar: the file's lpm:* metadata and grid names as JSON, for tools that cannot read
// VDB metadata; in a sequence one per frame, and a missing one makes the frame pending.
TEST(Cli, SidecarHoldsTheFilesMetadata) {
    const std::string dir = lpmtest::scratchDir();
    auto a = torusArgs(dir + "/out.vdb");
    a.insert(a.end(), {"--sun", "0.3,0.8,0.5", "--g", "0.5", "--sidecar", dir + "/out.json"});
    const auto r = runLpmbake(a, dir);
    ASSERT_EQ(r.code, 0) << r.err;
    const nlohmann::json js = nlohmann::json::parse(lpmtest::readAll(dir + "/out.json"));
    const BakeFile b = readBakeFile(dir + "/out.vdb");
    int keys = 0;
    for (auto it = b.meta->beginMeta(); it != b.meta->endMeta(); ++it, ++keys) {
        ASSERT_TRUE(js["metadata"].contains(it->first)) << it->first;
        if (auto d = b.meta->getMetadata<openvdb::DoubleMetadata>(it->first)) {
            EXPECT_EQ(js["metadata"][it->first].get<double>(), d->value()) << it->first;
        }
        if (auto t = b.meta->getMetadata<openvdb::StringMetadata>(it->first)) {
            EXPECT_EQ(js["metadata"][it->first].get<std::string>(), t->value()) << it->first;
        }
    }
    EXPECT_GT(keys, 50);
    EXPECT_EQ(js["bake"], "out.vdb");
    EXPECT_EQ(js["format_version"], kBakeFormatVersion);
    std::vector<std::string> gridNames, listed = js["grids"].get<std::vector<std::string>>();
    for (const auto& g : b.grids) gridNames.push_back(g->getName());
    std::sort(gridNames.begin(), gridNames.end());
    std::sort(listed.begin(), listed.end());
    EXPECT_EQ(listed, gridNames);
    // The shader block: what a shader needs, by name, from the same schema.
    const nlohmann::json& sh = js["shader"];
    EXPECT_EQ(sh["density_scale"].get<double>(), getDouble(*b.meta, bakekey::densityScale, -1));
    EXPECT_EQ(sh["g"].get<double>(), 0.5);
    EXPECT_EQ(sh["sh_order"].get<int>(), b.shOrder);
    EXPECT_EQ(sh["albedo"].size(), 3u);
    EXPECT_EQ(sh["up_axis"], "y");
    EXPECT_EQ(sh["working_colorspace"], getString(*b.meta, bakekey::workingColorspace));
    EXPECT_TRUE(sh.contains("sh_basis") && sh.contains("frame") && sh.contains("density_grid"));
    ASSERT_EQ(sh["sun_terms"].size(), 1u);
    EXPECT_EQ(sh["sun_terms"][0]["grid"], "sun_transmittance_0");
    EXPECT_NEAR(sh["sun_terms"][0]["toward"][0].get<double>(), 0.3 / std::sqrt(0.98), 1e-12);
    EXPECT_FALSE(sh.contains("settings")) << "only shader keys in the shader block";
    // The bake's metadata is exactly the schema's: complete, typed, nothing outside it.
    EXPECT_TRUE(schemaProblems(*b.meta, true).empty()) << schemaProblems(*b.meta, true).front();
    for (auto it = b.meta->beginMeta(); it != b.meta->endMeta(); ++it) {
        bool known = it->first.rfind("lpm:sun_term_0_", 0) == 0;
        for (const MetaKey& k : bakeSchema()) known = known || k.name == it->first;
        EXPECT_TRUE(known) << it->first << " is not in vdb_io/bake_schema.h";
    }

    const std::string seqDir = dir + "/seq";
    fs::create_directories(seqDir);
    for (int f : {2, 3})
        fs::copy_file(dataPath("vdb/smoke_seq.000" + std::to_string(f) + ".vdb"),
                      seqDir + "/in.000" + std::to_string(f) + ".vdb");
    std::vector<std::string> s = {
        seqDir + "/in.####.vdb",   "--frames", "2-3", "--sun", "0,1,0", "-o", seqDir + "/out.####.vdb", "--sidecar",
        seqDir + "/out.####.json", "-q"};
    s.insert(s.end(), kCheap.begin(), kCheap.end());
    ASSERT_EQ(runLpmbake(s, dir).code, 0);
    EXPECT_TRUE(fs::exists(seqDir + "/out.0002.json"));
    fs::remove(seqDir + "/out.0003.json");
    s.push_back("--list-pending");
    EXPECT_EQ(runLpmbake(s, dir).out, "3\n");
}

TEST(Cli, ASecondBakeReadsTheSkyFromTheImageCache) {
    // Farm frames are separate processes: the second decodes nothing, and bakes the same.
    const std::string dir = lpmtest::scratchDir();
    const std::vector<std::pair<std::string, std::string>> cache = {{"LPMBAKE_IMAGE_CACHE", dir + "/cache"}};
    std::string source[2];
    for (const int i : {0, 1}) {
        auto a = torusArgs(dir + "/b" + std::to_string(i) + ".vdb");
        a.insert(a.end(), {"-v", "--stats", dir + "/s" + std::to_string(i) + ".json"});
        const auto r = runLpmbake(a, dir, cache);
        ASSERT_EQ(r.code, 0) << r.err.substr(0, 2000);
        EXPECT_NE(r.err.find(i == 0 ? "stored in the image cache" : "read from the image cache"), std::string::npos)
            << r.err;
        source[i] = nlohmann::json::parse(lpmtest::readAll(dir + "/s" + std::to_string(i) + ".json"))
                        .at("environment_source")
                        .get<std::string>();
    }
    EXPECT_EQ(source[0], "decoded");
    EXPECT_EQ(source[1], "image cache");
    const BakeFile decoded = readBakeFile(dir + "/b0.vdb"), cached = readBakeFile(dir + "/b1.vdb");
    ASSERT_TRUE(decoded.scatter && cached.scatter);
    size_t compared = 0;
    auto cachedAcc = cached.scatter->getConstAccessor();
    for (auto v = decoded.scatter->cbeginValueOn(); v; ++v, ++compared)
        ASSERT_EQ(*v, cachedAcc.getValue(v.getCoord())) << v.getCoord();
    EXPECT_GT(compared, 1000u);
    // A limit that is not a number: one line naming the variable, and no output.
    const auto r = runLpmbake(torusArgs(dir + "/bad.vdb"), dir,
                              {{"LPMBAKE_IMAGE_CACHE", dir + "/cache"}, {"LPMBAKE_IMAGE_CACHE_MIB", "2GB"}});
    expectOneLineError(r, 2, "env", {"LPMBAKE_IMAGE_CACHE_MIB", "'2GB'"});
    EXPECT_FALSE(fs::exists(dir + "/bad.vdb"));
}

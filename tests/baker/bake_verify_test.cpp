// `lpmbake --verify N --max-error E` end to end (docs/verify.md): a deliberately coarse bake
// (n = 1, r = 1, tolerance 0.1) fails --max-error 0.02 with exit 6, written and marked; a
// default bake of the same scene passes; sequences count the marked frame as failed and
// --skip-existing re-bakes it. The estimator itself: tests/core/verify_test.cpp.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "../vdb_io/test_helpers.h"
#include "run_helpers.h"
#include "vdb_io/bake_file.h"
#include "vdb_io/bake_schema.h"

using namespace lpm;
using lpmtest::dataPath;
using lpmtest::runLpmbake;

namespace {

const std::vector<std::string> kCoarse = {"--directions-per-face", "1", "--rays-per-voxel", "1", "--tolerance", "0.1"};

/// densityAndHeat.vdb (a real smoke, 11k voxels), g = 0.6, sky: the verify scene.
std::vector<std::string> bakeArgs(const std::string& in, const std::string& out, std::vector<std::string> extra) {
    std::vector<std::string> a = {
        in, "--env", dataPath("env/rooftop_small.hdr"), "--g", "0.6", "--density-scale", "2", "-o", out};
    a.insert(a.end(), extra.begin(), extra.end());
    return a;
}

bool verifyFailedMark(const std::string& path) {
    const BakeFile b = readBakeFile(path);
    return getBool(*b.meta, bakekey::verifyFailed, false);
}

}  // namespace

TEST(BakeVerify, CoarseBakeFailsMaxErrorDefaultPasses) {
    const std::string dir = lpmtest::scratchDir(), in = dataPath("vdb/densityAndHeat.vdb");
    std::vector<std::string> coarse = kCoarse;
    coarse.insert(coarse.end(), {"--max-error", "0.02", "--stats", dir + "/coarse.json"});
    const auto bad = runLpmbake(bakeArgs(in, dir + "/coarse.vdb", coarse), dir);
    EXPECT_EQ(bad.code, 6) << bad.err;
    EXPECT_NE(bad.err.find("lpmbake: warning: verify: the error is above --max-error 2%"), std::string::npos)
        << bad.err;
    ASSERT_TRUE(std::filesystem::exists(dir + "/coarse.vdb"));
    const BakeFile b = readBakeFile(dir + "/coarse.vdb");
    EXPECT_TRUE(validateBake(b).empty());
    EXPECT_TRUE(getBool(*b.meta, bakekey::verifyFailed, false));
    EXPECT_GT(metaDouble(*b.meta, bakekey::verifyErrorLow.name, 0), 0.02);
    EXPECT_EQ(metaDouble(*b.meta, bakekey::verifyMaxError.name, 0), 0.02);
    const auto stats = nlohmann::json::parse(lpmtest::readAll(dir + "/coarse.json"));
    EXPECT_EQ(stats["verify"]["failed"], true);
    EXPECT_EQ(stats["verify"]["probes"], 64);  // implied by --max-error

    const auto good = runLpmbake(
        bakeArgs(in, dir + "/default.vdb", {"--verify", "64", "--max-error", "0.02", "--stats", dir + "/default.json"}),
        dir);
    EXPECT_EQ(good.code, 0) << good.err;
    EXPECT_NE(good.err.find("lpmbake: verify: estimated relative error"), std::string::npos) << good.err;
    EXPECT_FALSE(verifyFailedMark(dir + "/default.vdb"));
    const auto ok = nlohmann::json::parse(lpmtest::readAll(dir + "/default.json"))["verify"];
    EXPECT_LE(ok["low"].get<double>(), 0.02);
    EXPECT_LE(ok["low"].get<double>(), ok["error"].get<double>());
    EXPECT_GE(ok["high"].get<double>(), ok["error"].get<double>());
    // The coarse bake's estimate is far above the default one's.
    EXPECT_GT(stats["verify"]["error"].get<double>(), 3 * ok["high"].get<double>());
}

TEST(BakeVerify, SequenceCountsTheMarkedFrameAndReBakesIt) {
    const std::string dir = lpmtest::scratchDir();
    std::filesystem::copy_file(dataPath("vdb/densityAndHeat.vdb"), dir + "/smoke.0001.vdb");
    std::vector<std::string> extra = kCoarse;
    extra.insert(extra.end(), {"--max-error", "0.02", "--frame", "1", "--skip-existing", "--frame-log", "-", "-q"});
    const auto first = runLpmbake(bakeArgs(dir + "/smoke.####.vdb", dir + "/lit.####.vdb", extra), dir);
    EXPECT_EQ(first.code, 6) << first.err;
    const auto line = nlohmann::json::parse(first.out);
    EXPECT_EQ(line["status"], "failed");
    EXPECT_EQ(line["exit_code"], 6);
    EXPECT_TRUE(verifyFailedMark(dir + "/lit.0001.vdb"));
    // Same command again: the marked file is not up to date, so the frame is baked again.
    const auto again = runLpmbake(bakeArgs(dir + "/smoke.####.vdb", dir + "/lit.####.vdb", extra), dir);
    EXPECT_EQ(again.code, 6) << again.err;
    EXPECT_NE(nlohmann::json::parse(again.out)["status"], "skipped");
}

TEST(BakeVerify, EmptyVolumeHasNothingToCheck) {
    const std::string dir = lpmtest::scratchDir();
    const auto r = runLpmbake({dataPath("vdb/smoke_seq.0001.vdb"), "--env", dataPath("env/rooftop_small.hdr"),
                               "--max-error", "0.02", "-o", dir + "/empty.vdb"},
                              dir);
    EXPECT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.err.find("verify: the volume is empty: nothing to check"), std::string::npos) << r.err;
    EXPECT_FALSE(verifyFailedMark(dir + "/empty.vdb"));
}

TEST(BakeVerify, BadValuesAreUsageErrors) {
    const std::string dir = lpmtest::scratchDir(), in = dataPath("vdb/densityAndHeat.vdb");
    for (const auto& [flag, value] : std::vector<std::pair<std::string, std::string>>{
             {"--max-error", "0"}, {"--max-error", "nan"}, {"--verify", "3"}, {"--verify-paths", "2"}})
    {
        const auto r = runLpmbake(bakeArgs(in, dir + "/x.vdb", {flag, value}), dir);
        EXPECT_EQ(r.code, 1) << flag << " " << value << ": " << r.err;
        EXPECT_NE(r.err.find(flag), std::string::npos) << r.err;
        EXPECT_FALSE(std::filesystem::exists(dir + "/x.vdb"));
    }
}

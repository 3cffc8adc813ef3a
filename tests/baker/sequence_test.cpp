// Frame sequences end to end (baker/sequence.h, docs/farm.md): the real Blender smoke
// frames in data/vdb (frame 1 is an empty grid), cheap solver settings.
#include <gtest/gtest.h>

#include <sys/stat.h>

#include <filesystem>
#include <fstream>

#include "../vdb_io/test_helpers.h"
#include "run_helpers.h"

using lpmtest::dataPath;
using lpmtest::runLpmbake;
namespace fs = std::filesystem;

namespace {

const std::vector<std::string> kCheap = {"--directions-per-face", "2", "--tolerance", "1e-2", "--rays-per-voxel", "1"};

/// A copy of smoke frames 1..3 as in/smoke.NNNN.vdb (the test may touch or remove them).
std::string copyFrames(const std::string& dir) {
    fs::create_directories(dir + "/in");
    for (int f = 1; f <= 3; ++f)
        fs::copy_file(dataPath("vdb/smoke_seq.000" + std::to_string(f) + ".vdb"),
                      dir + "/in/smoke.000" + std::to_string(f) + ".vdb");
    return dir + "/in/smoke.####.vdb";
}

std::vector<std::string> seqArgs(const std::string& in, const std::string& out, const std::string& frames,
                                 std::vector<std::string> extra = {}) {
    std::vector<std::string> a = {in, "--env", dataPath("env/rooftop_small.hdr"), "-o", out, "--frames", frames};
    a.insert(a.end(), kCheap.begin(), kCheap.end());
    a.insert(a.end(), extra.begin(), extra.end());
    return a;
}

std::string digest(const std::string& bake, const std::string& dir) {
    const auto r = runLpmbake({"info", "--digest", bake}, dir);
    EXPECT_EQ(r.code, 0) << r.err;
    return r.out;
}

long long mtimeNs(const std::string& p) {
    struct stat st {};
    if (::stat(p.c_str(), &st) != 0) return -1;
    return static_cast<long long>(st.st_mtim.tv_sec) * 1000000000LL + st.st_mtim.tv_nsec;
}

int countOf(const std::string& s, const std::string& what) {
    int n = 0;
    for (size_t at = s.find(what); at != std::string::npos; at = s.find(what, at + 1)) ++n;
    return n;
}

}  // namespace

TEST(Sequence, SameBakeAloneInASequenceInAnyOrderWithAnyThreads) {
    const std::string dir = lpmtest::scratchDir(), in = copyFrames(dir);
    const auto seq = runLpmbake(seqArgs(in, dir + "/seq.$F4.vdb", "3,2,1", {"--threads", "2", "-q"}), dir);
    ASSERT_EQ(seq.code, 0) << seq.err;
    std::vector<std::string> alone = {dir + "/in/smoke.0002.vdb",
                                      "--env",
                                      dataPath("env/rooftop_small.hdr"),
                                      "-o",
                                      dir + "/alone.vdb",
                                      "--threads",
                                      "1",
                                      "-q"};
    alone.insert(alone.end(), kCheap.begin(), kCheap.end());
    ASSERT_EQ(runLpmbake(alone, dir).code, 0);
    const std::string d2 = digest(dir + "/seq.0002.vdb", dir);
    EXPECT_EQ(d2.size(), 17u) << d2;  // 16 hex digits and a newline
    EXPECT_EQ(d2, digest(dir + "/alone.vdb", dir));
    // The digest sees content: another frame, or another albedo, differs.
    EXPECT_NE(d2, digest(dir + "/seq.0003.vdb", dir));
    alone[4] = dir + "/albedo.vdb";
    alone.insert(alone.end(), {"--albedo", "0.8"});
    ASSERT_EQ(runLpmbake(alone, dir).code, 0);
    EXPECT_NE(d2, digest(dir + "/albedo.vdb", dir));
    // Frame 1 is Blender's empty first frame: an empty bake, with a warning, not a failure.
    EXPECT_TRUE(fs::exists(dir + "/seq.0001.vdb"));
}

TEST(Sequence, SkipExistingRedoesOnlyMissingInvalidStaleOrChangedFrames) {
    const std::string dir = lpmtest::scratchDir(), in = copyFrames(dir), out = dir + "/lit.####.vdb";
    ASSERT_EQ(runLpmbake(seqArgs(in, out, "1-3", {"-q"}), dir).code, 0);
    auto pending = [&](std::vector<std::string> extra = {}) {
        extra.push_back("--list-pending");
        const auto r = runLpmbake(seqArgs(in, out, "1-3", extra), dir);
        EXPECT_EQ(r.code, 0) << r.err;
        return r.out;
    };
    EXPECT_EQ(pending(), "\n");
    EXPECT_EQ(pending({"--albedo", "0.8"}), "1-3\n");                          // other settings
    EXPECT_EQ(pending({"--threads", "1", "--stats", dir + "/s.json"}), "\n");  // not settings
    const std::string bytes = lpmtest::readBytes(dir + "/lit.0003.vdb");
    lpmtest::writeBytes(dir + "/lit.0003.vdb", bytes.substr(0, bytes.size() / 2));  // a damaged file
    fs::remove(dir + "/lit.0001.vdb");
    EXPECT_EQ(pending(), "1,3\n");
    const long long t2 = mtimeNs(dir + "/lit.0002.vdb");
    const auto r = runLpmbake(seqArgs(in, out, "1-3", {"--skip-existing", "--frame-log", "-", "-q"}), dir);
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(countOf(r.out, "\"status\": \"baked\""), 2) << r.out;
    EXPECT_EQ(countOf(r.out, "\"frame\": 2, \"status\": \"skipped\""), 1) << r.out;
    EXPECT_EQ(mtimeNs(dir + "/lit.0002.vdb"), t2);  // not rewritten
    EXPECT_EQ(pending(), "\n");
    // A re-simulated input frame makes its bake stale.
    fs::last_write_time(dir + "/in/smoke.0002.vdb", fs::file_time_type::clock::now() + std::chrono::hours(1));
    EXPECT_EQ(pending(), "2\n");
}

TEST(Sequence, FailedFramesStopTheSequenceOrAreListedWithKeepGoing) {
    const std::string dir = lpmtest::scratchDir(), in = copyFrames(dir), out = dir + "/lit.####.vdb";
    // Frame 4 is absent; frame 5 has no grid named 'density'.
    fs::copy_file(dataPath("vdb/torus01.vdb"), dir + "/in/smoke.0005.vdb");
    const auto stop = runLpmbake(seqArgs(in, out, "4,2,5"), dir);
    EXPECT_EQ(stop.code, 5) << stop.err;
    EXPECT_NE(stop.err.find("frame 4 is missing: no file '" + dir + "/in/smoke.0004.vdb'"), std::string::npos)
        << stop.err;
    EXPECT_NE(stop.err.find("failed frames: 4 (stopped at the first failure; 2 frame(s) not run"), std::string::npos)
        << stop.err;
    EXPECT_FALSE(fs::exists(dir + "/lit.0002.vdb"));

    const auto go = runLpmbake(seqArgs(in, out, "4,2,5", {"--keep-going", "--stats", dir + "/seq.json"}), dir);
    EXPECT_EQ(go.code, 5) << go.err;
    EXPECT_NE(go.err.find("lpmbake: error: failed frames: 4-5\n"), std::string::npos) << go.err;
    EXPECT_NE(go.err.find("frame 5: input: "), std::string::npos) << go.err;
    EXPECT_NE(go.err.find("'density'"), std::string::npos) << go.err;
    EXPECT_TRUE(fs::exists(dir + "/lit.0002.vdb"));
    EXPECT_FALSE(fs::exists(dir + "/lit.0004.vdb"));
    EXPECT_FALSE(fs::exists(dir + "/lit.0005.vdb"));
    const std::string stats = lpmtest::readBytes(dir + "/seq.json");
    EXPECT_NE(stats.find("\"baked\": 1, \"skipped\": 0, \"failed\": 2, \"not_run\": 0"), std::string::npos) << stats;
    EXPECT_EQ(countOf(stats, "\"exit_code\": 2"), 2) << stats;

    // One frame alone fails with its own exit code (input error), not 5.
    const auto one = runLpmbake({in, "--env", dataPath("env/rooftop_small.hdr"), "-o", out, "--frame", "4"}, dir);
    EXPECT_EQ(one.code, 2) << one.err;
}

TEST(Sequence, EnvironmentReadOncePerSequenceAndOneJsonLinePerFrame) {
    const std::string dir = lpmtest::scratchDir(), in = copyFrames(dir);
    const std::string log = dir + "/frames.jsonl";
    const auto r =
        runLpmbake(seqArgs(in, dir + "/lit.%04d.vdb", "1-3", {"--stats", dir + "/seq.json", "--frame-log", log, "-q"}),
                   dir, {{"SLURM_CPUS_PER_TASK", "1"}});
    ASSERT_EQ(r.code, 0) << r.err;
    const std::string stats = lpmtest::readBytes(dir + "/seq.json");
    EXPECT_NE(stats.find("\"environment_reads\": 1,"), std::string::npos) << stats;
    const std::string lines = lpmtest::readBytes(log);
    EXPECT_EQ(countOf(lines, "\n"), 3);
    for (const char* field : {"\"frame\": ", "\"status\": \"baked\"", "\"seconds\": ", "\"threads\": 1,",
                              "\"passes\": ", "\"residual\": ", "\"peak_rss_mib\": ", "\"output\": "})
        EXPECT_EQ(countOf(lines, field), 3) << field << "\n" << lines;
    EXPECT_EQ(countOf(lines, "\"environment_reused\": true"), 2) << lines;
    // A per-frame stats pattern writes one stats file per frame instead.
    ASSERT_EQ(runLpmbake(seqArgs(in, dir + "/b.@.vdb", "2-3", {"--stats", dir + "/b.@.json", "-q"}), dir).code, 0);
    EXPECT_TRUE(fs::exists(dir + "/b.2.json"));
    EXPECT_TRUE(fs::exists(dir + "/b.3.json"));
    // A frame log that cannot be written stops the sequence with an output error.
    const auto bad =
        runLpmbake(seqArgs(in, dir + "/c.@.vdb", "2", {"--frame-log", dir + "/no/such/dir/log.@.jsonl", "-q"}), dir);
    EXPECT_EQ(bad.code, 3) << bad.err;
    EXPECT_NE(bad.err.find("frame log: cannot write '" + dir + "/no/such/dir/log.2.jsonl'"), std::string::npos)
        << bad.err;
}

TEST(Sequence, BadSequenceOptionsAreUsageErrors) {
    const std::string dir = lpmtest::scratchDir(), in = copyFrames(dir);
    const std::string env = dataPath("env/rooftop_small.hdr");
    struct Case {
        std::vector<std::string> args;
        std::string says;
    } cases[] = {
        {{in, "--env", env, "-o", dir + "/one.vdb", "--frames", "1-3"}, "has no frame pattern"},
        {{in, "--env", env, "-o", dir + "/x.####.vdb"}, "has a frame pattern: give --frames"},
        {{dir + "/in/smoke.0002.vdb", "--env", env, "-o", dir + "/x.vdb", "--skip-existing"}, "need --frames"},
        {{in, "--env", env, "-o", dir + "/x.####.vdb", "--frames", "5-1"}, "frame list '5-1'"},
        {{in, "--env", env, "-o", dir + "/x.####.vdb", "--frames", "1", "--frame", "2"}, "excludes"},
    };
    for (const auto& c : cases) {
        const auto r = runLpmbake(c.args, dir);
        EXPECT_EQ(r.code, 1) << r.err;
        EXPECT_NE(r.err.find(c.says), std::string::npos) << r.err;
        EXPECT_EQ(r.errLines(), 1) << r.err;
    }
    EXPECT_FALSE(fs::exists(dir + "/x.0001.vdb"));
}

// vdb_io/atomic_file: temp + rename, never the input, cleanup, kill before rename.
#include "vdb_io/atomic_file.h"

#include <gtest/gtest.h>

#include <sys/wait.h>
#include <unistd.h>

#include "test_helpers.h"
#include "vdb_io/io_error.h"

using namespace lpm;
namespace fs = std::filesystem;

namespace {
std::string slurp(const std::string& p) {
    std::ifstream f(p);
    return std::string((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
}
size_t filesIn(const std::string& dir) {
    size_t n = 0;
    for (auto& e : fs::directory_iterator(dir)) n += e.is_regular_file();
    return n;
}
}  // namespace

TEST(AtomicOutput, WritesThroughTempAndRename) {
    const std::string dir = lpmtest::scratchDir();
    const std::string out = dir + "/out.vdb";
    {
        AtomicOutput a(out, {});
        EXPECT_NE(a.tempPath(), out);
        EXPECT_EQ(fs::path(a.tempPath()).parent_path(), fs::path(out).parent_path()) << "same filesystem for rename()";
        EXPECT_EQ(fs::path(a.tempPath()).extension(), ".vdb") << "writers pick formats by extension";
        std::ofstream(a.tempPath()) << "complete";
        EXPECT_FALSE(fs::exists(out)) << "nothing at the final name before commit";
        a.commit();
    }
    EXPECT_EQ(slurp(out), "complete");
    EXPECT_EQ(filesIn(dir), 1u) << "no temporary file left";
}

TEST(AtomicOutput, AbandonedWriteLeavesNothing) {
    const std::string dir = lpmtest::scratchDir();
    const std::string out = dir + "/out.vdb";
    std::ofstream(out) << "previous";
    {
        AtomicOutput a(out, {});
        std::ofstream(a.tempPath()) << "half";
        // an exception would unwind here without commit()
    }
    EXPECT_EQ(slurp(out), "previous");
    EXPECT_EQ(filesIn(dir), 1u);
}

TEST(AtomicOutput, RefusesInputsAndMissingDirectories) {
    const std::string dir = lpmtest::scratchDir();
    const std::string in = dir + "/in.vdb";
    std::ofstream(in) << "input";
    lpmtest::expectThrowWith<OutputError>([&] { AtomicOutput a(in, {in}); }, {"in.vdb", "input"});
    // Same file through another spelling and through a hard link.
    lpmtest::expectThrowWith<OutputError>([&] { AtomicOutput a(dir + "/./in.vdb", {in}); }, {"input"});
    fs::create_hard_link(in, dir + "/link.vdb");
    lpmtest::expectThrowWith<OutputError>([&] { AtomicOutput a(dir + "/link.vdb", {in}); }, {"input"});
    lpmtest::expectThrowWith<OutputError>([&] { AtomicOutput a(dir + "/nodir/x.vdb", {}); },
                                          {"nodir", "does not exist"});
    EXPECT_EQ(slurp(in), "input");
}

// A process SIGKILLed between writing and renaming (the test hook) leaves the previous
// content at the final name.
TEST(AtomicOutput, KilledBeforeRenameKeepsFinalNameIntact) {
    const std::string dir = lpmtest::scratchDir();
    const std::string out = dir + "/out.vdb";
    std::ofstream(out) << "previous";
    const pid_t pid = ::fork();
    ASSERT_GE(pid, 0);
    if (pid == 0) {
        ::setenv("LPM_TEST_KILL_BEFORE_RENAME", "1", 1);
        AtomicOutput a(out, {});
        std::ofstream(a.tempPath()) << "new but never committed";
        a.commit();
        ::_exit(0);  // not reached
    }
    int status = 0;
    ::waitpid(pid, &status, 0);
    ASSERT_TRUE(WIFSIGNALED(status));
    EXPECT_EQ(WTERMSIG(status), SIGKILL);
    EXPECT_EQ(slurp(out), "previous");
}

// Runs the built lpmbake binary as a child process (no shell) and captures its exit
// status, stdout and stderr.
#pragma once

#include <fcntl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <fstream>
#include <string>
#include <utility>
#include <vector>

namespace lpmtest {

struct RunResult {
    int code = -1;   ///< exit code, -1 if killed
    int signal = 0;  ///< terminating signal, 0 if exited
    std::string out, err;
    int errLines() const {
        int n = 0;
        for (char c : err) n += c == '\n';
        return n;
    }
};

inline std::string readAll(const std::string& p) {
    std::ifstream f(p);
    return std::string((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
}

inline RunResult runLpmbake(const std::vector<std::string>& args, const std::string& scratch,
                            const std::vector<std::pair<std::string, std::string>>& env = {},
                            const std::vector<std::string>& unsetEnv = {"SLURM_CPUS_PER_TASK", "OCIO"}) {
    const std::string outPath = scratch + "/.stdout", errPath = scratch + "/.stderr";
    const pid_t pid = ::fork();
    if (pid == 0) {
        const int o = ::open(outPath.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
        const int e = ::open(errPath.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
        ::dup2(o, 1);
        ::dup2(e, 2);
        for (const auto& u : unsetEnv) ::unsetenv(u.c_str());
        for (const auto& kv : env) ::setenv(kv.first.c_str(), kv.second.c_str(), 1);
        std::vector<char*> argv;
        std::string exe = LPMBAKE_EXE;
        argv.push_back(exe.data());
        std::vector<std::string> copy = args;
        for (auto& a : copy) argv.push_back(a.data());
        argv.push_back(nullptr);
        ::execv(exe.c_str(), argv.data());
        ::_exit(127);
    }
    RunResult r;
    int status = 0;
    ::waitpid(pid, &status, 0);
    if (WIFEXITED(status)) r.code = WEXITSTATUS(status);
    if (WIFSIGNALED(status)) r.signal = WTERMSIG(status);
    r.out = readAll(outPath);
    r.err = readAll(errPath);
    ::unlink(outPath.c_str());
    ::unlink(errPath.c_str());
    return r;
}

}  // namespace lpmtest

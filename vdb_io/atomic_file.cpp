// Temporary file + fsync + rename, with cleanup on ordinary termination signals.
#include "vdb_io/atomic_file.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/statvfs.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "vdb_io/io_error.h"

namespace fs = std::filesystem;

namespace lpm {

namespace {

const char* kComp = "output";

// The temporary file of the write in progress, for the signal handler (one at a time is
// enough for a command-line tool; a fixed buffer keeps the handler async-signal-safe).
char g_temp[4096];
std::atomic<bool> g_active{false};

extern "C" void removeTempAndReraise(int sig) {
    if (g_active.load()) ::unlink(g_temp);
    ::signal(sig, SIG_DFL);
    ::raise(sig);
}

void installHandlers() {
    static bool done = false;
    if (done) return;
    done = true;
    for (int sig : {SIGINT, SIGTERM, SIGHUP}) {
        struct sigaction old {};
        ::sigaction(sig, nullptr, &old);
        if (old.sa_handler == SIG_IGN) continue;  // respect nohup
        ::signal(sig, removeTempAndReraise);
    }
}

bool samePath(const fs::path& a, const fs::path& b) {
    std::error_code ec;
    if (fs::exists(a, ec) && fs::exists(b, ec)) return fs::equivalent(a, b, ec);
    return fs::weakly_canonical(a, ec) == fs::weakly_canonical(b, ec);
}

}  // namespace

AtomicOutput::AtomicOutput(const std::string& finalPath, const std::vector<std::string>& inputs) : final_(finalPath) {
    if (final_.empty()) throw OutputError(kComp, "no output path given");
    for (const auto& in : inputs)
        if (!in.empty() && samePath(final_, in))
            throw OutputError(kComp, "refusing to write '" + final_ + "': it is the input file '" + in + "'");
    const fs::path p(final_);
    if (fs::is_directory(p)) throw OutputError(kComp, "output path '" + final_ + "' is a directory");
    fs::path dir = p.parent_path();
    if (dir.empty()) dir = ".";
    if (!fs::is_directory(dir))
        throw OutputError(kComp, "output directory '" + dir.string() + "' does not exist (for '" + final_ + "')");
    if (::access(dir.c_str(), W_OK) != 0)
        throw OutputError(kComp, "cannot write to output directory '" + dir.string() + "': " + std::strerror(errno) +
                                     " (for '" + final_ + "')");
    temp_ =
        (dir / ("." + p.stem().string() + ".lpmtmp-" + std::to_string(::getpid()) + p.extension().string())).string();
    if (temp_.size() < sizeof(g_temp)) {
        std::memcpy(g_temp, temp_.c_str(), temp_.size() + 1);
        g_active = true;
        installHandlers();
    }
}

AtomicOutput::~AtomicOutput() {
    if (!committed_) ::unlink(temp_.c_str());
    g_active = false;
}

std::string AtomicOutput::failureReason() const {
    fs::path dir = fs::path(final_).parent_path();
    if (dir.empty()) dir = ".";
    struct statvfs st {};
    if (::statvfs(dir.c_str(), &st) != 0) return "";
    if (st.f_flag & ST_RDONLY) return "the file system of '" + dir.string() + "' is read-only";
    const unsigned long long freeBytes = static_cast<unsigned long long>(st.f_bavail) * st.f_frsize;
    if (freeBytes >= (1ull << 20)) return "";
    return "no space left on device ('" + dir.string() + "' has " + std::to_string(freeBytes / 1024) + " KiB free)";
}

void AtomicOutput::commit() {
    // Flush the data to disk before the rename makes it visible (ext4/xfs ordering).
    const int fd = ::open(temp_.c_str(), O_RDONLY);
    if (fd < 0) throw OutputError(kComp, "temporary file '" + temp_ + "' vanished: " + std::strerror(errno));
    if (::fsync(fd) != 0) {
        const int err = errno;
        ::close(fd);
        throw OutputError(kComp, "cannot flush '" + temp_ + "' to disk: " + std::strerror(err));
    }
    ::close(fd);
    if (const char* hook = std::getenv("LPM_TEST_KILL_BEFORE_RENAME"); hook && std::string(hook) == "1")
        ::raise(SIGKILL);
    if (std::rename(temp_.c_str(), final_.c_str()) != 0)
        throw OutputError(kComp, "cannot rename '" + temp_ + "' to '" + final_ + "': " + std::strerror(errno));
    committed_ = true;
    g_active = false;
    // Make the rename itself durable.
    fs::path dir = fs::path(final_).parent_path();
    if (dir.empty()) dir = ".";
    const int dfd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY);
    if (dfd >= 0) {
        ::fsync(dfd);
        ::close(dfd);
    }
}

void writeTextFileAtomically(const std::string& what, const std::string& path, const std::string& text,
                             const std::vector<std::string>& inputs) {
    AtomicOutput out(path, inputs);
    {
        std::ofstream f(out.tempPath());
        f << text;
        f.close();
        if (!f) {
            const std::string why = out.failureReason();
            throw OutputError(what, "cannot write '" + path + "'" + (why.empty() ? "" : ": " + why));
        }
    }
    out.commit();
}

}  // namespace lpm

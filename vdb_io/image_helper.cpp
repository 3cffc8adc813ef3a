// Running the image helper (image_helper.h).
#include "vdb_io/image_helper.h"

#include <fcntl.h>
#include <spawn.h>
#include <sys/mman.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <stdexcept>
#include <vector>

#include "vdb_io/image_protocol.h"

extern char** environ;

namespace lpm {

namespace {

const char* kHelperName = "lpmbake-image";

/// An anonymous in-memory file, closed when it goes out of scope.
class MemoryFile {
public:
    explicit MemoryFile(const char* name) : fd_(::memfd_create(name, MFD_CLOEXEC)) {
        if (fd_ < 0) throw std::runtime_error(std::string("cannot create an in-memory file: ") + std::strerror(errno));
    }
    ~MemoryFile() { ::close(fd_); }
    MemoryFile(const MemoryFile&) = delete;
    MemoryFile& operator=(const MemoryFile&) = delete;
    int fd() const { return fd_; }
    void rewind() const { ::lseek(fd_, 0, SEEK_SET); }
    /// Everything written to it, as text, newlines turned into spaces and trimmed.
    std::string text() const {
        rewind();
        std::string s;
        char buf[4096];
        ssize_t n;
        while ((n = ::read(fd_, buf, sizeof buf)) > 0) s.append(buf, size_t(n));
        for (char& c : s)
            if (c == '\n') c = ' ';
        while (!s.empty() && s.back() == ' ') s.pop_back();
        return s;
    }

private:
    int fd_;
};

/// Runs `helper args...` with the three files as its stdin, stdout and stderr (-1: /dev/null)
/// and waits for it. Throws if it cannot start, dies of a signal or exits non-zero (with
/// its stderr as the message).
void runHelper(const std::vector<std::string>& args, int in, int out, const MemoryFile& err) {
    const std::string helper = imageHelperPath();
    std::vector<char*> argv;
    argv.push_back(const_cast<char*>(helper.c_str()));
    for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    posix_spawn_file_actions_t files;
    posix_spawn_file_actions_init(&files);
    if (in >= 0) posix_spawn_file_actions_adddup2(&files, in, 0);
    else posix_spawn_file_actions_addopen(&files, 0, "/dev/null", O_RDONLY, 0);
    if (out >= 0) posix_spawn_file_actions_adddup2(&files, out, 1);
    else posix_spawn_file_actions_addopen(&files, 1, "/dev/null", O_WRONLY, 0);
    posix_spawn_file_actions_adddup2(&files, err.fd(), 2);
    pid_t pid = 0;
    const int spawned = posix_spawn(&pid, helper.c_str(), &files, nullptr, argv.data(), environ);
    posix_spawn_file_actions_destroy(&files);
    if (spawned != 0) throw std::runtime_error("cannot run " + helper + ": " + std::strerror(spawned));
    int status = 0;
    while (::waitpid(pid, &status, 0) < 0)
        if (errno != EINTR) throw std::runtime_error("cannot wait for " + helper + ": " + std::strerror(errno));
    if (WIFSIGNALED(status))
        throw std::runtime_error(helper + " died of signal " + std::to_string(WTERMSIG(status)) + " (" +
                                 strsignal(WTERMSIG(status)) + ")");
    if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) {
        const std::string why = err.text();
        throw std::runtime_error(why.empty() ? helper + " failed with exit code " + std::to_string(WEXITSTATUS(status))
                                             : why);
    }
}

bool executable(const std::filesystem::path& p) {
    std::error_code ec;
    return std::filesystem::is_regular_file(p, ec) && ::access(p.c_str(), X_OK) == 0;
}

}  // namespace

std::string imageHelperPath() {
    if (const char* set = std::getenv("LPMBAKE_IMAGE_HELPER"); set && *set) return set;
    std::vector<std::filesystem::path> candidates;
    std::error_code ec;
    const std::filesystem::path exe = std::filesystem::read_symlink("/proc/self/exe", ec);
    if (!ec) {
        candidates.push_back(exe.parent_path() / kHelperName);
        candidates.push_back(exe.parent_path().parent_path() / "libexec" / "lpmbake" / kHelperName);
    }
#ifdef LPM_BUILD_IMAGE_HELPER
    candidates.emplace_back(LPM_BUILD_IMAGE_HELPER);
#endif
    std::string looked;
    for (const auto& c : candidates) {
        if (executable(c)) return c.string();
        looked += (looked.empty() ? "" : ", ") + c.string();
    }
    throw std::runtime_error(std::string("cannot find ") + kHelperName +
                             ", the image reader and writer lpmbake runs (looked at " + looked +
                             "; set LPMBAKE_IMAGE_HELPER to its path)");
}

DecodedImage decodeImageWithHelper(const std::string& path) {
    MemoryFile out("lpmbake-image-out"), err("lpmbake-image-err");
    runHelper({"decode", path}, -1, out.fd(), err);
    out.rewind();
    return readDecodedImage(out.fd());
}

void encodeImageWithHelper(const std::string& writePath, const std::string& shownPath, const ImageToEncode& image) {
    MemoryFile in("lpmbake-image-in"), err("lpmbake-image-err");
    writeImageToEncode(in.fd(), image);
    in.rewind();
    runHelper({"encode", writePath, shownPath}, in.fd(), -1, err);
}

}  // namespace lpm

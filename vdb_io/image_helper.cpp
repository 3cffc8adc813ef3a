// Running the image helper (image_helper.h).
#include "vdb_io/image_helper.h"

#include <fcntl.h>
#include <pthread.h>
#include <spawn.h>
#include <sys/mman.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <stdexcept>
#include <utility>
#include <vector>

#include "core/malloc_policy.h"
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

/// Starts `helper args...` with the three files as its stdin, stdout and stderr (-1:
/// /dev/null). Throws if it cannot start.
pid_t spawnHelper(const std::string& helper, const std::vector<std::string>& args, int in, int out, int err) {
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
    posix_spawn_file_actions_adddup2(&files, err, 2);
    pid_t pid = 0;
    const int spawned = posix_spawn(&pid, helper.c_str(), &files, nullptr, argv.data(), environ);
    posix_spawn_file_actions_destroy(&files);
    if (spawned != 0) throw std::runtime_error("cannot run " + helper + ": " + std::strerror(spawned));
    return pid;
}

/// Waits for the helper. Throws if it died of a signal or exited non-zero (with its stderr
/// as the message).
void waitForHelper(pid_t pid, const std::string& helper, const MemoryFile& err) {
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

struct ImageDecode::Run {
    MemoryFile out{"lpmbake-image-out"}, err{"lpmbake-image-err"};
    std::string helper;
    pid_t pid = -1;
};

ImageDecode::ImageDecode(const std::string& path) : path_(path) {
    try {
        helper_ = imageHelperPath();
        cache_ = imageCacheFromEnvironment();
        if (cache_) {
            imageStamp_ = imageFileStamp(path);
            cacheKey_ = imageCacheKey(path, helper_);
            if (!cacheKey_.empty()) cachedFd_ = openCachedImage(*cache_, cacheKey_);
            if (cachedFd_ >= 0) return;
        }
        startHelper();
    } catch (const std::runtime_error& e) {
        startError_ = e.what();
    }
}

void ImageDecode::startHelper() {
    run_ = std::make_unique<Run>();
    run_->helper = helper_;
    run_->pid = spawnHelper(run_->helper, {"decode", path_}, -1, run_->out.fd(), run_->err.fd());
}

ImageDecode::~ImageDecode() {
    if (cachedFd_ >= 0) ::close(cachedFd_);
    if (run_ && run_->pid > 0) {  // never waited for: the bake failed before it needed the image
        ::kill(run_->pid, SIGTERM);
        int status = 0;
        while (::waitpid(run_->pid, &status, 0) < 0 && errno == EINTR) {
        }
    }
}

/// The cached stream, checked against its entry's hash as read; an entry that does not
/// parse or fails the check (damaged on disk) is removed and the helper decodes the image
/// after all.
DecodedImage ImageDecode::readCached() {
    const int fd = std::exchange(cachedFd_, -1);
    bool intact = false;
    DecodedImage image;
    try {
        image = readDecodedImage(fd, &assignZeroed<float>);
        intact = cachedImageIntact(*cache_, cacheKey_, fd, image.rgb.data(), image.rgb.size() * sizeof(float));
    } catch (const std::exception&) {  // a header that does not parse (std::stoi throws logic errors)
        removeCachedImage(*cache_, cacheKey_);
    }
    ::close(fd);
    if (!intact) {
        startHelper();
        return wait();
    }
    cacheHit_ = true;
    cacheNote_ = "read from the image cache " + cache_->dir.string();
    return image;
}

DecodedImage ImageDecode::wait() {
    if (!startError_.empty()) throw std::runtime_error(startError_);
    if (cachedFd_ >= 0) return readCached();
    if (!run_ || run_->pid <= 0) throw std::runtime_error("image helper: wait() called twice");
    const pid_t pid = run_->pid;
    run_->pid = -1;
    waitForHelper(pid, run_->helper, run_->err);
    run_->out.rewind();
    DecodedImage image = readDecodedImage(run_->out.fd(), &assignZeroed<float>);
    if (cache_ && !cacheKey_.empty()) {
        const auto t = std::chrono::steady_clock::now();
        const std::string notStored = imageFileStamp(path_) != imageStamp_
                                          ? "the file changed while it was decoded"
                                          : storeCachedImage(*cache_, cacheKey_, run_->out.fd());
        const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t).count();
        cacheNote_ = notStored.empty() ? "decoded and stored in the image cache " + cache_->dir.string() + " (" +
                                             std::to_string(int(ms + 0.5)) + " ms)"
                                       : "decoded; not cached: " + notStored;
    }
    run_.reset();  // the in-memory file's pages (the image again) go now, not with this object
    return image;
}

DecodedImage decodeImageWithHelper(const std::string& path) { return ImageDecode(path).wait(); }

namespace {

/// Writes the image into the pipe with SIGPIPE held back, so a helper that died makes the
/// write fail (EPIPE) instead of killing lpmbake; a SIGPIPE left pending is taken.
void writeIntoPipe(int fd, const ImageToEncode& image) {
    sigset_t pipeSignal, old;
    sigemptyset(&pipeSignal);
    sigaddset(&pipeSignal, SIGPIPE);
    pthread_sigmask(SIG_BLOCK, &pipeSignal, &old);
    std::string failure;
    try {
        writeImageToEncode(fd, image);
    } catch (const std::runtime_error& e) {
        failure = e.what();
        const timespec now{0, 0};
        while (sigtimedwait(&pipeSignal, nullptr, &now) == SIGPIPE) {
        }
    }
    pthread_sigmask(SIG_SETMASK, &old, nullptr);
    if (!failure.empty()) throw std::runtime_error(failure);
}

}  // namespace

struct ImageEncode::Run {
    MemoryFile err{"lpmbake-image-err"};
    std::string helper;
    int pipeWrite = -1;
    pid_t pid = -1;
};

ImageEncode::ImageEncode(const std::string& writePath, const std::string& shownPath) {
    try {
        run_ = std::make_unique<Run>();
        run_->helper = imageHelperPath();
        int fds[2];
        if (::pipe2(fds, O_CLOEXEC) != 0)
            throw std::runtime_error(std::string("cannot make a pipe: ") + std::strerror(errno));
        run_->pipeWrite = fds[1];
        try {
            run_->pid = spawnHelper(run_->helper, {"encode", writePath, shownPath}, fds[0], -1, run_->err.fd());
        } catch (...) {
            ::close(fds[0]);
            throw;
        }
        ::close(fds[0]);
    } catch (const std::runtime_error& e) {
        startError_ = e.what();
    }
}

ImageEncode::~ImageEncode() {
    if (!run_) return;
    if (run_->pipeWrite >= 0) ::close(run_->pipeWrite);  // the helper reads a short stream and fails
    if (run_->pid > 0) {                                 // never finished: the render failed first
        ::kill(run_->pid, SIGTERM);
        int status = 0;
        while (::waitpid(run_->pid, &status, 0) < 0 && errno == EINTR) {
        }
    }
}

void ImageEncode::finish(const ImageToEncode& image) {
    if (!startError_.empty()) throw std::runtime_error(startError_);
    if (!run_ || run_->pid <= 0) throw std::runtime_error("image helper: finish() called twice");
    std::string writeFailure;
    try {
        writeIntoPipe(run_->pipeWrite, image);
    } catch (const std::runtime_error& e) {
        writeFailure = e.what();
    }
    ::close(run_->pipeWrite);
    run_->pipeWrite = -1;
    const pid_t pid = run_->pid;
    run_->pid = -1;
    waitForHelper(pid, run_->helper, run_->err);  // the helper's own failure explains a broken pipe best
    if (!writeFailure.empty()) throw std::runtime_error(writeFailure);
}

void encodeImageWithHelper(const std::string& writePath, const std::string& shownPath, const ImageToEncode& image) {
    ImageEncode(writePath, shownPath).finish(image);
}

}  // namespace lpm

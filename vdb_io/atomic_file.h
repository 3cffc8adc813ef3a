// Atomic output files: write to a temporary file in the destination directory, flush it
// to disk, then rename() it over the final name. A job killed at any point leaves either
// no file or the previous file at the final name, never a truncated one (a stray
// ".NAME.lpmtmp-PID.EXT" may remain after SIGKILL; SIGINT/SIGTERM/SIGHUP remove it).
#pragma once

#include <string>
#include <vector>

namespace lpm {

class AtomicOutput {
public:
    /// Throws OutputError if `finalPath` is one of `inputs` (same file or same path), or its
    /// directory does not exist or is not writable (read-only file system, permissions).
    AtomicOutput(const std::string& finalPath, const std::vector<std::string>& inputs);
    ~AtomicOutput();  ///< removes the temporary file unless commit() succeeded
    AtomicOutput(const AtomicOutput&) = delete;
    AtomicOutput& operator=(const AtomicOutput&) = delete;

    /// Where to write. Keeps the final extension (image writers choose the format by it).
    const std::string& tempPath() const { return temp_; }
    const std::string& finalPath() const { return final_; }

    /// fsync()s the temporary file and renames it to the final path. Throws OutputError.
    /// Test hook: with LPM_TEST_KILL_BEFORE_RENAME=1 in the environment the process
    /// SIGKILLs itself here, as a farm would kill a job in the middle of writing.
    void commit();

    /// Why a write into the temporary file most likely failed, from the file system's own
    /// state: "no space left on device (...)" when the output's file system has less than
    /// 1 MiB free, else "" (the writer's own message is then the best one).
    std::string failureReason() const;

private:
    std::string final_, temp_;
    bool committed_ = false;
};

/// Writes `text` atomically to `path` (never over one of `inputs`). Throws OutputError
/// naming `what` ("stats", "sidecar") and the file.
void writeTextFileAtomically(const std::string& what, const std::string& path, const std::string& text,
                             const std::vector<std::string>& inputs);

}  // namespace lpm

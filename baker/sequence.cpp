// Frame sequences (sequence.h).
#include "baker/sequence.h"

#include <sys/stat.h>

#include <chrono>
#include <fstream>
#include <iostream>
#include <memory>
#include <new>

#include "baker/bake_metadata.h"
#include "baker/frame_pattern.h"
#include "baker/peak_memory.h"
#include "baker/text_format.h"
#include "vdb_io/atomic_file.h"
#include "vdb_io/bake_file.h"
#include "vdb_io/bake_schema.h"
#include "vdb_io/io_error.h"

namespace lpm {

namespace {

using Clock = std::chrono::steady_clock;

/// Modification time in nanoseconds, or -1 when the file is absent.
long long mtimeNs(const std::string& path) {
    struct stat st {};
    if (path.empty() || ::stat(path.c_str(), &st) != 0) return -1;
    return static_cast<long long>(st.st_mtim.tv_sec) * 1000000000LL + st.st_mtim.tv_nsec;
}

struct FrameRecord {
    int frame = 0;
    std::string status;                 ///< baked, skipped, failed
    std::string input, output, detail;  ///< detail: why it was baked or skipped, or the error
    int exitCode = kExitOk;
    double seconds = 0;
    BakeSummary summary;
    long peakRssKiB = 0;
};

std::string jsonLine(const FrameRecord& r) {
    std::ostringstream j;
    j << std::setprecision(9);
    j << "{\"frame\": " << r.frame << ", \"status\": \"" << r.status << "\", \"seconds\": " << r.seconds;
    if (r.status == "baked")
        j << ", \"threads\": " << r.summary.threads << ", \"passes\": " << r.summary.passes
          << ", \"residual\": " << r.summary.residual << ", \"converged\": " << (r.summary.converged ? "true" : "false")
          << ", \"empty\": " << (r.summary.empty ? "true" : "false")
          << ", \"peak_rss_mib\": " << double(r.peakRssKiB) / 1024.0
          << ", \"environment_reused\": " << (r.summary.envReused ? "true" : "false");
    if (r.summary.verified)
        j << ", \"verify_error\": " << r.summary.verify.error << ", \"verify_error_low\": " << r.summary.verify.low
          << ", \"verify_error_high\": " << r.summary.verify.high;
    if (r.status == "failed")
        j << ", \"exit_code\": " << r.exitCode << ", \"error\": \"" << jsonEscape(r.detail) << "\"";
    else j << ", \"reason\": \"" << jsonEscape(r.detail) << "\"";
    j << ", \"input\": \"" << jsonEscape(r.input) << "\", \"output\": \"" << jsonEscape(r.output) << "\"}";
    return j.str();
}

/// Exit code and one-line message of the exception in flight (the CLI's mapping).
int classifyCurrentException(std::string& message) {
    try {
        throw;
    } catch (const UsageError&) {
        throw;  // not a frame's fault: the whole sequence stops
    } catch (const InputError& e) {
        message = e.what();
        return kExitInput;
    } catch (const OutputError& e) {
        message = e.what();
        return kExitOutput;
    } catch (const Error& e) {
        message = e.what();
        return kExitInput;
    } catch (const std::bad_alloc&) {
        message = "internal: out of memory (try a smaller volume or --max-voxels)";
        return kExitInternal;
    } catch (const std::exception& e) {
        message = std::string("internal: ") + e.what();
        return kExitInternal;
    }
}

void checkSequence(const SequenceOptions& s) {
    const BakeOptions& b = s.bake;
    if (s.frames.empty()) throw UsageError("no frames to bake");
    if (s.frames.size() > 1) {
        if (!hasFramePattern(b.output))
            throw UsageError("output '" + b.output + "' has no frame pattern (####, @, %04d or $F4) for " +
                             std::to_string(s.frames.size()) + " frames");
        if (!hasFramePattern(b.input))
            throw UsageError("input '" + b.input + "' has no frame pattern (####, @, %04d or $F4) for " +
                             std::to_string(s.frames.size()) + " frames");
        if (!b.statsPath.empty() && !hasFramePattern(b.statsPath) && hasFramePattern(b.output) &&
            expandFramePattern(b.statsPath, 0) == expandFramePattern(b.output, 0))
            throw UsageError("--stats and --output name the same files");
    }
}

/// Per-sequence stats JSON: settings, every frame's record, totals.
void writeSequenceStats(const SequenceOptions& s, const std::vector<FrameRecord>& records, double seconds,
                        int envReads) {
    std::ostringstream j;
    j << std::setprecision(9);
    j << "{\n  \"tool\": \"lpmbake " << LPM_VERSION_STRING << "\",\n";
    j << "  \"input_pattern\": \"" << jsonEscape(s.bake.input) << "\",\n";
    j << "  \"output_pattern\": \"" << jsonEscape(s.bake.output) << "\",\n";
    j << "  \"settings_digest\": \"" << settingsDigest(frameOptions(s.bake, s.frames.front())) << "\",\n";
    int baked = 0, skipped = 0, failed = 0;
    for (const auto& r : records) (r.status == "baked" ? baked : r.status == "skipped" ? skipped : failed)++;
    j << "  \"frames_requested\": " << s.frames.size() << ", \"baked\": " << baked << ", \"skipped\": " << skipped
      << ", \"failed\": " << failed << ", \"not_run\": " << s.frames.size() - records.size() << ",\n";
    j << "  \"environment_reads\": " << envReads << ",\n  \"seconds\": " << seconds << ",\n  \"frames\": [";
    for (size_t i = 0; i < records.size(); ++i) j << (i ? "," : "") << "\n    " << jsonLine(records[i]);
    j << "\n  ]\n}\n";
    AtomicOutput out(s.bake.statsPath, {});
    {
        std::ofstream f(out.tempPath());
        f << j.str();
        f.close();
        if (!f) throw OutputError("stats", "cannot write '" + out.tempPath() + "'");
    }
    out.commit();
}

/// Sink of --frame-log: stdout, one file for the sequence, or one file per frame.
class FrameLog {
public:
    FrameLog(const std::string& path, std::ostream& out) : path_(path), out_(out) {
        if (!path.empty() && path != "-" && !hasFramePattern(path)) {
            file_.open(path, std::ios::trunc);
            if (!file_) throw OutputError("frame log", "cannot write '" + path + "'");
        }
    }
    void write(const FrameRecord& r) {
        if (path_.empty()) return;
        const std::string line = jsonLine(r) + "\n";
        if (path_ == "-") {
            out_ << line << std::flush;
        } else if (file_.is_open()) {
            file_ << line << std::flush;
        } else {
            const std::string path = expandFramePattern(path_, r.frame);
            std::ofstream f(path, std::ios::trunc);
            f << line;
            f.close();
            if (!f) throw OutputError("frame log", "cannot write '" + path + "'");
        }
        if (file_.is_open() && !file_) throw OutputError("frame log", "cannot write '" + path_ + "'");
    }

private:
    std::string path_;
    std::ostream& out_;
    std::ofstream file_;
};

FrameRecord bakeFrame(const SequenceOptions& s, int frame, const Log& log, BakeContext& context) {
    FrameRecord r;
    r.frame = frame;
    const BakeOptions o = frameOptions(s.bake, frame);
    r.input = o.input;
    r.output = o.output;
    const auto t0 = Clock::now();
    if (s.skipExisting) {
        r.detail = pendingReason(o);
        if (r.detail.empty()) {
            r.status = "skipped";
            r.detail = "output is a complete bake of the same settings, newer than its inputs";
            log.note("frame " + std::to_string(frame) + ": skipped, " + o.output + " is up to date");
            return r;
        }
    } else {
        r.detail = "--skip-existing not given";
    }
    if (mtimeNs(o.input) < 0) {  // a hole in the sequence: say so plainly
        r.status = "failed";
        r.exitCode = kExitInput;
        r.detail = "input: frame " + std::to_string(frame) + " is missing: no file '" + o.input + "'";
        log.error("frame " + std::to_string(frame) + ": " + r.detail);
        return r;
    }
    resetPeakRss();
    try {
        r.summary = runBake(o, log, &context);
        r.status = "baked";
        if (r.summary.verifyFailed) {
            r.status = "failed";
            r.exitCode = kExitVerify;
            r.detail = "verify: estimated error " + fmt(r.summary.verify.error) + " (low end " +
                       fmt(r.summary.verify.low) + ") above --max-error " + fmt(o.maxError) +
                       "; written and marked lpm:verify_failed";
            log.error("frame " + std::to_string(frame) + ": " + r.detail);
        }
    } catch (...) {
        r.exitCode = classifyCurrentException(r.detail);
        r.status = "failed";
        log.error("frame " + std::to_string(frame) + ": " + r.detail);
    }
    r.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
    r.peakRssKiB = peakRssKiB();
    return r;
}

}  // namespace

BakeOptions frameOptions(const BakeOptions& pattern, int frame) {
    BakeOptions o = pattern;
    o.input = expandFramePattern(pattern.input, frame);
    o.output = expandFramePattern(pattern.output, frame);
    o.env = expandFramePattern(pattern.env, frame);
    o.sidecarPath = expandFramePattern(pattern.sidecarPath, frame);
    // One stats file per frame when the path has a pattern; else the sequence writes one.
    o.statsPath = hasFramePattern(pattern.statsPath) ? expandFramePattern(pattern.statsPath, frame) : "";
    return o;
}

std::string pendingReason(const BakeOptions& o) {
    const long long tOut = mtimeNs(o.output);
    if (tOut < 0) return "no output yet";
    try {
        const BakeFile f = readBakeFile(o.output);
        const std::vector<std::string> problems = validateBake(f);
        if (!problems.empty()) return "the output is not a valid bake: " + problems.front();
        const std::string digest = getString(*f.meta, bakekey::settingsDigest, "");
        if (digest != settingsDigest(o))
            return digest.empty() ? "the output records no settings digest (made by an older lpmbake)"
                                  : "the output was made with other settings (lpm:settings_digest " + digest + ")";
        if (getBool(*f.meta, bakekey::verifyFailed, false)) return "the output failed its --max-error check";
    } catch (const Error& e) {
        return std::string("the output cannot be read: ") + e.what();
    }
    if (!o.sidecarPath.empty() && mtimeNs(o.sidecarPath) < 0) return "no sidecar " + o.sidecarPath;
    if (mtimeNs(o.input) > tOut) return "the input is newer than the output";
    if (mtimeNs(o.env) > tOut) return "the environment is newer than the output";
    return "";
}

int runSequence(const SequenceOptions& s, const Log& log, std::ostream& out) {
    checkSequence(s);
    if (s.listPending) {
        std::vector<int> pending;
        for (int f : s.frames) {
            const std::string why = pendingReason(frameOptions(s.bake, f));
            if (!why.empty()) pending.push_back(f);
            log.debug("frame " + std::to_string(f) + ": " + (why.empty() ? "up to date" : why));
        }
        out << formatFrameList(pending) << "\n";
        return kExitOk;
    }
    const auto t0 = Clock::now();
    FrameLog frameLog(s.frameLog, out);
    BakeContext context;
    std::vector<FrameRecord> records;
    std::vector<int> failed;
    int lastCode = kExitOk;
    for (int frame : s.frames) {
        records.push_back(bakeFrame(s, frame, log, context));
        frameLog.write(records.back());
        if (records.back().status == "failed") {
            failed.push_back(frame);
            lastCode = records.back().exitCode;
            if (!s.keepGoing) break;
        }
    }
    const double seconds = std::chrono::duration<double>(Clock::now() - t0).count();
    if (!s.bake.statsPath.empty() && !hasFramePattern(s.bake.statsPath))
        writeSequenceStats(s, records, seconds, context.envReads);
    if (s.frames.size() > 1)
        log.note("sequence: " + std::to_string(records.size()) + " of " + std::to_string(s.frames.size()) +
                 " frames run, " + std::to_string(failed.size()) + " failed, " + fmt(seconds) + " s");
    if (failed.empty()) return kExitOk;
    log.error("failed frames: " + formatFrameList(failed) +
              (s.keepGoing || records.size() == s.frames.size()
                   ? ""
                   : " (stopped at the first failure; " + std::to_string(s.frames.size() - records.size()) +
                         " frame(s) not run: give --keep-going to bake the rest)"));
    return s.frames.size() == 1 ? lastCode : kExitFramesFailed;
}

}  // namespace lpm

// Frame sequences (docs/farm.md): one lpmbake run bakes the frames of a pattern such as
// smoke.####.vdb, each independently and atomically, resumable with --skip-existing,
// with one JSON line per frame and a per-sequence stats file. Work that does not change
// between frames (the environment, the solver's form factors) is done once.
#pragma once

#include <ostream>
#include <string>
#include <vector>

#include "baker/options.h"

namespace lpm {

/// Exit code of a multi-frame sequence in which some frames failed (docs/cli.md).
constexpr int kExitFramesFailed = 5;

struct SequenceOptions {
    BakeOptions bake;         ///< input, output, env, stats may hold frame patterns
    std::vector<int> frames;  ///< in the order to bake them
    bool skipExisting = false;
    bool keepGoing = false;
    bool listPending = false;  ///< print the frames still to bake; bake nothing
    std::string frameLog;      ///< JSON line per frame: a path (may hold a pattern) or "-" (stdout)
};

/// The options of one frame: every pattern in the paths replaced by `frame`.
BakeOptions frameOptions(const BakeOptions& pattern, int frame);

/// Why the output of `o` must be baked: "" when it is already a valid, complete bake made
/// with the same settings (lpm:settings_digest) and newer than its input files.
std::string pendingReason(const BakeOptions& o);

/// Runs the sequence; never throws for a frame's failure (UsageError for bad options).
/// `out` receives --list-pending's line and --frame-log "-". Returns an ExitCode, or
/// kExitFramesFailed when some of several frames failed.
int runSequence(const SequenceOptions& options, const Log& log, std::ostream& out);

}  // namespace lpm

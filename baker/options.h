// Options of the three lpmbake commands, as plain structs: the CLI (cli.cpp) fills them,
// the library functions (bake.cpp, render.cpp, info.cpp) consume them. Tests build them
// directly.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "core/envmap.h"
#include "core/error.h"
#include "core/lpm_cache.h"
#include "core/lpm_solver.h"
#include "core/math.h"
#include "core/verify.h"

namespace lpm {

/// Exit codes (documented in --help and docs/cli.md).
/// (5, kExitFramesFailed, is a sequence's: baker/sequence.h.) kExitVerify: the bake was
/// written, but its --verify estimate is above --max-error (the file says so:
/// lpm:verify_failed).
enum ExitCode : int {
    kExitOk = 0,
    kExitUsage = 1,
    kExitInput = 2,
    kExitOutput = 3,
    kExitInternal = 4,
    kExitVerify = 6
};

/// A bad command line (inconsistent or out-of-range options): exit code 1.
class UsageError : public Error {
public:
    explicit UsageError(const std::string& message) : Error("usage", message) {}
};

/// Messages to stderr, filtered by verbosity (0 = -q: errors only, 1 = default, 2 = -v).
struct Log {
    int verbosity = 1;
    void warn(const std::string& m) const;   ///< "lpmbake: warning: m" (verbosity >= 1)
    void note(const std::string& m) const;   ///< "lpmbake: m" (verbosity >= 1)
    void debug(const std::string& m) const;  ///< "lpmbake: m" (verbosity >= 2)
    void error(const std::string& m) const;  ///< "lpmbake: error: m" (always)
};

struct SunOption {
    Vec3 toSun{0, 1, 0};  ///< direction toward the sun (need not be unit)
    RGB irradiance{1, 1, 1};
    double angleDeg = 0.53;
};

struct BakeOptions {
    std::string input, output;
    std::string grid = "density";
    int gridIndex = -1;
    bool convertLevelSet = false;
    bool sanitize = false;
    double densityScale = 1.0;
    RGB albedo{0.9f, 0.9f, 0.9f};
    double g = 0.0;
    std::string emissionGrid;
    double emissionScale = 1.0;
    std::string temperatureGrid;
    double temperatureScale = 1.0, temperatureOffset = 0.0, temperatureIntensity = 1.0;

    std::string env, envColorSpace;
    std::string workingSpace = "ACEScg";
    double envRotateDeg = 0.0;
    float envScale = 1.0f;
    UpAxis upAxis = UpAxis::Y;  ///< the scene's up axis: where the environment's zenith lies
    std::vector<SunOption> suns;

    LpmSettings solver;
    std::string quality = "default";  ///< --quality preset the solver knobs came from (baker/quality.h)
    int threads = 0;                  ///< 0 = all cores
    bool half = false;
    bool zip = false;  ///< zip-compress the grids (--compression zip): up to 11% smaller, write 4-6x slower
    bool noDensity = false;
    bool rendererGrids = false;  ///< also write extinction and source (vdb_io/renderer_grids.h)
    std::uint64_t maxVoxels = 1ull << 30;
    double solveScale = 1.0;  ///< solve voxels per input voxel along each axis, in [0.05, 8]
    int sunTerm = -1;         ///< exact sun term: -1 auto (when g != 0), 0 off, 1 on (core/sun_term.h)
    int verifyProbes = 0;     ///< --verify N: Monte Carlo probes after the bake (core/verify.h); 0 = none
    int verifyPaths = 4096;   ///< paths per probe
    std::uint64_t verifySeed = VerifySettings{}.seed;  ///< which voxels are drawn, and their paths
    double maxError = -1;  ///< --max-error E (negative: none): kExitVerify when the estimate's lower bound exceeds E
    std::string statsPath;
    std::string sidecarPath;  ///< the metadata as JSON beside the bake (vdb_io/sidecar.h); may be empty
    std::string commandLine;  ///< recorded in the metadata
};

struct BakeSummary {
    bool empty = false;
    int shOrder = 0, passes = 0;
    double residual = 0;
    bool converged = false;
    std::uint64_t denseVoxels = 0, activeVoxels = 0, segments = 0;  ///< denseVoxels: stored (tiled) voxels
    std::uint64_t boxVoxels = 0, tilesStored = 0, tilesInBox = 0;
    double solveScale = 1.0;
    int solveDims[3] = {0, 0, 0};  ///< the solve block (0 for an empty bake)
    Vec3 solveVoxelSize{0, 0, 0};  ///< its voxel size, world units (input voxel size / solveScale)
    double secondsRead = 0, secondsEnv = 0, secondsSolve = 0, secondsWrite = 0, secondsTotal = 0;
    bool envReused = false;  ///< the environment came from the sequence's context
    /// Where the environment's pixels came from: "" (none), "decoded" (the image helper),
    /// "image cache" (vdb_io/image_cache.h), "sequence" (an earlier frame's).
    std::string envSource;
    int threads = 0;        ///< worker threads the bake ran with
    int sunTerms = 0;       ///< exact sun terms written (sun_transmittance_K grids)
    bool verified = false;  ///< --verify ran (`verify` holds its report)
    VerifyReport verify;
    bool verifyFailed = false;  ///< the estimate's lower bound exceeds --max-error
    long peakRssKiB = 0;
};

struct RenderOptions {
    std::string bake, output, env, envColorSpace;
    Vec3 eye{0, 0, 5}, target{0, 0, 0}, up{0, 1, 0};
    bool autoEye = false, autoTarget = false;  ///< frame the volume's bounding box instead
    bool autoUp = false;                       ///< the bake's up axis (lpm:up_axis) instead of `up`
    double fovYDeg = 40;
    int width = 256, height = 256;
    double stepVoxels = 0.5;  ///< ray-march step in voxels
    int threads = 0;
};

struct InfoOptions {
    std::string bake;
    bool digest = false;  ///< print only the content digest (vdb_io/bake_digest.h)
};

struct EnvInput;

/// Work shared by the frames of a sequence (baker/sequence.cpp): the environment, read
/// and converted once per distinct file and colour options, and the solver's
/// precomputations (core/lpm_cache.h). A bake gives the same output with or without one.
struct BakeContext {
    std::string envKey;  ///< what `env` was read from (path and read options)
    std::shared_ptr<EnvInput> env;
    std::shared_ptr<LpmCache> solverCache;
    int envReads = 0;  ///< environments read so far (reported by sequences)
};

/// Bakes; throws lpm::Error subclasses (UsageError, InputError, OutputError). `context`
/// (optional) carries work over from earlier frames of a sequence.
BakeSummary runBake(const BakeOptions& options, const Log& log, BakeContext* context = nullptr);
/// Renders a preview image of a bake; throws like runBake.
void runRender(const RenderOptions& options, const Log& log);
/// Prints a report to `out`; returns kExitOk for a valid bake, kExitInput otherwise.
int runInfo(const InfoOptions& options, std::ostream& out, const Log& log);

/// Parses the command line and runs the command; never throws. Returns an ExitCode.
int runCli(int argc, char** argv);

}  // namespace lpm

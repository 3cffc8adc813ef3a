// `lpmbake IN.vdb ...`: read the density and lights, solve, write the bake (+ stats).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <optional>
#include <sstream>

#include "baker/bake_metadata.h"
#include "baker/options.h"
#include "baker/peak_memory.h"
#include "baker/stats_json.h"
#include "baker/stop_warning.h"
#include "baker/text_format.h"
#include "core/lpm_cache.h"
#include "core/parallel.h"
#include "core/sh.h"
#include "vdb_io/atomic_file.h"
#include "vdb_io/bake_file.h"
#include "vdb_io/env_reader.h"
#include "vdb_io/io_error.h"
#include "vdb_io/sidecar.h"
#include "vdb_io/volume_reader.h"

namespace lpm {

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

/// One number for cubic voxels, X,Y,Z otherwise.
std::string fmtVoxelSize(const Vec3& v) { return fmt(v.x) == fmt(v.y) && fmt(v.y) == fmt(v.z) ? fmt(v.x) : fmtVec(v); }
std::string fmtDims(const int d[3]) {
    return std::to_string(d[0]) + "x" + std::to_string(d[1]) + "x" + std::to_string(d[2]);
}

/// The CLI flag of a settings field (SettingError::field()), for errors in the user's words.
std::string flagOf(const std::string& field) {
    static const std::pair<const char*, const char*> flags[] = {{"densityScale", "--density-scale"},
                                                                {"emissionScale", "--emission-scale"},
                                                                {"temperatureScale", "--temperature-scale"},
                                                                {"temperatureOffset", "--temperature-offset"},
                                                                {"temperatureIntensity", "--temperature-intensity"},
                                                                {"solveScale", "--solve-scale"},
                                                                {"maxDenseVoxels", "--max-voxels"},
                                                                {"scale", "--env-scale"},
                                                                {"rotateYDeg", "--env-rotate"},
                                                                {"albedo", "--albedo"},
                                                                {"g", "--g"},
                                                                {"toSun", "--sun"},
                                                                {"irradiance", "--sun-irradiance"},
                                                                {"angularDiameterDeg", "--sun-angle"},
                                                                {"directionsPerFace", "--directions-per-face"},
                                                                {"raysPerVoxel", "--rays-per-voxel"},
                                                                {"raysHigherOrders", "--rays-higher-orders"},
                                                                {"binsPerFace", "--bins-per-face"},
                                                                {"shOrder", "--sh-order"},
                                                                {"tolerance", "--tolerance"},
                                                                {"maxOrders", "--max-orders"},
                                                                {"krylovRestart", "--krylov-restart"},
                                                                {"subdivide", "--subdivide"},
                                                                {"multires", "--multires"},
                                                                {"multiresAfter", "--multires-after"},
                                                                {"separableSource", "--separable-sources"},
                                                                {"shapedCoarseTail", "--two-grid-tail"},
                                                                {"diffusionTail", "--two-grid-tail"},
                                                                {"linearSource", "--source"},
                                                                {"deltaM", "--delta-m"},
                                                                {"envHotShare", "--env-hot-share"},
                                                                {"probes", "--verify"},
                                                                {"pathsPerProbe", "--verify-paths"}};
    for (const auto& f : flags)
        if (field == f.first) return f.second;
    return field;  // a setting without a flag (only reachable from the library)
}

VolumeReadOptions volumeReadOptions(const BakeOptions& o) {
    VolumeReadOptions vo;
    vo.path = o.input;
    vo.gridName = o.grid;
    vo.gridIndex = o.gridIndex;
    vo.densityScale = o.densityScale;
    vo.sanitize = o.sanitize;
    vo.convertLevelSet = o.convertLevelSet;
    vo.emissionGrid = o.emissionGrid;
    vo.emissionScale = o.emissionScale;
    vo.temperatureGrid = o.temperatureGrid;
    vo.temperatureScale = o.temperatureScale;
    vo.temperatureOffset = o.temperatureOffset;
    vo.temperatureIntensity = o.temperatureIntensity;
    vo.workingSpace = o.workingSpace;
    vo.maxDenseVoxels = o.maxVoxels;
    vo.solveScale = o.solveScale;
    return vo;
}

EnvReadOptions envReadOptions(const BakeOptions& o) {
    EnvReadOptions eo;
    eo.path = o.env;
    eo.colorSpace = o.envColorSpace;
    eo.workingSpace = o.workingSpace;
    eo.rotateYDeg = o.envRotateDeg;
    eo.scale = o.envScale;
    eo.up = o.upAxis;
    eo.sanitize = o.sanitize;
    return eo;
}

Sun toSun(const SunOption& s) { return Sun{normalize(s.toSun), s.irradiance, s.angleDeg}; }

/// --verify's settings; --max-error alone implies 64 probes.
VerifySettings verifySettings(const BakeOptions& o) {
    VerifySettings v;
    v.probes = o.verifyProbes > 0 || o.maxError < 0 ? o.verifyProbes : 64;
    v.pathsPerProbe = o.verifyPaths;
    v.seed = o.verifySeed;
    return v;
}

/// What the command needs, then every settings struct's own range rules (the library is
/// their one home), with the failing field named by its flag.
void checkOptions(const BakeOptions& o) {
    if (o.input.empty()) throw UsageError("no input VDB given");
    if (o.output.empty()) throw UsageError("no output given (-o OUT.vdb)");
    if (o.env.empty() && o.suns.empty() && o.emissionGrid.empty() && o.temperatureGrid.empty())
        throw UsageError("no light: give --env, --sun or --emission-grid");
    if (o.threads < 0)
        throw UsageError("--threads must be 0 (all cores) or positive, got " + std::to_string(o.threads));
    if (!(o.maxError < 0) && !(o.maxError > 0 && o.maxError < 10))  // negative: not given
        throw UsageError("--max-error must be in (0, 10) (a relative error: 0.02 = 2%), got " + fmt(o.maxError));
    try {
        volumeReadOptions(o).validate();
        envReadOptions(o).validate();
        validateMaterial(o.albedo, o.g);
        for (const SunOption& s : o.suns) {
            Sun sun{s.toSun, s.irradiance, s.angleDeg};
            sun.validate();
        }
        o.solver.validate();
        if (o.verifyProbes != 0 || o.maxError >= 0) verifySettings(o).validate();
        else if (o.verifyPaths != VerifySettings{}.pathsPerProbe || o.verifySeed != VerifySettings{}.seed)
            throw UsageError("--verify-paths and --verify-seed need --verify N or --max-error E");
    } catch (const SettingError& e) {
        throw UsageError(flagOf(e.field()) + " " + e.rule());
    }
}

/// 1. The volume, resampled into the dense solve block.
VolumeInput readVolumeStage(const BakeOptions& o, BakeSummary& sum, const Log& log) {
    const auto t = Clock::now();
    VolumeInput vol = readVolume(volumeReadOptions(o));
    for (const auto& w : vol.warnings) log.warn(w);
    sum.secondsRead = since(t);
    sum.empty = vol.empty;
    sum.activeVoxels = vol.activeVoxels;
    sum.denseVoxels = vol.empty ? 0 : vol.medium.voxelCount();
    sum.boxVoxels = vol.empty ? 0 : vol.medium.blockVoxelCount();
    sum.tilesInBox = vol.empty ? 0 : std::uint64_t(vol.medium.tilesX()) * vol.medium.tilesY() * vol.medium.tilesZ();
    sum.tilesStored = vol.medium.sparse() ? vol.medium.storedTiles : sum.tilesInBox;
    sum.solveScale = o.solveScale;
    sum.solveDims[0] = vol.medium.nx;
    sum.solveDims[1] = vol.medium.ny;
    sum.solveDims[2] = vol.medium.nz;
    // An empty input has no block; the reader then leaves the input's voxel size.
    sum.solveVoxelSize = vol.empty ? vol.medium.voxelSize * (1.0 / o.solveScale) : vol.medium.voxelSize;
    if (o.solveScale != 1.0 && !vol.empty)
        log.note("solve grid " + fmtDims(sum.solveDims) + " at voxel size " + fmtVoxelSize(sum.solveVoxelSize) +
                 " (--solve-scale " + fmt(o.solveScale) + "; input voxel size " +
                 fmtVoxelSize(vol.medium.voxelSize * o.solveScale) + ")");
    log.debug("read " + o.input + ": " + std::to_string(vol.activeVoxels) + " active voxels, block " +
              fmtDims(sum.solveDims) + " in 8^3 tiles (" + std::to_string(sum.tilesStored) + " of " +
              std::to_string(sum.tilesInBox) + " stored), voxel size " + fmtVec(vol.medium.voxelSize));
    vol.medium.albedo = o.albedo;
    vol.medium.g = o.g;
    return vol;
}

/// What identifies a converted environment: the file and every option applied to it.
std::string envKey(const BakeOptions& o) {
    return o.env + "\n" + o.envColorSpace + "\n" + o.workingSpace + "\n" + fmtExact(o.envRotateDeg) + "\n" +
           fmtExact(o.envScale) + "\n" + upAxisName(o.upAxis) + "\n" + std::to_string(o.sanitize);
}

/// True when the sequence's copy of the environment serves this bake.
bool envReusable(const BakeOptions& o, const BakeContext* context) {
    return context && context->env && context->envKey == envKey(o);
}

/// 2. The environment: converted from the image `decode` started reading, or the
/// sequence's copy when the same file and options were read for an earlier frame.
std::shared_ptr<EnvInput> readEnvironmentStage(const BakeOptions& o, BakeContext* context, ImageDecode* decode,
                                               BakeSummary& sum, const Log& log) {
    const auto t = Clock::now();
    auto envHeld = std::make_shared<EnvInput>();
    if (o.env.empty()) return envHeld;
    if (envReusable(o, context)) {
        sum.envReused = true;
        sum.envSource = "sequence";
        sum.secondsEnv = since(t);
        return context->env;
    }
    const std::string key = envKey(o);
    *envHeld = decode ? readEnvironment(envReadOptions(o), *decode) : readEnvironment(envReadOptions(o));
    sum.envSource = decode && decode->cacheHit() ? "image cache" : "decoded";
    if (decode && !decode->cacheNote().empty()) log.debug("environment " + o.env + ": " + decode->cacheNote());
    for (const auto& w : envHeld->warnings) log.warn(w);
    log.debug("environment " + o.env + ": " + std::to_string(envHeld->width) + "x" + std::to_string(envHeld->height) +
              ", " + envHeld->colorSpace + " -> " + envHeld->workingSpace);
    if (context) {
        // The solver's binnings of the old map are keyed by its address: drop them before
        // the map goes.
        if (context->solverCache) context->solverCache->forgetEnvironments();
        context->env = envHeld;
        context->envKey = key;
        ++context->envReads;
    }
    sum.secondsEnv = since(t);
    return envHeld;
}

/// The solver's settings for this bake: the exact sun term where SH cannot hold a sun's
/// single scattering (any g != 0), the shared cache, and progress lines: every pass with
/// -v; otherwise, once the solve has run a second, at most one line a second.
LpmSettings solveSettings(const BakeOptions& o, BakeContext* context, const Log& log) {
    LpmSettings settings = o.solver;
    settings.sunTerms = o.sunTerm == 1 || (o.sunTerm < 0 && o.g != 0.0);
    // Directional SH stays held by the written voxels' rows: the writer reads it through
    // them (its peak then holds the rows, not one row per stored voxel); the stages that
    // read it by voxel (verify, the sun terms) expand it first.
    settings.keepShRows = true;
    if (context && !context->solverCache) context->solverCache = std::make_shared<LpmCache>();
    // Without a sequence the cache still holds the plan's environment binning for the solve.
    settings.cache = context ? context->solverCache : std::make_shared<LpmCache>();
    if (log.verbosity >= 2) {
        settings.progress = [&log](const std::string& p) { log.debug(p); };
    } else if (log.verbosity >= 1) {
        const auto start = Clock::now();
        auto lastShown = std::make_shared<Clock::time_point>(start);
        settings.progress = [&log, start, lastShown](const std::string& p) {
            const auto now = Clock::now();
            if (std::chrono::duration<double>(now - start).count() < 1.0) return;
            if (*lastShown != start && std::chrono::duration<double>(now - *lastShown).count() < 1.0) return;
            *lastShown = now;
            log.note(p);
        };
    }
    return settings;
}

/// 2b. The solve reads the environment only through its binning, which planning makes and
/// keeps in settings.cache for every medium of the solve (they share one rotation). A
/// single bake without --verify bins it now and frees the pixels before the solver's
/// buffers are made: 400 MB of an 8192 x 4096 sky. A sequence keeps them for its next
/// volume, whose rotation (and so binning) may differ; --verify's Monte Carlo reads them.
void releaseEnvironmentPixels(const BakeOptions& o, const VolumeInput& vol, const Lights& lights,
                              const LpmSettings& settings, const BakeContext* context, EnvInput& env, const Log& log) {
    if (context || !env.env || vol.empty || verifySettings(o).probes > 0) return;
    planLpm(vol.medium, lights, settings);
    env.env->releasePixels();
    log.debug("environment: binned, its pixels (" + fmt(double(env.width) * env.height * 12.0 / (1 << 20)) +
              " MiB) freed before the solve");
}

/// 3. The solve (with -v the plan first), or the empty result of an empty volume. Marks
/// the voxels the bake writes in vol.medium (markWantedS) when the solve keeps directional SH.
LpmResult solveStage(const BakeOptions& o, VolumeInput& vol, const Lights& lights, const LpmSettings& settings,
                     BakeSummary& sum, const Log& log) {
    const auto t = Clock::now();
    LpmResult res;
    if (!vol.empty) {
        // The solver holds directional SH only where the bake writes it (core/sh_rows.h),
        // and its sweeps skip the empty voxels nobody reads (core/sweep.cpp, dead chunks).
        markWantedS(vol);
        if (log.verbosity >= 2)
            for (const std::string& line : planLpm(vol.medium, lights, settings).lines(true))
                log.debug("plan: " + line);
        res = solveLpm(vol.medium, lights, settings);
        // With -v the plan was printed before the solve: after it, only what the solve met.
        const std::vector<std::string> planned = log.verbosity >= 2 ? res.plan.lines() : std::vector<std::string>{};
        for (const auto& d : res.decisions)
            if (std::find(planned.begin(), planned.end(), d) == planned.end()) log.note("solver: " + d);
    } else {
        res.shOrder = o.g == 0.0 ? 0 : o.solver.shOrder;  // same rule as the solver
        res.coeffs = shCount(res.shOrder);
        res.converged = true;
    }
    sum.secondsSolve = since(t);
    sum.shOrder = res.shOrder;
    sum.passes = int(res.passes.size());
    sum.residual = res.residual;
    sum.converged = res.converged;
    sum.segments = res.segments;
    if (!vol.empty && !res.converged) log.warn(stopWarning(res, o.solver.tolerance));
    return res;
}

/// 3b. --verify: Monte Carlo probes of the result (with every sun's single scattering still
/// in the SH), and --max-error's verdict.
void verifyStage(const BakeOptions& o, const VolumeInput& vol, const Lights& lights, const LpmResult& res,
                 BakeSummary& sum, const Log& log) {
    const VerifySettings vs = verifySettings(o);
    if (vs.probes <= 0) return;
    if (vol.empty) {
        log.note("verify: the volume is empty: nothing to check");
        return;
    }
    sum.verify = verifyBake(vol.medium, lights, res.sh, res.coeffs, vs);
    sum.verified = true;
    const VerifyReport& v = sum.verify;
    if (v.probes == 0) {
        log.note("verify: nothing a renderer would see scatters light (no probe drawn)");
        return;
    }
    const auto g3 = [](double x) {
        char buf[32];
        std::snprintf(buf, sizeof buf, "%.3g", x);
        return std::string(buf);
    };
    const auto pct = [&g3](double x) { return g3(100.0 * x) + "%"; };
    log.note("verify: estimated relative error " + pct(v.error) + " (" + fmt(100.0 * v.confidence) + "% interval " +
             pct(v.low) + " to " + pct(v.high) + "; " + std::to_string(v.probes) + " probes of " +
             std::to_string(v.pathsPerProbe) + " paths, their noise " + pct(v.mcNoise) + ", " + g3(v.seconds) + " s)" +
             (o.solveScale != 1.0 ? "; on the --solve-scale grid: the resampling to the input's voxels is not checked"
                                  : ""));
    if (o.maxError >= 0 && v.low > o.maxError) {
        sum.verifyFailed = true;
        log.warn("verify: the error is above --max-error " + pct(o.maxError) + " with " + fmt(100.0 * v.confidence) +
                 "% confidence; the bake is written and marked lpm:verify_failed (exit " + std::to_string(kExitVerify) +
                 ")");
    }
}

/// 4. The suns' single scattering leaves the SH for the exact terms; the returned
/// direction-averaged `scatter` keeps it (empty: scatter = sh_0 Y00).
std::vector<float> separateSunTerms(const BakeOptions& o, bool sunTermsAsked, bool emptyVolume, LpmResult& res,
                                    BakeSummary& sum, const Log& log) {
    std::vector<float> scatter;
    if (!res.sunTerms.empty()) {
        scatter.resize(res.sh.size() / res.coeffs);
        for (size_t v = 0; v < scatter.size() / 3; ++v)
            for (int c = 0; c < 3; ++c) scatter[v * 3 + c] = res.sh[v * res.coeffs * 3 + c] * float(kY00);
        removeSunTermsFromSh(res.sh, res.shOrder, res.sunTerms, o.g);
        res.decisions.push_back("exact sun term: " + std::to_string(res.sunTerms.size()) +
                                " sun(s) kept out of the SH and stored as transmittance grids (g = " + fmt(o.g) +
                                ": no low SH order holds the phase lobe of a sun's single scattering)");
        log.note(res.decisions.back());
    } else if (!emptyVolume && !o.suns.empty() && !sunTermsAsked) {
        res.decisions.push_back(o.g == 0.0 ? "no exact sun term: g = 0, SH order 0 holds isotropic single scattering "
                                             "exactly"
                                           : "no exact sun term (--sun-term off): suns' single scattering through SH");
    }
    sum.sunTerms = int(res.sunTerms.size());
    return scatter;
}

/// 5. What the writer needs: the solve block's place in the input and its values.
/// The writer frees res.sh once its grids hold the values.
DenseBake denseBake(const VolumeInput& vol, LpmResult& res, const std::vector<float>& scatter) {
    const Medium& m = vol.medium;
    DenseBake db;
    db.blockMin = vol.blockMin;
    db.scale = vol.solveGrid.scale;
    db.corner = vol.solveGrid.corner;
    db.affine = vol.solveGrid.affine;
    std::copy(&vol.solveGrid.M[0][0], &vol.solveGrid.M[0][0] + 9, &db.M[0][0]);
    std::copy(vol.solveGrid.t, vol.solveGrid.t + 3, db.t);
    db.nx = m.nx;
    db.ny = m.ny;
    db.nz = m.nz;
    db.coeffs = res.coeffs;
    db.sh = vol.empty ? nullptr : res.sh.data();
    db.shRow = res.shRow.empty() ? nullptr : res.shRow.data();
    db.releaseSh = vol.empty ? nullptr : &res.sh;
    db.emission = (!vol.empty && m.hasEmission()) ? m.emission.data() : nullptr;
    db.scatter = scatter.empty() ? nullptr : scatter.data();
    for (const SunTerm& t : res.sunTerms) db.sunTransmittance.push_back(t.transmittance.data());
    db.layout = vol.empty ? nullptr : &m;
    return db;
}

BakeWriteOptions writeOptions(const BakeOptions& o) {
    BakeWriteOptions wo;
    wo.path = o.output;
    wo.inputs = {o.input, o.env};
    wo.half = o.half;
    wo.zip = o.zip;
    wo.writeDensity = !o.noDensity;
    wo.densityName = "density";  // the name renderers look for; the source name is in lpm:input_grid
    wo.rendererGrids = o.rendererGrids;
    wo.densityScale = o.densityScale;
    wo.albedo = o.albedo;
    return wo;
}

}  // namespace

BakeSummary runBake(const BakeOptions& o, const Log& log, BakeContext* context) {
    checkOptions(o);
    const auto tStart = Clock::now();
    ThreadLimit limit(o.threads);
    BakeSummary sum;
    sum.threads = maxThreads();
    {
        // Fail on an impossible output path before the expensive work.
        AtomicOutput probe(o.output, {o.input, o.env});
    }
    // The environment's image is decoded by a helper process (OpenImageIO: about 0.45 s to
    // load, docs/image_helper.md) while this one reads the volume.
    std::optional<ImageDecode> envDecode;
    if (!o.env.empty() && !envReusable(o, context)) envDecode.emplace(o.env);
    VolumeInput vol = readVolumeStage(o, sum, log);
    const std::shared_ptr<EnvInput> env = readEnvironmentStage(o, context, envDecode ? &*envDecode : nullptr, sum, log);
    Lights lights;
    lights.env = env->env.get();
    for (const auto& s : o.suns) lights.suns.push_back(toSun(s));

    const LpmSettings settings = solveSettings(o, context, log);
    releaseEnvironmentPixels(o, vol, lights, settings, context, *env, log);
    LpmResult res = solveStage(o, vol, lights, settings, sum, log);
    if (verifySettings(o).probes > 0 || !res.sunTerms.empty()) res.expandSh();
    verifyStage(o, vol, lights, res, sum, log);
    const std::vector<float> scatter = separateSunTerms(o, settings.sunTerms, vol.empty, res, sum, log);

    // Metadata: everything a consumer needs to use the bake without this tool.
    const openvdb::MetaMap meta = bakeMetadata(o, sum, res, *env, vol.sanitized + env->sanitized);
    const BakeWriteReport wr = writeBake(*vol.density, denseBake(vol, res, scatter), meta, writeOptions(o));
    for (const auto& w : wr.warnings) log.warn(w);
    sum.secondsWrite = wr.seconds;
    sum.secondsTotal = since(tStart);
    sum.peakRssKiB = peakRssKiB();
    log.note("wrote " + o.output + ": SH order " + std::to_string(res.shOrder) + ", " +
             std::to_string(wr.voxelsWritten) + " voxels, " + std::to_string(sum.passes) + " passes, residual " +
             fmt(res.residual) + ", " + fmt(sum.secondsTotal) + " s, peak memory " +
             fmt(double(sum.peakRssKiB) / 1024.0) + " MiB");
    if (!o.sidecarPath.empty()) writeSidecar(o.sidecarPath, o.output, wr.gridNames, meta, {o.input, o.env, o.output});
    if (!o.statsPath.empty()) writeStats(o, sum, vol.empty ? nullptr : &res);
    return sum;
}

}  // namespace lpm

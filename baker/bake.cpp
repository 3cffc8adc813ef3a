// `lpmbake IN.vdb ...`: read the density and lights, solve, write the bake (+ stats).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <sstream>

#include "baker/bake_metadata.h"
#include "baker/options.h"
#include "baker/peak_memory.h"
#include "baker/sidecar.h"
#include "baker/text_format.h"
#include "core/lpm_cache.h"
#include "core/parallel.h"
#include "core/sh.h"
#include "vdb_io/atomic_file.h"
#include "vdb_io/bake_file.h"
#include "vdb_io/env_reader.h"
#include "vdb_io/io_error.h"
#include "vdb_io/volume_reader.h"

namespace lpm {

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

/// One number for cubic voxels, X,Y,Z otherwise.
std::string fmtVoxelSize(const Vec3& v) {
    return fmt(v.x) == fmt(v.y) && fmt(v.y) == fmt(v.z) ? fmt(v.x) : fmtVec(v);
}
std::string fmtDims(const int d[3]) {
    return std::to_string(d[0]) + "x" + std::to_string(d[1]) + "x" + std::to_string(d[2]);
}


void checkOptions(const BakeOptions& o) {
    if (o.input.empty()) throw UsageError("no input VDB given");
    if (o.output.empty()) throw UsageError("no output given (-o OUT.vdb)");
    if (o.env.empty() && o.suns.empty() && o.emissionGrid.empty() && o.temperatureGrid.empty())
        throw UsageError("no light: give --env, --sun or --emission-grid");
    if (!(o.densityScale >= 0) || !std::isfinite(o.densityScale))
        throw UsageError("--density-scale must be finite and non-negative, got " + fmt(o.densityScale));
    for (int c = 0; c < 3; ++c)
        if (!(o.albedo[c] >= 0 && o.albedo[c] <= 1))
            throw UsageError("--albedo must lie in [0, 1], got " + fmtRgb(o.albedo));
    if (!(o.g > -1 && o.g < 1)) throw UsageError("--g must lie in (-1, 1), got " + fmt(o.g));
    for (const auto& s : o.suns) {
        if (!(length(s.toSun) > 0) || !std::isfinite(length(s.toSun)))
            throw UsageError("--sun direction must be non-zero and finite, got " + fmtVec(s.toSun));
        for (int c = 0; c < 3; ++c)
            if (!(s.irradiance[c] >= 0) || !std::isfinite(s.irradiance[c]))
                throw UsageError("--sun-irradiance must be finite and non-negative, got " + fmtRgb(s.irradiance));
        if (!(s.angleDeg >= 0 && s.angleDeg < 180))
            throw UsageError("--sun-angle must be in [0, 180) degrees, got " + fmt(s.angleDeg));
    }
    if (o.threads < 0) throw UsageError("--threads must be 0 (all cores) or positive, got " + std::to_string(o.threads));
    const LpmSettings& s = o.solver;
    if (s.directionsPerFace < 1 || s.directionsPerFace > 64)
        throw UsageError("--directions-per-face must be in 1..64, got " + std::to_string(s.directionsPerFace));
    if (s.raysPerVoxel < 1 || s.raysPerVoxel > 16) throw UsageError("--rays-per-voxel must be in 1..16");
    if (s.raysHigherOrders != -1 && (s.raysHigherOrders < 1 || s.raysHigherOrders > 16))
        throw UsageError("--rays-higher-orders must be -1 (auto) or in 1..16, got " + std::to_string(s.raysHigherOrders));
    if (s.binsPerFace < -1) throw UsageError("--bins-per-face must be -1 (auto), 0 or more");
    if (s.shOrder < 0 || s.shOrder > kMaxShOrder) throw UsageError("--sh-order must be in 0..3");
    if (!(s.tolerance > 0)) throw UsageError("--tolerance must be positive");
    if (s.maxOrders < 1) throw UsageError("--max-orders must be >= 1");
    // Below 0.05 a solve voxel spans more than 20 input voxels (nothing of the volume's
    // shape survives); above 8 the block grows 512x for no added detail (the medium is
    // piecewise constant on the input's voxels).
    if (!std::isfinite(o.solveScale) || o.solveScale < 0.05 || o.solveScale > 8)
        throw UsageError("--solve-scale must be finite and in [0.05, 8], got " + fmt(o.solveScale));
    if (s.subdivide < 1 || s.subdivide > 8) throw UsageError("--subdivide must be in 1..8, got " + std::to_string(s.subdivide));
    if (s.binsPerFace > 0 && s.directionsPerFace % s.binsPerFace != 0)
        throw UsageError("--bins-per-face " + std::to_string(s.binsPerFace) + " must divide --directions-per-face " +
                         std::to_string(s.directionsPerFace));
    if (!(o.envScale >= 0) || !std::isfinite(o.envScale)) throw UsageError("--env-scale must be finite and >= 0");
}

/// The effect planner's plan with its predicted costs, and the measured cost of each stage
/// of the solve (docs/solve_plan.md).
void writePlanAndStages(std::ostream& j, const LpmResult& r) {
    const SolvePlan& p = r.plan;
    j << "  \"plan\": {\"predicted_fine_pass_segments\": " << p.predictedSegmentsPerFinePass
      << ", \"predicted_fine_pass_s\": " << p.predictedSecondsPerFinePass
      << ", \"predicted_buffers_mib\": " << p.predictedBytes / (1 << 20) << ", \"decisions\": [";
    for (size_t i = 0; i < p.decisions.size(); ++i) {
        const PlanDecision& d = p.decisions[i];
        j << (i ? "," : "") << "\n    {\"decision\": \"" << jsonEscape(d.what) << "\", \"reason\": \"" << jsonEscape(d.why)
          << "\"";
        if (d.predictedSeconds >= 0) j << ", \"predicted_s\": " << d.predictedSeconds;
        if (d.predictedBytes >= 0) j << ", \"predicted_mib\": " << d.predictedBytes / (1 << 20);
        j << "}";
    }
    j << "]},\n";
    double single = 0, fine = 0, coarse = 0, krylov = 0, firstFine = -1;
    std::uint64_t firstFineSegments = 0;
    for (const PassStats& ps : r.passes) {
        if (ps.pass == 0) single += ps.seconds;
        else if (ps.coarse) coarse += ps.seconds;
        else if (ps.krylov) krylov += ps.seconds;
        else fine += ps.seconds;
        if (ps.pass > 0 && !ps.coarse && firstFine < 0) {
            firstFine = ps.seconds;
            firstFineSegments = ps.segments;
        }
    }
    j << "  \"stages_s\": {\"single_scattering\": " << single << ", \"sun_terms\": " << r.sunTermSeconds
      << ", \"fine_orders\": " << fine << ", \"coarse_orders\": " << coarse << ", \"gmres\": " << krylov
      << ", \"first_fine_pass\": " << std::max(0.0, firstFine) << ", \"first_fine_pass_segments\": " << firstFineSegments
      << "},\n";
}

void writeStats(const BakeOptions& o, const BakeSummary& s, const LpmResult* r) {
    std::ostringstream j;
    j << std::setprecision(9);
    j << "{\n  \"tool\": \"lpmbake " << LPM_VERSION_STRING << "\",\n";
    j << "  \"input\": \"" << jsonEscape(o.input) << "\",\n  \"grid\": \"" << jsonEscape(o.grid) << "\",\n";
    j << "  \"output\": \"" << jsonEscape(o.output) << "\",\n";
    j << "  \"threads\": " << maxThreads() << ",\n";
    j << "  \"empty\": " << (s.empty ? "true" : "false") << ",\n";
    j << "  \"voxels\": {\"active\": " << s.activeVoxels << ", \"stored\": " << s.denseVoxels
      << ", \"bounding_box\": " << s.boxVoxels << "},\n";
    j << "  \"tiles\": {\"size\": " << Medium::kTile << ", \"stored\": " << s.tilesStored << ", \"in_box\": " << s.tilesInBox
      << "},\n";
    j << "  \"solve_grid\": {\"solve_scale\": " << s.solveScale << ", \"dims\": [" << s.solveDims[0] << ", "
      << s.solveDims[1] << ", " << s.solveDims[2] << "], \"voxel_size\": [" << s.solveVoxelSize.x << ", "
      << s.solveVoxelSize.y << ", " << s.solveVoxelSize.z << "]},\n";
    j << "  \"timings_s\": {\"read\": " << s.secondsRead << ", \"environment\": " << s.secondsEnv
      << ", \"solve\": " << s.secondsSolve << ", \"write\": " << s.secondsWrite << ", \"total\": " << s.secondsTotal
      << "},\n";
    j << "  \"sh_order\": " << s.shOrder << ",\n  \"passes\": " << s.passes << ",\n";
    j << "  \"residual\": " << s.residual << ",\n  \"converged\": " << (s.converged ? "true" : "false") << ",\n";
    j << "  \"ray_segments\": " << s.segments << ",\n";
    j << "  \"ray_segments_per_second\": " << (s.secondsSolve > 0 ? double(s.segments) / s.secondsSolve : 0.0)
      << ",\n";
    j << "  \"peak_rss_mib\": " << double(s.peakRssKiB) / 1024.0 << ",\n";
    j << "  \"pass_stats\": [";
    if (r)
        for (size_t i = 0; i < r->passes.size(); ++i) {
            const PassStats& p = r->passes[i];
            j << (i ? "," : "") << "\n    {\"pass\": " << p.pass << ", \"injected\": " << p.injected
              << ", \"scattered\": " << p.scattered << ", \"absorbed\": " << p.absorbed << ", \"escaped\": "
              << p.escaped << ", \"seconds\": " << p.seconds << ", \"krylov\": " << (p.krylov ? "true" : "false")
              << ", \"coarse\": " << (p.coarse ? "true" : "false") << ", \"segments\": " << p.segments << "}";
        }
    j << "\n  ],\n";
    if (r) writePlanAndStages(j, *r);
    j << "  \"decisions\": [";
    if (r)
        for (size_t i = 0; i < r->decisions.size(); ++i)
            j << (i ? ", " : "") << "\"" << jsonEscape(r->decisions[i]) << "\"";
    j << "]\n}\n";

    AtomicOutput out(o.statsPath, {o.input, o.env, o.output});
    {
        std::ofstream f(out.tempPath());
        f << j.str();
        f.close();
        if (!f) throw OutputError("stats", "cannot write '" + out.tempPath() + "'");
    }
    out.commit();
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

    // 1. Volume.
    auto t = Clock::now();
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
    VolumeInput vol = readVolume(vo);
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
              std::to_string(vol.medium.nx) + "x" + std::to_string(vol.medium.ny) + "x" +
              std::to_string(vol.medium.nz) + " in 8^3 tiles (" + std::to_string(sum.tilesStored) + " of " +
              std::to_string(sum.tilesInBox) + " stored), voxel size " + fmtVec(vol.medium.voxelSize));

    // 2. Lights.
    t = Clock::now();
    std::shared_ptr<EnvInput> envHeld = std::make_shared<EnvInput>();
    if (!o.env.empty()) {
        EnvReadOptions eo;
        eo.path = o.env;
        eo.colorSpace = o.envColorSpace;
        eo.workingSpace = o.workingSpace;
        eo.rotateYDeg = o.envRotateDeg;
        eo.scale = o.envScale;
        eo.up = o.upAxis;
        eo.sanitize = o.sanitize;
        const std::string key = o.env + "\n" + o.envColorSpace + "\n" + o.workingSpace + "\n" +
                                fmtExact(o.envRotateDeg) + "\n" + fmtExact(o.envScale) + "\n" + upAxisName(o.upAxis) + "\n" +
                                std::to_string(o.sanitize);
        if (context && context->env && context->envKey == key) {
            envHeld = context->env;
            sum.envReused = true;
        } else {
            *envHeld = readEnvironment(eo);
            for (const auto& w : envHeld->warnings) log.warn(w);
            log.debug("environment " + o.env + ": " + std::to_string(envHeld->width) + "x" +
                      std::to_string(envHeld->height) + ", " + envHeld->colorSpace + " -> " + envHeld->workingSpace);
            if (context) {
                // The solver's binnings of the old map are keyed by its address: drop them
                // before the map goes.
                if (context->solverCache) context->solverCache->forgetEnvironments();
                context->env = envHeld;
                context->envKey = key;
                ++context->envReads;
            }
        }
    }
    const EnvInput& env = *envHeld;
    sum.secondsEnv = since(t);
    Lights lights;
    lights.env = env.env.get();
    for (const auto& s : o.suns) lights.suns.push_back(Sun{normalize(s.toSun), s.irradiance, s.angleDeg});

    Medium& m = vol.medium;
    m.albedo = o.albedo;
    m.g = o.g;

    // 3. Solve.
    LpmResult res;
    LpmSettings settings = o.solver;
    // The exact sun term pays where SH cannot hold a sun's single scattering: any g != 0
    // (at g = 0 the phase is isotropic and SH order 0 holds it exactly).
    settings.sunTerms = o.sunTerm == 1 || (o.sunTerm < 0 && o.g != 0.0);
    if (context) {
        if (!context->solverCache) context->solverCache = std::make_shared<LpmCache>();
        settings.cache = context->solverCache;
    } else {
        settings.cache = std::make_shared<LpmCache>();  // the plan's environment binning, reused by the solve
    }
    // Progress: every pass with -v; otherwise, once the solve has run for a second, at
    // most one line a second (farm logs stay short, long interactive runs show life).
    const auto solveStart = Clock::now();
    auto lastShown = solveStart;
    if (log.verbosity >= 2) {
        settings.progress = [&](const std::string& p) { log.debug(p); };
    } else if (log.verbosity >= 1) {
        settings.progress = [&](const std::string& p) {
            const auto now = Clock::now();
            if (std::chrono::duration<double>(now - solveStart).count() < 1.0) return;
            if (lastShown != solveStart && std::chrono::duration<double>(now - lastShown).count() < 1.0) return;
            lastShown = now;
            log.note(p);
        };
    }
    t = Clock::now();
    if (!vol.empty) {
        if (log.verbosity >= 2)
            for (const std::string& line : planLpm(m, lights, settings).lines(true)) log.debug("plan: " + line);
        res = solveLpm(m, lights, settings);
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
    if (!vol.empty && !res.converged)
        log.warn("the solver stopped after " + std::to_string(sum.passes) + " passes with residual " +
                 fmt(res.residual) + " above --tolerance " + fmt(o.solver.tolerance) + " (raise --max-orders)");

    // The suns' single scattering leaves the SH for the exact terms; `scatter` keeps it.
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
    } else if (!vol.empty && !lights.suns.empty() && !settings.sunTerms) {
        res.decisions.push_back(o.g == 0.0 ? "no exact sun term: g = 0, SH order 0 holds isotropic single scattering "
                                             "exactly"
                                           : "no exact sun term (--sun-term off): suns' single scattering through SH");
    }
    sum.sunTerms = int(res.sunTerms.size());

    // 4. Metadata: everything a consumer needs to use the bake without this tool.
    const openvdb::MetaMap meta = bakeMetadata(o, sum, res, env, vol.sanitized + env.sanitized);

    // 5. Write.
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
    db.emission = (!vol.empty && m.hasEmission()) ? m.emission.data() : nullptr;
    db.scatter = scatter.empty() ? nullptr : scatter.data();
    for (const SunTerm& t : res.sunTerms) db.sunTransmittance.push_back(t.transmittance.data());
    db.layout = vol.empty ? nullptr : &m;
    BakeWriteOptions wo;
    wo.path = o.output;
    wo.inputs = {o.input, o.env};
    wo.half = o.half;
    wo.writeDensity = !o.noDensity;
    wo.densityName = "density";  // the name renderers look for; the source name is in lpm:input_grid
    BakeWriteReport wr = writeBake(*vol.density, db, meta, wo);
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

// `lpmbake IN.vdb ...`: read the density and lights, solve, write the bake (+ stats).
#include <sys/resource.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <sstream>

#include "baker/options.h"
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

std::string fmt(double v) {
    std::ostringstream s;
    s << std::setprecision(6) << v;
    return s.str();
}
std::string fmtRgb(const RGB& c) { return fmt(c.r) + "," + fmt(c.g) + "," + fmt(c.b); }
std::string fmtVec(const Vec3& v) { return fmt(v.x) + "," + fmt(v.y) + "," + fmt(v.z); }
/// One number for cubic voxels, X,Y,Z otherwise.
std::string fmtVoxelSize(const Vec3& v) {
    return fmt(v.x) == fmt(v.y) && fmt(v.y) == fmt(v.z) ? fmt(v.x) : fmtVec(v);
}
std::string fmtDims(const int d[3]) {
    return std::to_string(d[0]) + "x" + std::to_string(d[1]) + "x" + std::to_string(d[2]);
}

long peakRssKiB() {
    struct rusage u {};
    getrusage(RUSAGE_SELF, &u);
    return u.ru_maxrss;  // KiB on Linux
}

std::string jsonEscape(const std::string& s) {
    std::string o;
    for (char c : s) {
        if (c == '"' || c == '\\') o += '\\', o += c;
        else if (c == '\n') o += "\\n";
        else if (static_cast<unsigned char>(c) < 0x20) o += ' ';
        else o += c;
    }
    return o;
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
    if (s.directionsPerFace < 1) throw UsageError("--directions-per-face must be >= 1");
    if (s.raysPerVoxel < 1 || s.raysPerVoxel > 16) throw UsageError("--rays-per-voxel must be in 1..16");
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
              << ", \"coarse\": " << (p.coarse ? "true" : "false") << "}";
        }
    j << "\n  ],\n  \"decisions\": [";
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

BakeSummary runBake(const BakeOptions& o, const Log& log) {
    checkOptions(o);
    const auto tStart = Clock::now();
    ThreadLimit limit(o.threads);
    BakeSummary sum;
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
    EnvInput env;
    if (!o.env.empty()) {
        EnvReadOptions eo;
        eo.path = o.env;
        eo.colorSpace = o.envColorSpace;
        eo.workingSpace = o.workingSpace;
        eo.rotateYDeg = o.envRotateDeg;
        eo.scale = o.envScale;
        eo.sanitize = o.sanitize;
        env = readEnvironment(eo);
        for (const auto& w : env.warnings) log.warn(w);
        log.debug("environment " + o.env + ": " + std::to_string(env.width) + "x" + std::to_string(env.height) +
                  ", " + env.colorSpace + " -> " + env.workingSpace);
    }
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
        res = solveLpm(m, lights, settings);
        for (const auto& d : res.decisions) log.note("solver: " + d);
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

    // 4. Metadata: everything a consumer needs to use the bake without this tool.
    openvdb::MetaMap meta;
    auto str = [&](const std::string& k, const std::string& v) { meta.insertMeta("lpm:" + k, openvdb::StringMetadata(v)); };
    auto dbl = [&](const std::string& k, double v) { meta.insertMeta("lpm:" + k, openvdb::DoubleMetadata(v)); };
    auto i32 = [&](const std::string& k, int v) { meta.insertMeta("lpm:" + k, openvdb::Int32Metadata(v)); };
    auto rgb = [&](const std::string& k, const RGB& c) {
        meta.insertMeta("lpm:" + k, openvdb::Vec3DMetadata(openvdb::Vec3d(c.r, c.g, c.b)));
    };
    i32("format_version", kBakeFormatVersion);
    str("version", std::string("lpmbake ") + LPM_VERSION_STRING);
    i32("sh_order", res.shOrder);
    i32("sh_count", res.coeffs);
    str("sh_basis", "real orthonormal spherical harmonics, ACN index k = l*l + l + m, no Condon-Shortley phase; "
                    "Y0 = 0.282095, Y1 = 0.488603 y, Y2 = 0.488603 z, Y3 = 0.488603 x (solver_notes section 5); "
                    "directions in world space (the grids' transform frame)");
    str("sh_grids", "sh_0 .. sh_" + std::to_string(res.coeffs - 1) + ": Vec3f, RGB in xyz");
    str("sh_negative_lobes", "coefficients are not windowed; evaluating S may give small negative values: clamp "
                             "at zero when shading (lpmbake render does)");
    str("quantity", "S(x,w) = Int p(w,w') L(x,w') dw': phase-weighted in-scattered radiance, w = direction in "
                    "which light travels; does not contain sigma_s");
    str("usage", "renderer adds sigma_s(x)*S(x,-view) per unit length along a camera ray with direction view, "
                 "sigma_s = albedo * density * density_scale; scatter = direction-averaged S for shaders that use "
                 "it as emission (multiply by sigma_s)");
    str("units", "S: radiance in the working colour space (environment pixels * env_scale, sun irradiance per "
                 "steradian); lengths: world units of the grid transform; sigma_t = density * density_scale per "
                 "world unit");
    str("frame", "world");
    str("working_colorspace", env.workingSpace.empty() ? o.workingSpace : env.workingSpace);
    str("density_grid", o.noDensity ? "" : "density");
    dbl("density_scale", o.densityScale);
    rgb("albedo", o.albedo);
    dbl("g", o.g);
    str("phase_function", "Henyey-Greenstein");
    std::string lightsDesc;
    if (!o.env.empty()) {
        str("env_file", o.env);
        str("env_colorspace", env.colorSpace);
        dbl("env_rotate_y_deg", o.envRotateDeg);
        dbl("env_scale", o.envScale);
        str("env_orientation", "lat-long, OpenEXR ImfEnvmap convention, +Y up");
        lightsDesc += "environment '" + o.env + "' (" + env.colorSpace + ", rotate " + fmt(o.envRotateDeg) +
                      " deg, scale " + fmt(o.envScale) + ")";
    }
    i32("sun_count", int(o.suns.size()));
    std::string sunsDesc;
    for (size_t i = 0; i < o.suns.size(); ++i) {
        const auto& s = o.suns[i];
        sunsDesc += (i ? "; " : "") + std::string("toward ") + fmtVec(normalize(s.toSun)) + " irradiance " +
                    fmtRgb(s.irradiance) + " angle " + fmt(s.angleDeg) + " deg";
    }
    if (!o.suns.empty()) {
        str("suns", sunsDesc);
        lightsDesc += std::string(lightsDesc.empty() ? "" : "; ") + "suns: " + sunsDesc;
    }
    if (!o.temperatureGrid.empty()) {
        str("temperature_grid", o.temperatureGrid);
        dbl("temperature_scale", o.temperatureScale);
        dbl("temperature_offset", o.temperatureOffset);
        dbl("temperature_intensity", o.temperatureIntensity);
        str("temperature_convention", "Kelvin = value * temperature_scale + temperature_offset; L_e = "
                                      "temperature_intensity * black body (Planck x CIE 1931), 6500 K -> luminance 1, "
                                      "in the working colour space; written as grid 'emission'");
        lightsDesc += std::string(lightsDesc.empty() ? "" : "; ") + "temperature grid '" + o.temperatureGrid + "'";
    }
    if (!o.emissionGrid.empty()) {
        str("emission_grid", o.emissionGrid);
        dbl("emission_scale", o.emissionScale);
        str("emission_convention", "emitted radiance L_e = value * emission_scale; source term sigma_a * L_e "
                                   "(pbrt-v4); written as grid 'emission'");
        lightsDesc += std::string(lightsDesc.empty() ? "" : "; ") + "emission grid '" + o.emissionGrid + "'";
    }
    str("lights", lightsDesc);
    i32("directions_per_face", o.solver.directionsPerFace);
    i32("rays_per_voxel", o.solver.raysPerVoxel);
    i32("bins_per_face", o.solver.binsPerFace);
    dbl("tolerance", o.solver.tolerance);
    i32("max_orders", o.solver.maxOrders);
    i32("subdivide", o.solver.subdivide);
    str("multires", o.solver.multires < 0 ? "auto" : (o.solver.multires ? "on" : "off"));
    i32("multires_after", o.solver.multiresAfter);
    str("source_shape", o.solver.linearSource < 0 ? "auto" : (o.solver.linearSource ? "linear" : "constant"));
    str("delta_m", o.solver.deltaM < 0 ? "auto" : (o.solver.deltaM ? "on" : "off"));
    dbl("env_hot_share", o.solver.envHotShare);
    dbl("solve_scale", o.solveScale);
    meta.insertMeta("lpm:solve_grid_dims",
                    openvdb::Vec3IMetadata(openvdb::Vec3i(sum.solveDims[0], sum.solveDims[1], sum.solveDims[2])));
    meta.insertMeta("lpm:solve_voxel_size", openvdb::Vec3DMetadata(openvdb::Vec3d(
                                                 sum.solveVoxelSize.x, sum.solveVoxelSize.y, sum.solveVoxelSize.z)));
    meta.insertMeta("lpm:krylov", openvdb::BoolMetadata(o.solver.krylov));
    str("solver", "Light Propagation Maps (discrete ordinates, source iteration with GMRES acceleration); " +
                      std::to_string(res.directionCount) + " directions, " + std::to_string(res.binCount) +
                      " unshot bins");
    i32("passes", sum.passes);
    dbl("residual", res.residual);
    meta.insertMeta("lpm:converged", openvdb::BoolMetadata(res.converged));
    std::string dec;
    for (const auto& d : res.decisions) dec += (dec.empty() ? "" : "; ") + d;
    str("decisions", dec);
    str("input_file", o.input);
    str("input_grid", o.grid);
    i32("input_grid_index", std::max(0, o.gridIndex));
    meta.insertMeta("lpm:empty", openvdb::BoolMetadata(vol.empty));
    meta.insertMeta("lpm:sanitized_values", openvdb::Int64Metadata(openvdb::Int64(vol.sanitized + env.sanitized)));
    str("storage", o.half ? "half" : "float32");
    dbl("time_read_s", sum.secondsRead);
    dbl("time_env_s", sum.secondsEnv);
    dbl("time_solve_s", sum.secondsSolve);
    str("timings", "read " + fmt(sum.secondsRead) + " s, environment " + fmt(sum.secondsEnv) + " s, solve " +
                       fmt(sum.secondsSolve) + " s");
    if (!o.commandLine.empty()) str("command_line", o.commandLine);

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
    if (!o.statsPath.empty()) writeStats(o, sum, vol.empty ? nullptr : &res);
    return sum;
}

}  // namespace lpm

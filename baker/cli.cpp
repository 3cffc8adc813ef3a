// Command line of lpmbake (CLI11): parse into the option structs of options.h, run the
// command, map exceptions to one-line errors and documented exit codes.
#include <unistd.h>

#include <cstdlib>
#include <iostream>
#include <new>
#include <sstream>

#include <openvdb/Exceptions.h>
#include <CLI/CLI.hpp>

#include "baker/frame_pattern.h"
#include "baker/options.h"
#include "baker/quality.h"
#include "baker/sequence.h"
#include "core/sh.h"
#include "vdb_io/io_error.h"

namespace lpm {

void Log::warn(const std::string& m) const {
    if (verbosity >= 1) std::cerr << "lpmbake: warning: " << m << "\n";
}
void Log::note(const std::string& m) const {
    if (verbosity >= 1) std::cerr << "lpmbake: " << m << "\n";
}
void Log::debug(const std::string& m) const {
    if (verbosity >= 2) std::cerr << "lpmbake: " << m << "\n";
}
void Log::error(const std::string& m) const { std::cerr << "lpmbake: error: " << m << "\n"; }

namespace {

std::vector<double> parseNumbers(const std::string& s, const std::string& opt) {
    std::vector<double> v;
    std::stringstream ss(s);
    std::string item;
    while (std::getline(ss, item, ',')) {
        try {
            size_t used = 0;
            v.push_back(std::stod(item, &used));
            if (used != item.size()) throw std::invalid_argument(item);
        } catch (const std::exception&) {
            throw UsageError(opt + " expects numbers separated by commas, got '" + s + "'");
        }
    }
    return v;
}

/// One number; "nan" and "inf" parse (checkOptions then names them as out of range).
double parseNumber(const std::string& s, const std::string& opt) {
    try {
        size_t used = 0;
        const double v = std::stod(s, &used);
        if (used == s.size()) return v;
    } catch (const std::exception&) {
    }
    throw UsageError(opt + " expects a number, got '" + s + "'");
}

Vec3 parseVec3(const std::string& s, const std::string& opt) {
    const auto v = parseNumbers(s, opt);
    if (v.size() != 3) throw UsageError(opt + " expects X,Y,Z, got '" + s + "'");
    return {v[0], v[1], v[2]};
}

RGB parseRgb(const std::string& s, const std::string& opt) {
    const auto v = parseNumbers(s, opt);
    if (v.size() == 1) return RGB(float(v[0]));
    if (v.size() == 3) return RGB(float(v[0]), float(v[1]), float(v[2]));
    throw UsageError(opt + " expects a value or R,G,B, got '" + s + "'");
}

void parseSize(const std::string& s, int& w, int& h) {
    const auto x = s.find_first_of("xX");
    try {
        if (x == std::string::npos) throw std::invalid_argument(s);
        size_t a = 0, b = 0;
        w = std::stoi(s.substr(0, x), &a);
        h = std::stoi(s.substr(x + 1), &b);
        if (a != x || b != s.size() - x - 1) throw std::invalid_argument(s);
    } catch (const std::exception&) {
        throw UsageError("--size expects WxH (e.g. 640x360), got '" + s + "'");
    }
}

/// Threads: --threads wins; else the Slurm allocation; else all cores (0).
int defaultThreads() {
    if (const char* s = std::getenv("SLURM_CPUS_PER_TASK"); s && *s) {
        const int n = std::atoi(s);
        if (n > 0) return n;
    }
    return 0;
}

// One readable line: control bytes become spaces, runs of spaces collapse, and very long
// messages (a corrupt file can make a library quote kilobytes of garbage) are cut.
std::string oneLine(const std::string& in) {
    std::string s;
    s.reserve(in.size());
    for (unsigned char c : in) {
        const char o = (c < 0x20 || c == 0x7f) ? ' ' : char(c);
        if (o == ' ' && !s.empty() && s.back() == ' ') continue;
        s += o;
    }
    constexpr size_t kMax = 400;
    if (s.size() > kMax) s = s.substr(0, kMax) + "... (message cut)";
    return s;
}

bool fileExists(const std::string& path) { return ::access(path.c_str(), F_OK) == 0; }

int fail(int code, const std::string& what) {
    std::cerr << "lpmbake: error: " << oneLine(what) << "\n";
    return code;
}

const char* kDescription = R"(NAME
  lpmbake - bake in-scattered radiance of an OpenVDB volume lit by an environment and suns

SYNOPSIS
  lpmbake IN.vdb [--env SKY.exr] [--sun DX,DY,DZ ...] -o OUT.vdb [options]
  lpmbake render BAKED.vdb [--eye X,Y,Z --target X,Y,Z] --fov-y DEG --size WxH [--env SKY.exr] -o IMAGE.exr|.png
  lpmbake IN.####.vdb --frames 1001-1100 [--skip-existing] [--keep-going] -o OUT.####.vdb [options]
  lpmbake info [--digest] BAKED.vdb

DESCRIPTION
  Reads a float density grid, solves the radiative transfer equation with Light
  Propagation Maps (multiple scattering, Henyey-Greenstein phase function) and writes
  the spherical-harmonic coefficients of the phase-weighted in-scattered radiance
  S(x,w) as Vec3f grids sh_0..sh_N, plus a direction-averaged 'scatter' grid and the
  density, on the input's transform and active voxels. A renderer adds
  sigma_s(x) * S(x,-view) along camera rays. See docs/cli.md and docs/output_format.md.
)";

const char* kFooter = R"(
CONVENTIONS
  Sun: --sun DX,DY,DZ points FROM the scene TOWARD the sun (0,1,0 = overhead), world
  space. Irradiance is measured on a plane facing the sun, in the working colour space.
  Environment: lat-long (width = 2 x height), OpenEXR ImfEnvmap orientation with +Y up:
  the image centre looks toward +Z, a quarter from the left toward +X, the top row is +Y.
  --up-axis z (Blender, Mantaflow) turns it: the top row is +Z, the centre faces -Y.
  Units: sigma_t = density * --density-scale per world unit of the grid transform;
  voxel centres are at integer index coordinates. S is radiance in the working colour
  space (default ACEScg). Emission: --emission-grid values * --emission-scale are the
  emitted radiance L_e; the source term is sigma_a * L_e (pbrt-v4).

EXIT STATUS
  0  success (also for an empty density grid: an empty bake is written, with a warning)
  1  usage error (bad or inconsistent options)
  2  input error (unreadable file, missing grid, bad values, not a valid bake for info)
  3  output error (cannot write, or the output path is an input file)
  4  internal error (out of memory, unexpected failure)
  5  some frames of a sequence of several failed (they are listed at the end; a
     one-frame run exits with that frame's code instead)
  6  the bake was written, but --max-error failed: its --verify error estimate is
     above E with 95% confidence (the file is marked lpm:verify_failed)
  Errors are printed as one line: lpmbake: error: <component>: <message>

ENVIRONMENT
  OCIO                 OpenColorIO config to use instead of the shipped config.ocio
  SLURM_CPUS_PER_TASK  default for --threads
  LPMBAKE_IMAGE_HELPER the image reader/writer lpmbake runs (default: lpmbake-image
                       beside lpmbake or in ../libexec/lpmbake)
  LPMBAKE_IMAGE_CACHE  where decoded --env images are kept for the next process
                       (default $XDG_CACHE_HOME/lpmbake/images or ~/.cache/lpmbake/images;
                       off: none); LPMBAKE_IMAGE_CACHE_MIB caps it (default 2048)

OUTPUT
  The output appears atomically: it is written to .NAME.lpmtmp-PID.EXT in the output
  directory and renamed when complete. The input is never overwritten.

SEQUENCES
  Frame patterns in IN, -o, --env and --stats: #### (4 digits, zero-padded), @@@ (one
  digit per @), %04d, $F4 (Houdini; quote it). --frames takes 1001-1100, 1-50x2
  (step) and lists 1,5,9-12; --frame N is one frame. Each frame is written
  atomically; --skip-existing keeps outputs that are valid bakes of the same settings
  (lpm:settings_digest), newer than their inputs. See docs/farm.md.

EXAMPLES
  lpmbake cloud.vdb --env sky.exr --sun 0.3,0.8,0.5 --sun-irradiance 5 -o cloud_lit.vdb
  lpmbake torus.vdb --grid voxel_fog_density --env sky.hdr --g 0.6 --sh-order 2 -o out.vdb
  lpmbake torus.vdb --grid voxel_fog_density --env sky.hdr --solve-scale 0.5 -o preview.vdb
  lpmbake render out.vdb --eye 0,0,8 --target 0,0,0 --fov-y 40 --size 512x512 -o out.png
  lpmbake 'smoke.$F4.vdb' --frames 1001-1240 --env sky.exr --skip-existing -o 'lit.$F4.vdb'
  lpmbake info out.vdb)";

/// Everything the command line sets: the option structs and the raw text converted after
/// parsing (CLI11 would refuse "nan" without naming the range; the settings' validate()
/// names the value and the range).
struct Args {
    BakeOptions b;
    SequenceOptions seq;
    RenderOptions r;
    InfoOptions in;
    int verbose = 0;
    bool quiet = false;
    std::string albedo = "0.9";
    std::vector<std::string> suns, sunIrr;
    std::vector<double> sunAngle;
    bool noKrylov = false;
    std::string sourceShape = "auto", deltaM = "auto", multires = "auto", separable = "auto", sunTerm = "auto",
                tail = "auto";
    std::string upAxis = "y";
    std::string compression = "none";
    std::string solveScale = "1";
    std::string maxError;  ///< empty: not given
    std::string frames;
    int oneFrame = 0;
    std::string eye, target, up, size = "256x256";
    CLI::Option *framesOpt = nullptr, *frameOpt = nullptr;
    CLI::App *render = nullptr, *info = nullptr;
    CLI::App* app = nullptr;
    std::string quality = "default";
};

void addInputOptions(CLI::App& app, Args& a) {
    app.add_option("input", a.b.input, "input OpenVDB file (positional)");
    app.add_option("-o,--output", a.b.output, "output VDB (written atomically; never the input)");
    auto* gIn = "Input volume";
    app.add_option("--grid", a.b.grid, "name of the float density grid")->default_val("density")->group(gIn);
    app.add_option("--grid-index", a.b.gridIndex,
                   "which of several grids with that name (0-based; default 0 with a warning)")
        ->group(gIn);
    app.add_flag("--convert-level-set", a.b.convertLevelSet,
                 "accept a level set by converting it with openvdb::tools::sdfToFogVolume")
        ->group(gIn);
    app.add_flag("--sanitize", a.b.sanitize,
                 "clamp NaN/Inf/negative densities and NaN/Inf environment pixels to 0 (default: error)")
        ->group(gIn);
    app.add_option("--density-scale", a.b.densityScale, "sigma_t = density * this, per world unit")
        ->default_val(1.0)
        ->group(gIn);
    app.add_option("--albedo", a.albedo, "single-scattering albedo sigma_s/sigma_t: A or R,G,B in [0,1]")
        ->default_val("0.9")
        ->group(gIn);
    app.add_option("--g", a.b.g, "Henyey-Greenstein asymmetry in (-1,1); 0 = isotropic (SH order forced to 0)")
        ->default_val(0.0)
        ->group(gIn);
    app.add_option("--emission-grid", a.b.emissionGrid, "float or Vec3f grid of emitted radiance L_e")->group(gIn);
    app.add_option("--emission-scale", a.b.emissionScale, "L_e = emission value * this")->default_val(1.0)->group(gIn);
    app.add_option("--temperature-grid", a.b.temperatureGrid,
                   "float grid of temperature: black-body emission (Kelvin = value * scale + offset)")
        ->group(gIn);
    app.add_option("--temperature-scale", a.b.temperatureScale, "Kelvin per grid unit (e.g. 1000 for caches in kK)")
        ->default_val(1.0)
        ->group(gIn);
    app.add_option("--temperature-offset", a.b.temperatureOffset, "Kelvin added after scaling")
        ->default_val(0.0)
        ->group(gIn);
    app.add_option("--temperature-intensity", a.b.temperatureIntensity,
                   "L_e = this * black body(K), normalised so 6500 K has luminance 1")
        ->default_val(1.0)
        ->group(gIn);
    app.add_option("--max-voxels", a.b.maxVoxels, "refuse dense blocks larger than this (memory guard)")
        ->default_val(a.b.maxVoxels)
        ->group(gIn);
}

void addLightOptions(CLI::App& app, Args& a) {
    auto* gL = "Lights";
    app.add_option("--env", a.b.env,
                   "lat-long environment image (EXR, HDR, ... ; width = 2 x height, at most 32768x16384)")
        ->group(gL);
    app.add_option("--env-colorspace", a.b.envColorSpace,
                   "colour space of --env (default: the file's, if the OCIO config knows it, else lin_rec709)")
        ->group(gL);
    app.add_option("--working-space", a.b.workingSpace, "colour space of the bake")->default_val("ACEScg")->group(gL);
    app.add_option("--up-axis", a.upAxis,
                   "the scene's up axis: y (default; Houdini, Maya) or z (Blender, Mantaflow): the environment's "
                   "zenith lies along it")
        ->check(CLI::IsMember({"y", "z"}))
        ->default_val("y")
        ->group(gL);
    app.add_option("--env-rotate", a.b.envRotateDeg, "rotate the environment about the up axis (degrees, right-handed)")
        ->default_val(0.0)
        ->group(gL);
    app.add_option("--env-scale", a.b.envScale, "multiply environment radiance")->default_val(1.0)->group(gL);
    app.add_option("--sun", a.suns, "direction TOWARD a sun, DX,DY,DZ (repeatable)")->group(gL);
    app.add_option("--sun-irradiance", a.sunIrr,
                   "sun irradiance E or R,G,B: once for all suns or once per --sun (default 1)")
        ->group(gL);
    app.add_option("--sun-angle", a.sunAngle, "sun angular diameter in degrees: once or once per --sun (default 0.53)")
        ->group(gL);
}

void addSolverOptions(CLI::App& app, Args& a) {
    auto* gS = "Solver";
    std::string qualityHelp = "solver knobs measured to a target error (docs/accuracy.md); explicit knobs override:";
    for (const QualityPreset& p : qualityPresets()) qualityHelp += "\n  " + p.name + ": " + p.purpose;
    app.add_option("--quality", a.quality, qualityHelp)
        ->default_val("default")
        ->check(CLI::IsMember({"preview", "default", "production"}))
        ->group(gS);
    app.add_option("--directions-per-face", a.b.solver.directionsPerFace,
                   "n: n x n propagation directions per cube face (1.." + std::to_string(kMaxDirectionsPerFace) + ")")
        ->default_val(a.b.solver.directionsPerFace)
        ->group(gS);
    app.add_option("--rays-per-voxel", a.b.solver.raysPerVoxel,
                   "ray-map rays per voxel per lateral axis (1.." + std::to_string(kMaxRaysPerVoxel) + ")")
        ->default_val(a.b.solver.raysPerVoxel)
        ->group(gS);
    app.add_option("--rays-higher-orders", a.b.solver.raysHigherOrders,
                   "rays per voxel of the multiple-scattering passes: -1 auto (1 when the two-grid solve runs, "
                   "else --rays-per-voxel), or 1..16")
        ->default_val(a.b.solver.raysHigherOrders)
        ->group(gS);
    app.add_option("--bins-per-face", a.b.solver.binsPerFace, "unshot bins: -1 auto, 0 isotropic, b = b x b per face")
        ->default_val(a.b.solver.binsPerFace)
        ->group(gS);
    app.add_option("--sh-order", a.b.solver.shOrder, "SH order of the result, 0.." + std::to_string(kMaxShOrder))
        ->default_val(a.b.solver.shOrder)
        ->group(gS);
    app.add_option("--tolerance", a.b.solver.tolerance,
                   "stop when the scattered power still to come is below this share of the input (the power the "
                   "medium takes from the lights plus what it emits)")
        ->default_val(a.b.solver.tolerance)
        ->group(gS);
    app.add_option("--max-orders", a.b.solver.maxOrders, "at most this many scattering orders")
        ->default_val(a.b.solver.maxOrders)
        ->group(gS);
    app.add_option("--subdivide", a.b.solver.subdivide,
                   "solve on voxels split k x k x k and average back (1..8): for optically thick voxels")
        ->default_val(a.b.solver.subdivide)
        ->group(gS);
    app.add_option("--multires", a.multires,
                   "solve the higher scattering orders on a 2x coarser grid: auto (when the block stores more "
                   "than 32768 voxels), on, off (docs/multires.md)")
        ->default_val("auto")
        ->check(CLI::IsMember({"auto", "on", "off"}))
        ->group(gS);
    app.add_option("--multires-after", a.b.solver.multiresAfter,
                   "scattering passes at full resolution before the coarse grid takes over")
        ->default_val(a.b.solver.multiresAfter)
        ->check(CLI::Range(1, 1000))
        ->group(gS);
    app.add_option("--separable-sources", a.separable,
                   "two-grid solve with unshot bins: the fine passes keep each voxel's angular integral and take "
                   "the angular shape from the coarse grid (about 1/4 of the memory); auto (on), on, off")
        ->default_val("auto")
        ->check(CLI::IsMember({"auto", "on", "off"}))
        ->group(gS);
    app.add_option(
           "--two-grid-tail", a.tail,
           "how the two-grid cycle brings its coarse tail back into each coarse voxel: auto (diffusion where the "
           "albedo is at least 0.97 and voxels reach optical depth 2 or the medium is 60 across, else shaped where a "
           "coarse voxel may be "
           "optically thicker than 1, else flat), shaped (by the first residual its children hold: closer to full "
           "resolution voxel by voxel, 1.5-2.2x the time where coarse voxels are thicker than 1), flat, diffusion "
           "(from a diffusion solve on the fine grid, no coarse grid: thick media at albedo near 1; one unshot bin or "
           "separable sources)")
        ->default_val("auto")
        ->check(CLI::IsMember({"auto", "shaped", "flat", "diffusion"}))
        ->group(gS);
    app.add_option("--source", a.sourceShape,
                   "source inside a voxel: auto (linear when a voxel is thicker than optical depth 2, or at albedo "
                   "0.97 and above with g = 0 where the voxels' depth times the medium's size in diffusion lengths "
                   "reaches 12; at g != 0 only while its per-bin sources fit 300 B a voxel + 200 MiB), constant, "
                   "linear (linear characteristics: leaks far less light through thick voxels; 3-5x the time)")
        ->default_val("auto")
        ->check(CLI::IsMember({"auto", "constant", "linear"}))
        ->group(gS);
    app.add_option("--delta-m", a.deltaM,
                   "forward-peak truncation (delta-M): auto and on apply it for g > 0 with a grey albedo; off "
                   "propagates the phase function unscaled")
        ->default_val("auto")
        ->check(CLI::IsMember({"auto", "on", "off"}))
        ->group(gS);
    app.add_option("--env-hot-share", a.b.solver.envHotShare,
                   "environment pixels holding at least this share of its power (a sun in an HDRI; at most 16) "
                   "are swept like suns in their exact direction; 0 = off")
        ->default_val(a.b.solver.envHotShare)
        ->check(CLI::Range(0.0, 1.0))
        ->group(gS);
    app.add_option("--sun-term", a.sunTerm,
                   "exact sun term: auto (when g != 0), on, off: each sun's single scattering is kept out of the SH "
                   "and stored as a transmittance grid a renderer evaluates with the exact phase function "
                   "(docs/sun_term.md)")
        ->default_val("auto")
        ->check(CLI::IsMember({"auto", "on", "off"}))
        ->group(gS);
    app.add_flag("--no-krylov", a.noKrylov, "never switch to GMRES acceleration (plain source iteration)")->group(gS);
    app.add_option(
           "--krylov-restart", a.b.solver.krylovRestart,
           "GMRES restarts after this many Krylov vectors (4 at least; each the unshot source in half precision): "
           "fewer hold less memory and may need more passes; the plan caps them under the memory line (4 at least)")
        ->default_val(a.b.solver.krylovRestart)
        ->group(gS);
    // Read as text and converted here: CLI11 would refuse "nan" without naming the allowed
    // range; checkOptions names the value and the range.
    app.add_option("--solve-scale", a.solveScale,
                   "S: solve on a grid with the input's axes and voxel size / S, S in [0.05, 8] (0.5: half the "
                   "resolution, 2: twice; 1: the input's voxels); results are interpolated back onto the "
                   "input's voxels")
        ->default_val("1")
        ->type_name("FLOAT")
        ->group(gS);
}

void addVerifyOptions(CLI::App& app, Args& a) {
    auto* gV = "Self-check (docs/verify.md)";
    app.add_option("--verify", a.b.verifyProbes,
                   "N Monte Carlo probes after the bake, at voxels drawn by what a renderer sees of them: the "
                   "bake's estimated relative error with a 95% interval (stderr, stats, lpm:verify_*); 64 is "
                   "a good start")
        ->type_name("N")
        ->group(gV);
    app.add_option("--verify-paths", a.b.verifyPaths, "Monte Carlo paths per probe")->default_val(4096)->group(gV);
    app.add_option("--verify-seed", a.b.verifySeed, "seed of the probes (other voxels and paths)")
        ->default_val(a.b.verifySeed)
        ->group(gV);
    app.add_option("--max-error", a.maxError,
                   "E: exit " + std::to_string(kExitVerify) +
                       " when the error is above E with 95% confidence (the interval's low end > E); the bake "
                       "is written and marked lpm:verify_failed; implies --verify 64")
        ->type_name("E")
        ->group(gV);
}

void addSequenceAndOutputOptions(CLI::App& app, Args& a) {
    auto* gF = "Sequences (docs/farm.md)";
    a.framesOpt = app.add_option("--frames", a.frames,
                                 "frames to bake: 1001-1100, 1-50x2, 1,5,9-12; paths hold "
                                 "#### @ %04d or $F4")
                      ->group(gF);
    a.frameOpt = app.add_option("--frame", a.oneFrame, "one frame (as --frames N)")->group(gF);
    a.framesOpt->excludes(a.frameOpt);
    app.add_flag("--skip-existing", a.seq.skipExisting,
                 "keep outputs that are complete bakes of the same settings, newer than their inputs")
        ->group(gF);
    app.add_flag("--keep-going", a.seq.keepGoing, "bake the remaining frames after one fails (exit 5 at the end)")
        ->group(gF);
    app.add_option("--frame-log", a.seq.frameLog, "one JSON line per frame: FILE (may hold a pattern) or - (stdout)")
        ->group(gF);
    app.add_flag("--list-pending", a.seq.listPending,
                 "print the frames whose output is missing, invalid, stale or of other settings (as 2,5-7); bake "
                 "nothing")
        ->group(gF);

    auto* gO = "Output and run";
    app.add_flag("--half", a.b.half, "store 16-bit floats (warns when values exceed 65504)")->group(gO);
    app.add_option(
           "--compression", a.compression,
           "none or zip: zip makes the file up to 11% smaller and its write 4-6x slower (the lighting grids are "
           "noisy floats; docs/output_format.md)")
        ->default_val("none")
        ->check(CLI::IsMember({"none", "zip"}))
        ->group(gO);
    app.add_flag("--no-density", a.b.noDensity, "do not copy the density grid into the output")->group(gO);
    app.add_flag("--renderer-grids", a.b.rendererGrids,
                 "also write extinction (sigma_t, float) and source (sigma_s * scatter + sigma_a * L_e, Vec3f): "
                 "grids a shader uses without any number from the metadata")
        ->group(gO);
    app.add_option("--stats", a.b.statsPath, "write timings, voxel counts, passes, memory as JSON")->group(gO);
    app.add_option("--sidecar", a.b.sidecarPath,
                   "also write the bake's lpm:* metadata and grid names as JSON (for tools that cannot read VDB "
                   "metadata, e.g. Blender)")
        ->group(gO);
    app.add_option("--threads", a.b.threads, "worker threads (default: $SLURM_CPUS_PER_TASK, else all cores)")
        ->group(gO);
    app.add_flag("-v,--verbose", a.verbose, "more messages (per-pass progress)")->group(gO);
    app.add_flag("-q,--quiet", a.quiet, "errors only")->group(gO);
}

void addRenderAndInfoCommands(CLI::App& app, Args& a) {
    a.r.threads = defaultThreads();
    a.render = app.add_subcommand("render", "ray-march a preview image of a bake (EXR scene-linear, PNG sRGB)");
    a.render->add_option("bake", a.r.bake, "baked VDB")->required();
    a.render->add_option("--eye", a.eye, "camera position X,Y,Z (default: framing the volume from +Z, a little above)");
    a.render->add_option("--target", a.target, "point looked at X,Y,Z (default: the centre of the volume)");
    a.render->add_option("--up", a.up, "camera up vector X,Y,Z (default: the bake's up axis, lpm:up_axis)");
    a.render->add_option("--fov-y", a.r.fovYDeg, "vertical field of view in degrees")->default_val(40.0);
    a.render->add_option("--size", a.size, "image size WxH")->default_val("256x256");
    a.render->add_option("--env", a.r.env, "environment drawn behind the volume (rotation/scale from the bake)");
    a.render->add_option("--env-colorspace", a.r.envColorSpace, "colour space of --env");
    a.render->add_option("--step", a.r.stepVoxels, "ray-march step in voxels")->default_val(0.5);
    a.render->add_option("-o,--output", a.r.output, "IMAGE.exr (scene-linear) or IMAGE.png (sRGB view)")->required();
    a.render->add_option("--threads", a.r.threads, "worker threads");
    a.render->add_flag("-v,--verbose", a.verbose, "more messages");
    a.render->add_flag("-q,--quiet", a.quiet, "errors only");

    a.info = app.add_subcommand("info", "describe a bake; exit 2 if it is not a valid one");
    a.info->add_option("bake", a.in.bake, "baked VDB")->required();
    a.info->add_flag("--digest", a.in.digest,
                     "print only the digest of the bake's content (grids and settings, not timings): equal digests, "
                     "equal bakes");
    a.info->add_flag("-q,--quiet", a.quiet, "errors only");
}

/// The suns of --sun, --sun-irradiance and --sun-angle (given once, or once per sun).
std::vector<SunOption> parseSuns(const Args& a) {
    const size_t n = a.suns.size();
    if (!a.sunIrr.empty() && a.sunIrr.size() != 1 && a.sunIrr.size() != n)
        throw UsageError("--sun-irradiance given " + std::to_string(a.sunIrr.size()) + " times for " +
                         std::to_string(n) + " --sun: give it once or once per sun");
    if (!a.sunAngle.empty() && a.sunAngle.size() != 1 && a.sunAngle.size() != n)
        throw UsageError("--sun-angle given " + std::to_string(a.sunAngle.size()) + " times for " + std::to_string(n) +
                         " --sun: give it once or once per sun");
    if (n == 0 && (!a.sunIrr.empty() || !a.sunAngle.empty()))
        throw UsageError("--sun-irradiance/--sun-angle without --sun");
    std::vector<SunOption> out;
    for (size_t i = 0; i < n; ++i) {
        SunOption s;
        s.toSun = parseVec3(a.suns[i], "--sun");
        if (!a.sunIrr.empty()) s.irradiance = parseRgb(a.sunIrr[a.sunIrr.size() == 1 ? 0 : i], "--sun-irradiance");
        if (!a.sunAngle.empty()) s.angleDeg = a.sunAngle[a.sunAngle.size() == 1 ? 0 : i];
        out.push_back(s);
    }
    return out;
}

int runRenderCommand(Args& a, const Log& log) {
    RenderOptions& r = a.r;
    r.autoEye = a.eye.empty();
    r.autoTarget = a.target.empty();
    r.autoUp = a.up.empty();
    if (!r.autoEye) r.eye = parseVec3(a.eye, "--eye");
    if (!r.autoTarget) r.target = parseVec3(a.target, "--target");
    if (!r.autoUp) r.up = parseVec3(a.up, "--up");
    parseSize(a.size, r.width, r.height);
    runRender(r, log);
    return kExitOk;
}

int runBakeCommand(Args& a, int argc, char** argv, const Log& log) {
    BakeOptions& b = a.b;
    if (b.input.empty()) throw UsageError("no input VDB given (lpmbake IN.vdb --env SKY.exr -o OUT.vdb)");
    if (a.noKrylov) b.solver.krylov = false;
    b.upAxis = a.upAxis == "z" ? UpAxis::Z : UpAxis::Y;
    b.zip = a.compression == "zip";
    b.solver.linearSource = a.sourceShape == "linear" ? 1 : (a.sourceShape == "constant" ? 0 : -1);
    b.solver.deltaM = a.deltaM == "on" ? 1 : (a.deltaM == "off" ? 0 : -1);
    b.solver.multires = a.multires == "on" ? 1 : (a.multires == "off" ? 0 : -1);
    b.solver.separableSource = a.separable == "on" ? 1 : (a.separable == "off" ? 0 : -1);
    b.solver.shapedCoarseTail = a.tail == "shaped" ? 1 : (a.tail == "flat" ? 0 : -1);
    b.solver.diffusionTail = a.tail == "diffusion" ? 1 : (a.tail == "auto" ? -1 : 0);
    b.sunTerm = a.sunTerm == "on" ? 1 : (a.sunTerm == "off" ? 0 : -1);
    std::vector<std::string> explicitKnobs;
    for (const std::string& flag : qualityFlags())
        if (a.app->count(flag) > 0) explicitKnobs.push_back(flag);
    applyQuality(a.quality, b.solver, explicitKnobs);
    b.quality = a.quality;
    b.albedo = parseRgb(a.albedo, "--albedo");
    b.solveScale = parseNumber(a.solveScale, "--solve-scale");
    if (!a.maxError.empty()) {
        b.maxError = parseNumber(a.maxError, "--max-error");
        if (!(b.maxError > 0)) throw UsageError("--max-error must be positive (0.02 = 2%), got " + a.maxError);
    }
    b.suns = parseSuns(a);
    for (int i = 0; i < argc; ++i) b.commandLine += (i ? " " : "") + std::string(argv[i]);
    if (!a.frames.empty() || *a.frameOpt) {
        a.seq.bake = b;
        a.seq.frames = *a.frameOpt ? std::vector<int>{a.oneFrame} : parseFrameList(a.frames);
        return runSequence(a.seq, log, std::cout);
    }
    if (a.seq.skipExisting || a.seq.keepGoing || a.seq.listPending || !a.seq.frameLog.empty())
        throw UsageError("--skip-existing, --keep-going, --frame-log and --list-pending need --frames or --frame");
    if (hasFramePattern(b.input) && !fileExists(b.input))
        throw UsageError("input '" + b.input + "' has a frame pattern: give --frames A-B or --frame N");
    return runBake(b, log).verifyFailed ? kExitVerify : kExitOk;
}

/// Runs the parsed command; every failure becomes one line and its exit code.
int runCommand(Args& a, int argc, char** argv) {
    Log log;
    log.verbosity = a.quiet ? 0 : 1 + a.verbose;
    try {
        if (*a.render) return runRenderCommand(a, log);
        if (*a.info) return runInfo(a.in, std::cout, log);
        return runBakeCommand(a, argc, argv, log);
    } catch (const UsageError& e) {
        return fail(kExitUsage, std::string(e.what()) + " (see lpmbake --help)");
    } catch (const InputError& e) {
        return fail(kExitInput, e.what());
    } catch (const OutputError& e) {
        return fail(kExitOutput, e.what());
    } catch (const Error& e) {
        // Core validation (Medium, LPM, EnvMap) rejects values that came from the input.
        return fail(kExitInput, e.what());
    } catch (const std::bad_alloc&) {
        return fail(kExitInternal, "internal: out of memory (try a smaller volume or --max-voxels)");
    } catch (const std::exception& e) {
        return fail(kExitInternal, std::string("internal: ") + e.what());
    } catch (...) {
        return fail(kExitInternal, "internal: unknown exception");
    }
}

}  // namespace

int runCli(int argc, char** argv) {
    CLI::App app{kDescription, "lpmbake"};
    app.get_formatter()->column_width(34);
    app.footer(kFooter);
    app.set_version_flag("--version", std::string("lpmbake ") + LPM_VERSION_STRING);
    app.require_subcommand(0, 1);
    Args a;
    a.app = &app;
    a.b.threads = defaultThreads();
    addInputOptions(app, a);
    addLightOptions(app, a);
    addSolverOptions(app, a);
    addVerifyOptions(app, a);
    addSequenceAndOutputOptions(app, a);
    addRenderAndInfoCommands(app, a);
    try {
        app.parse(argc, argv);
    } catch (const CLI::CallForHelp& e) {
        return app.exit(e);
    } catch (const CLI::CallForAllHelp& e) {
        return app.exit(e);
    } catch (const CLI::CallForVersion& e) {
        return app.exit(e);
    } catch (const CLI::ParseError& e) {
        return fail(kExitUsage, std::string("usage: ") + e.what() + " (see lpmbake --help)");
    }
    return runCommand(a, argc, argv);
}

}  // namespace lpm

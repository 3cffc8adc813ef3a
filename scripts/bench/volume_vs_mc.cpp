// A real-size volume (a VDB file, e.g. from lpm_make_volume or a Mantaflow cache) baked with
// several solver settings, each timed and compared with the Monte Carlo reference at voxels
// sampled uniformly among those with density (the same MC estimates for every setting).
// Prints a markdown table (docs/performance.md).
//   lpm_bench_volume IN.vdb [--env SKY] [--sun DX,DY,DZ] [--albedo A] [--g G] [--density-scale S]
//                    [--up-axis y|z (the sky's, as lpmbake's)] [--samples N] [--voxels K]
//                    [--threads T] [--settings default,full,...]
// Settings: default (what the planner picks), full (every order at full resolution),
// two-grid (multi-resolution forced on),
// after2 (two full-resolution passes before the coarse grid), coarse-n4 (the coarse grid
// keeps the fine directions), r2-higher (2 rays per voxel in every pass, the default before
// raysHigherOrders), r1-all (1 ray per voxel in every pass, single scattering too), k8
// (GMRES when plain iteration would need more than 8 more passes), previous (the default
// before raysHigherOrders and the coarse grid's earlier GMRES), full-sources (the two-grid
// solve's fine sources held in full, bins per voxel, not separably), full-tail (the coarse
// solve iterated to its tolerance, no geometric tail), constant / linear (the source inside
// a voxel, instead of the planner's choice), tight (a tenth of the default stop tolerance),
// coarse-tail / diffusion-tail (the two-grid cycle's tail from the coarse grid, or from a
// diffusion solve, instead of the planner's choice).
#include <sys/resource.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <sstream>

#include "core/malloc_policy.h"
#include "core/parallel.h"
#include "tests/core/lpm_vs_mc.h"
#include "vdb_io/env_reader.h"
#include "vdb_io/volume_reader.h"

using namespace lpm;
using namespace lpm::test;

namespace {

double peakRssMiB() {
    rusage u{};
    getrusage(RUSAGE_SELF, &u);
    return u.ru_maxrss / 1024.0;
}

std::vector<std::string> split(const std::string& s) {
    std::vector<std::string> out;
    std::stringstream ss(s);
    std::string item;
    while (std::getline(ss, item, ',')) out.push_back(item);
    return out;
}

LpmSettings settingsNamed(const std::string& name) {
    LpmSettings s;
    if (name == "full") s.multires = 0;
    else if (name == "two-grid") s.multires = 1;
    else if (name == "after2") s.multiresAfter = 2;
    else if (name == "coarse-n4") s.multiresDirections = 4;
    else if (name == "r2-higher") s.raysHigherOrders = 2;  // the default before raysHigherOrders
    else if (name == "r1-all") s.raysPerVoxel = 1;
    else if (name == "k8") s.krylovAfter = 8;
    else if (name == "previous") s.raysHigherOrders = 2, s.coarseKrylovAfter = 25;  // session 6's default
    else if (name == "full-sources") s.separableSource = 0;
    else if (name == "full-tail") s.coarseTailExtrapolation = false;
    else if (name == "constant") s.linearSource = 0;  // the voxel-constant (step) source everywhere
    else if (name == "linear") s.linearSource = 1;
    else if (name == "tight") s.tolerance = 1e-4;         // a tenth of the default stop tolerance
    else if (name == "coarse-tail") s.diffusionTail = 0;  // the two-grid cycle's tail from the coarse grid
    else if (name == "diffusion-tail") s.diffusionTail = 1;
    else if (name != "default") {
        std::fprintf(stderr, "unknown setting '%s'\n", name.c_str());
        std::exit(2);
    }
    return s;
}

int usage() {
    std::fprintf(stderr,
                 "usage: lpm_bench_volume IN.vdb [--env SKY] [--sun X,Y,Z] [--albedo A] [--g G] "
                 "[--density-scale S] [--up-axis y|z] [--samples N] [--voxels K] [--threads T] [--settings a,b]\n");
    return 2;
}

int run(int argc, char** argv) {
    std::string env, sun, list = "full,default", upAxis = "y";
    double albedo = 0.9, g = 0.0, densityScale = 1.0;
    int samples = 20000, voxels = 48, threads = 0;
    for (int i = 2; i + 1 < argc; i += 2) {
        const std::string k = argv[i], v = argv[i + 1];
        if (k == "--env") env = v;
        else if (k == "--sun") sun = v;
        else if (k == "--albedo") albedo = std::atof(v.c_str());
        else if (k == "--g") g = std::atof(v.c_str());
        else if (k == "--density-scale") densityScale = std::atof(v.c_str());
        else if (k == "--samples") samples = std::atoi(v.c_str());
        else if (k == "--voxels") voxels = std::atoi(v.c_str());
        else if (k == "--threads") threads = std::atoi(v.c_str());
        else if (k == "--settings") list = v;
        else if (k == "--up-axis" && (v == "y" || v == "z")) upAxis = v;
        else return usage();
    }
    ThreadLimit limit(threads);
    initOpenVdb();
    VolumeReadOptions ro;
    ro.path = argv[1];
    ro.densityScale = densityScale;
    VolumeInput vol = readVolume(ro);
    Medium& m = vol.medium;
    m.albedo = RGB(float(albedo));
    m.g = g;
    EnvInput envIn;
    Lights lights;
    if (!env.empty()) {
        EnvReadOptions eo;
        eo.path = env;
        eo.up = upAxis == "z" ? UpAxis::Z : UpAxis::Y;
        envIn = readEnvironment(eo);
        lights.env = envIn.env.get();
    }
    if (!sun.empty()) {
        Vec3 d;
        if (std::sscanf(sun.c_str(), "%lf,%lf,%lf", &d.x, &d.y, &d.z) != 3) return 2;
        lights.suns.push_back({normalize(d), RGB(3.0f), 0.53});
    }
    std::printf("%s: %llu active voxels, block %dx%dx%d, %zu stored voxels; albedo %g, g %g, %d threads\n\n", argv[1],
                (unsigned long long)vol.activeVoxels, m.nx, m.ny, m.nz, m.voxelCount(), albedo, g, maxThreads());
    std::vector<McVoxelEstimate> mc;
    const double tMc = secondsOf([&] { mc = mcVoxelSH(m, lights, sampleVoxels(m, voxels), samples, 2); });
    std::printf("MC reference: %d voxels x %d paths, %.1f s\n\n", voxels, samples, tMc);
    std::printf("| setting | passes (coarse) | seconds | segments/s | band-0 RMS | MC noise | bias | peak RSS MiB |\n");
    std::printf("|---|---|---|---|---|---|---|---|\n");
    for (const std::string& name : split(list)) {
        const LpmSettings s = settingsNamed(name);
        LpmResult r;
        const double t = secondsOf([&] { r = solveLpm(m, lights, s); });
        int coarse = 0;
        for (const PassStats& p : r.passes) coarse += p.coarse ? 1 : 0;
        const Comparison e = compare(r, mc);
        std::printf("| %s | %zu (%d) | %.2f | %.3g | %.4f | %.4f | %+.4f | %.0f |\n", name.c_str(), r.passes.size(),
                    coarse, t, r.segments / t, e.band0Rms, e.band0Noise, e.band0Bias, peakRssMiB());
        std::fflush(stdout);
    }
    return 0;
}

}  // namespace

int main(int argc, char** argv) {
    keepFreedBuffersForReuse();  // as lpmbake does
    if (argc < 2 || argv[1][0] == '-') return usage();
    try {
        return run(argc, argv);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "lpm_bench_volume: %s\n", e.what());
        return 1;
    }
}

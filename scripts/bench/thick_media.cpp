// Optically thick media, albedo near 1: LPM against the Monte Carlo reference on the
// heterogeneous cloud of largest line optical depth 50 (sky + sun, g = 0.5), at several
// grid resolutions and albedos, for the step (voxel-constant) and linear source schemes.
// The MC reference is computed once per scene and shared by every LPM setting.
// Prints a markdown table (the one in docs/accuracy.md).
//   lpm_bench_thick [--quick] [--threads N] [--samples S] [--n N] [--albedo A] [--plain] [--explore]
#include <cstdio>
#include <cstring>

#include "core/parallel.h"
#include "tests/core/lpm_vs_mc.h"

using namespace lpm;
using namespace lpm::test;

int main(int argc, char** argv) {
    bool quick = false, explore = false, plain = false;
    int threads = 0, samples = 40000, onlyN = 0;
    double onlyAlbedo = 0;
    for (int i = 1; i < argc; ++i) {
        if (!std::strcmp(argv[i], "--quick")) quick = true;
        if (!std::strcmp(argv[i], "--explore")) explore = true;
        if (!std::strcmp(argv[i], "--plain")) plain = true;
        if (!std::strcmp(argv[i], "--threads") && i + 1 < argc) threads = std::atoi(argv[++i]);
        if (!std::strcmp(argv[i], "--samples") && i + 1 < argc) samples = std::atoi(argv[++i]);
        if (!std::strcmp(argv[i], "--n") && i + 1 < argc) onlyN = std::atoi(argv[++i]);
        if (!std::strcmp(argv[i], "--albedo") && i + 1 < argc) onlyAlbedo = std::atof(argv[++i]);
    }
    ThreadLimit limit(threads);
    std::vector<int> sizes = quick ? std::vector<int>{16} : std::vector<int>{8, 16, 32};
    std::vector<double> albedos = quick ? std::vector<double>{0.99} : std::vector<double>{0.9, 0.99, 0.999};
    if (onlyN) sizes = {onlyN};
    if (onlyAlbedo > 0) albedos = {onlyAlbedo};
    struct Setting {
        std::string name;
        LpmSettings s;
    };
    std::vector<Setting> settings;
    {
        LpmSettings step;
        step.linearSource = 0;
        settings.push_back({"step source", step});
        LpmSettings lin;
        lin.linearSource = 1;
        settings.push_back({"linear source", lin});
        lin.subdivide = 2;
        settings.push_back({"linear source, subdivide 2", lin});
        if (plain) {
            // The un-accelerated figures: plain source iteration (no GMRES).
            LpmSettings p;
            p.linearSource = 1;
            p.krylov = false;
            p.maxOrders = 20000;
            settings.push_back({"linear source, no GMRES", p});
        }
        if (explore) {
            auto add = [&](const std::string& name, auto&& mod) {
                LpmSettings x = step;
                mod(x);
                settings.push_back({name, x});
            };
            add("step n=6", [](LpmSettings& x) { x.directionsPerFace = 6; });
            add("step r=4", [](LpmSettings& x) { x.raysPerVoxel = 4; });
            add("step b=4", [](LpmSettings& x) { x.binsPerFace = 4; });
            add("step tol 1e-5", [](LpmSettings& x) { x.tolerance = 1e-5; });
            add("step subdivide 2", [](LpmSettings& x) { x.subdivide = 2; });
        }
    }
    std::printf(
        "| grid | albedo | voxel tau (max) | MC s | MC noise | setting | band-0 RMS | bias | bands 1-2 | passes | LPM "
        "s |\n");
    std::printf("|---|---|---|---|---|---|---|---|---|---|---|\n");
    for (int n : sizes)
        for (double a : albedos) {
            Case c{"cloud", VolumeKind::Cloud, 0.5, a, 50.0};
            Scene sc = makeScene(c, n);
            sc.lights.env = &sc.sky;
            double maxTau = 0;
            for (float s : sc.medium.sigmaT) maxTau = std::max(maxTau, double(s) * sc.medium.voxelSize.x);
            std::vector<McVoxelEstimate> mc;
            const double tMc =
                secondsOf([&] { mc = mcVoxelSH(sc.medium, sc.lights, sampleVoxels(sc.medium, 48), samples, 2); });
            for (const Setting& st : settings) {
                if (st.s.subdivide > 1 && n > 16) continue;  // minutes per solve
                LpmResult r;
                const double t = secondsOf([&] { r = solveLpm(sc.medium, sc.lights, st.s); });
                const Comparison e = compare(r, mc);
                std::printf("| %d^3 | %g | %.2f | %.1f | %.4f | %s | %.4f | %+.4f | %.4f | %zu | %.2f |\n", n, a,
                            maxTau, tMc, e.band0Noise, st.name.c_str(), e.band0Rms, e.band0Bias, e.band12Rms,
                            r.passes.size(), t);
                std::fflush(stdout);
            }
        }
    return 0;
}

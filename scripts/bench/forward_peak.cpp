// Strongly peaked phase functions: LPM against the Monte Carlo reference (MIS between
// next-event estimation and phase sampling) on the heterogeneous cloud (32^3, line
// optical depth 8, sky + sun) for g in {0.9, 0.95, 0.99, -0.9, -0.99}, with and without
// delta-M truncation and with one unshot bin per direction. Prints a markdown table (the
// one in docs/accuracy.md).
//   lpm_bench_forward_peak [--threads N] [--samples S] [--n N] [--g G] [--albedo A] [--sky-only]
#include <cstdio>
#include <cstring>

#include "core/parallel.h"
#include "tests/core/lpm_vs_mc.h"

using namespace lpm;
using namespace lpm::test;

int main(int argc, char** argv) {
    int threads = 0, samples = 40000, n = 32;
    double onlyG = 2, albedo = 0.95;
    bool skyOnly = false;  // no sun: the MC reference is far less noisy at |g| -> 1
    for (int i = 1; i < argc; ++i) {
        if (!std::strcmp(argv[i], "--threads") && i + 1 < argc) threads = std::atoi(argv[++i]);
        if (!std::strcmp(argv[i], "--samples") && i + 1 < argc) samples = std::atoi(argv[++i]);
        if (!std::strcmp(argv[i], "--n") && i + 1 < argc) n = std::atoi(argv[++i]);
        if (!std::strcmp(argv[i], "--g") && i + 1 < argc) onlyG = std::atof(argv[++i]);
        if (!std::strcmp(argv[i], "--albedo") && i + 1 < argc) albedo = std::atof(argv[++i]);
        if (!std::strcmp(argv[i], "--sky-only")) skyOnly = true;
    }
    ThreadLimit limit(threads);
    std::vector<double> gs = {0.9, 0.95, 0.99, -0.9, -0.99};
    if (onlyG <= 1) gs = {onlyG};
    struct Setting {
        std::string name;
        LpmSettings s;
        bool forwardOnly;
    };
    std::vector<Setting> settings;
    LpmSettings plain;
    plain.deltaM = 0;
    settings.push_back({"no delta-M", plain, false});
    LpmSettings dm;
    dm.deltaM = 1;
    settings.push_back({"delta-M (f = g^4)", dm, true});
    LpmSettings fine = plain;
    fine.binsPerFace = 4;
    settings.push_back({"no delta-M, b = 4", fine, false});
    std::printf("Lights: %s\n\n", skyOnly ? "sky only" : "sky + sun (0.53 degrees)");
    std::printf("| g | albedo | MC s | MC noise | setting | band-0 RMS | bias | bands 1-2 | passes | LPM s |\n");
    std::printf("|---|---|---|---|---|---|---|---|---|---|\n");
    for (double g : gs) {
        Case c{"cloud", VolumeKind::Cloud, g, albedo, 8.0};
        Scene sc = makeScene(c, n);
        sc.lights.env = &sc.sky;
        if (skyOnly) sc.lights.suns.clear();
        std::vector<McVoxelEstimate> mc;
        const double tMc =
            secondsOf([&] { mc = mcVoxelSH(sc.medium, sc.lights, sampleVoxels(sc.medium, 48), samples, 2); });
        for (const Setting& st : settings) {
            if (st.forwardOnly && g <= 0) continue;
            LpmResult r;
            const double t = secondsOf([&] { r = solveLpm(sc.medium, sc.lights, st.s); });
            const Comparison e = compare(r, mc);
            std::printf("| %g | %g | %.1f | %.4f | %s | %.4f | %+.4f | %.4f | %zu | %.2f |\n", g, albedo, tMc,
                        e.band0Noise, st.name.c_str(), e.band0Rms, e.band0Bias, e.band12Rms, r.passes.size(), t);
            std::fflush(stdout);
        }
    }
    return 0;
}

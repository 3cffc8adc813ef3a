// Accuracy-versus-time of the LPM knobs against the Monte Carlo reference, on the six
// comparison cases of tests/core/lpm_vs_mc_test.cpp. Prints a markdown table:
// one row per setting, error columns averaged over the cases, LPM seconds summed.
//   lpm_bench_accuracy [--quick] [--threads N] [--only SUBSTRING]
#include <cstdio>
#include <cstring>
#include <map>

#include "core/parallel.h"
#include "tests/core/lpm_vs_mc.h"

using namespace lpm;
using namespace lpm::test;

int main(int argc, char** argv) {
    bool quick = false;
    int threads = 0;
    std::string only;  // run only the settings whose name contains this
    for (int i = 1; i < argc; ++i) {
        if (!std::strcmp(argv[i], "--quick")) quick = true;
        if (!std::strcmp(argv[i], "--threads") && i + 1 < argc) threads = std::atoi(argv[++i]);
        if (!std::strcmp(argv[i], "--only") && i + 1 < argc) only = argv[++i];
    }
    ThreadLimit limit(threads);
    struct Setting {
        std::string name;
        LpmSettings s;
    };
    std::vector<Setting> settings;
    auto add = [&](const std::string& name, auto&& mod) {
        LpmSettings s;
        mod(s);
        settings.push_back({name, s});
    };
    add("defaults (n=4, r=2, b=auto, tol=1e-3)", [](LpmSettings&) {});
    for (int n : {2, 3, 6})
        add("directions/face n=" + std::to_string(n), [n](LpmSettings& s) { s.directionsPerFace = n; });
    for (int r : {1, 4}) add("rays/voxel r=" + std::to_string(r), [r](LpmSettings& s) { s.raysPerVoxel = r; });
    for (int b : {1, 4}) add("bins/face b=" + std::to_string(b), [b](LpmSettings& s) { s.binsPerFace = b; });
    add("no GMRES (plain source iteration)", [](LpmSettings& s) { s.krylov = false; });
    add("subdivide 2", [](LpmSettings& s) { s.subdivide = 2; });
    add("step source everywhere", [](LpmSettings& s) { s.linearSource = 0; });
    add("linear source everywhere", [](LpmSettings& s) { s.linearSource = 1; });
    add("delta-M off", [](LpmSettings& s) { s.deltaM = 0; });
    add("delta-M wherever g > 0", [](LpmSettings& s) { s.deltaM = 1; });
    for (double t : {1e-2, 1e-4}) {
        char buf[64];
        std::snprintf(buf, sizeof buf, "tolerance %.0e", t);
        add(buf, [t](LpmSettings& s) { s.tolerance = t; });
    }
    if (quick) settings.resize(2);
    if (!only.empty()) {
        std::vector<Setting> keep;
        for (const Setting& st : settings)
            if (st.name.find(only) != std::string::npos) keep.push_back(st);
        settings = keep;
    }

    const auto cases = comparisonCases();
    std::vector<Scene> scenes;
    std::vector<std::vector<McVoxelEstimate>> refs;
    double mcSeconds = 0;
    for (const Case& c : cases) {
        scenes.push_back(makeScene(c));
        Scene& s = scenes.back();
        s.lights.env = &s.sky;
        const int samples = (c.g >= 0.7 ? 40000 : 12000) * (quick ? 1 : 4);
        mcSeconds +=
            secondsOf([&] { refs.push_back(mcVoxelSH(s.medium, s.lights, sampleVoxels(s.medium, 48), samples, 2)); });
    }
    for (Scene& s : scenes) s.lights.env = &s.sky;  // vector may have moved
    std::printf("MC reference: %zu cases x 48 voxels, %.1f s in all (%d threads)\n\n", cases.size(), mcSeconds,
                maxThreads());
    std::printf(
        "| setting | band-0 rel. RMS (mean / worst case) | MC noise | bands 1-2 rel. RMS (mean) | passes (sum) | LPM "
        "seconds (sum) |\n");
    std::printf("|---|---|---|---|---|---|\n");
    for (const Setting& st : settings) {
        double sum0 = 0, worst0 = 0, noise = 0, sum12 = 0, secs = 0;
        int n12 = 0, passes = 0;
        for (size_t i = 0; i < cases.size(); ++i) {
            LpmResult r;
            secs += secondsOf([&] { r = solveLpm(scenes[i].medium, scenes[i].lights, st.s); });
            const Comparison e = compare(r, refs[i]);
            sum0 += e.band0Rms / cases.size();
            worst0 = std::max(worst0, e.band0Rms);
            noise += e.band0Noise / cases.size();
            if (cases[i].g != 0) {
                sum12 += e.band12Rms;
                ++n12;
            }
            passes += int(r.passes.size());
        }
        std::printf("| %s | %.4f / %.4f | %.4f | %.4f | %d | %.2f |\n", st.name.c_str(), sum0, worst0, noise,
                    n12 ? sum12 / n12 : 0.0, passes, secs);
        std::fflush(stdout);
    }
    return 0;
}

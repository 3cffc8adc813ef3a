// White furnace (albedo 1, uniform environment L0) on the heterogeneous 16^3 cloud of
// tests/core/lpm_acceleration_test.cpp, scaled to a largest line optical depth of 50 and
// 500: passes, seconds and worst |S/L0 - 1| with GMRES and with plain source iteration
// (capped; where the cap stops it, the table says so and gives the error it had reached).
// Prints a markdown table (docs/accuracy.md).
//   lpm_bench_furnace [--threads N] [--cap PASSES (default 3000)] [--step]
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include "core/parallel.h"
#include "tests/core/lpm_vs_mc.h"

using namespace lpm;
using namespace lpm::test;

int main(int argc, char** argv) {
    int threads = 0, cap = 3000;
    bool step = false;
    for (int i = 1; i < argc; ++i) {
        if (!std::strcmp(argv[i], "--threads") && i + 1 < argc) threads = std::atoi(argv[++i]);
        if (!std::strcmp(argv[i], "--cap") && i + 1 < argc) cap = std::atoi(argv[++i]);
        if (!std::strcmp(argv[i], "--step")) step = true;
    }
    ThreadLimit limit(threads);
    std::printf("| line optical depth | source | iteration | passes | converged | LPM s | worst abs(S/L0 - 1) |\n");
    std::printf("|---|---|---|---|---|---|---|\n");
    for (double tau : {50.0, 500.0}) {
        const Medium m = furnaceCloud(tau);
        const float L0 = 1.5f;
        const EnvMap env = EnvMap::constant(RGB(L0));
        Lights lights;
        lights.env = &env;
        for (bool krylov : {true, false}) {
            LpmSettings s;
            s.krylov = krylov;
            s.maxOrders = cap;
            if (step) s.linearSource = 0;
            const LpmResult r = solveLpm(m, lights, s);
            std::printf("| %g | %s | %s | %zu | %s | %.1f | %.5f |\n", tau, step ? "step" : "auto (linear)",
                        krylov ? "GMRES" : "plain", r.passes.size(), r.converged ? "yes" : "no (cap)", r.seconds,
                        worstFurnaceError(m, r, L0));
            std::fflush(stdout);
        }
    }
    return 0;
}

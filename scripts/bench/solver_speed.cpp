// Solver speed and memory: ray-segment updates per second and peak RSS for cubic
// procedural clouds of growing size, at 1 thread and all threads.
//   lpm_bench_speed [max_n]   (default 64)
#include <sys/resource.h>

#include <cstdio>
#include <cstdlib>

#include "core/parallel.h"
#include "tests/core/lpm_vs_mc.h"

using namespace lpm;
using namespace lpm::test;

static double peakRssMiB() {
    rusage u{};
    getrusage(RUSAGE_SELF, &u);
    return u.ru_maxrss / 1024.0;
}

int main(int argc, char** argv) {
    const int maxN = argc > 1 ? std::atoi(argv[1]) : 64;
    const int all = maxThreads();
    std::printf(
        "| voxels | g | threads | passes | seconds | s/pass | segments/s | peak RSS MiB "
        "|\n|---|---|---|---|---|---|---|---|\n");
    for (int n = 16; n <= maxN; n *= 2)
        for (double g : {0.0, 0.6})
            for (int threads : {1, all}) {
                ThreadLimit limit(threads);
                Medium m = makeVolume(VolumeKind::Cloud, n, 1.0);
                scaleToMaxOpticalDepth(m, 8.0);
                m.albedo = RGB(0.9f);
                m.g = g;
                const EnvMap sky = makeSky(128);
                Lights lights;
                lights.env = &sky;
                lights.suns.push_back({normalize(Vec3{-0.5, 1, 0.35}), RGB(3.0f), 0.53});
                LpmSettings s;
                s.maxOrders = 4;  // fixed work per run
                const LpmResult r = solveLpm(m, lights, s);
                std::printf("| %d^3 | %.1f | %d | %zu | %.2f | %.3f | %.3g | %.0f |\n", n, g, threads, r.passes.size(),
                            r.seconds, r.seconds / r.passes.size(), r.segments / r.seconds, peakRssMiB());
                std::fflush(stdout);
            }
    return 0;
}

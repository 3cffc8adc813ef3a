// The host's own 1 -> 2 thread ceiling (issue 9, target 3): three kernels with no shared
// data, no locks and no serial part, each run on 1 and on 2 threads (each thread does the
// same work, so perfect scaling is 2.0x), interleaved, repeated. What they get is what
// any program gets from this host's second vCPU: when two vCPUs are hyperthreads of one
// physical core, or a neighbour holds the core, the compute kernel falls short of 2x.
//   lpm_bench_host_scaling [reps]
//   compute: 8 independent FMA chains in registers (the core's arithmetic units)
//   cache:   sums over a 256 KiB array per thread (L2-resident loads)
//   memory:  sums over a 256 MiB array per thread (DRAM bandwidth, shared L3)
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <thread>
#include <vector>

namespace {

volatile double g_sink = 0;  // keeps the results alive

double compute(std::size_t n) {
    double a[8] = {1, 2, 3, 4, 5, 6, 7, 8};
    for (std::size_t i = 0; i < n; ++i)
        for (double& x : a) x = x * 0.999999 + 1e-7;
    double s = 0;
    for (double x : a) s += x;
    return s;
}

double sweep(const std::vector<float>& v, int times) {
    float s[8] = {};
    for (int t = 0; t < times; ++t)
        for (std::size_t i = 0; i + 8 <= v.size(); i += 8)
            for (int k = 0; k < 8; ++k) s[k] += v[i + std::size_t(k)];
    double total = 0;
    for (float x : s) total += x;
    return total;
}

/// Seconds for `threads` threads each running work(thread).
double timed(int threads, const std::function<double(int)>& work) {
    const auto t0 = std::chrono::steady_clock::now();
    std::vector<std::thread> pool;
    for (int t = 0; t < threads; ++t) pool.emplace_back([&, t] { g_sink = g_sink + work(t); });
    for (auto& p : pool) p.join();
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

double median(std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
}

}  // namespace

int main(int argc, char** argv) {
    const int reps = argc > 1 ? std::max(1, std::atoi(argv[1])) : 5;
    std::vector<std::vector<float>> small(2, std::vector<float>(64 * 1024, 1.0f));
    std::vector<std::vector<float>> large(2, std::vector<float>(64 * 1024 * 1024, 1.0f));
    const std::vector<std::pair<const char*, std::function<double(int)>>> kernels = {
        {"compute", [](int) { return compute(200000000); }},
        {"cache", [&](int t) { return sweep(small[std::size_t(t)], 40000); }},
        {"memory", [&](int t) { return sweep(large[std::size_t(t)], 8); }},
    };
    std::printf(
        "| kernel | 1 thread s (min, median) | 2 threads s (min, median) | speed-up of minima | of medians |\n");
    std::printf("|---|---|---|---|---|\n");
    for (const auto& [name, work] : kernels) {
        std::vector<double> one, two;
        for (int r = 0; r < reps; ++r) {
            one.push_back(timed(1, work));
            two.push_back(timed(2, work));
        }
        // Each thread does one thread's work: the speed-up is 2 x (1-thread time / 2-thread time).
        const double m1 = *std::min_element(one.begin(), one.end()), m2 = *std::min_element(two.begin(), two.end());
        std::printf("| %s | %.3f, %.3f | %.3f, %.3f | %.2fx | %.2fx |\n", name, m1, median(one), m2, median(two),
                    2.0 * m1 / m2, 2.0 * median(one) / median(two));
    }
    return 0;
}

#include "core/parallel.h"

#include <vector>

#include <tbb/blocked_range.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>
#include <tbb/partitioner.h>

#include "core/flush_denormals.h"

namespace lpm {

double parallelSumOfChunks(std::size_t n, std::size_t grain,
                           const std::function<double(std::size_t, std::size_t)>& part) {
    if (grain == 0) grain = 1;
    std::vector<double> sums((n + grain - 1) / grain, 0.0);
    parallelForChunks(n, grain, [&](std::size_t b, std::size_t e) { sums[b / grain] = part(b, e); });
    double sum = 0;
    for (double x : sums) sum += x;
    return sum;
}

void parallelForChunks(std::size_t n, std::size_t grain, const std::function<void(std::size_t, std::size_t)>& body) {
    if (n == 0) return;
    if (grain == 0) grain = 1;
    const std::size_t chunks = (n + grain - 1) / grain;
    tbb::parallel_for(
        tbb::blocked_range<std::size_t>(0, chunks, 1),
        [&](const tbb::blocked_range<std::size_t>& r) {
            const FlushDenormals flush;  // the same mode on every thread (core/flush_denormals.h)
            for (std::size_t c = r.begin(); c != r.end(); ++c) {
                const std::size_t b = c * grain;
                const std::size_t e = b + grain < n ? b + grain : n;
                body(b, e);
            }
        },
        tbb::simple_partitioner());
}

int maxThreads() {
    return static_cast<int>(tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism));
}

struct ThreadLimit::Impl {
    std::unique_ptr<tbb::global_control> control;
};

ThreadLimit::ThreadLimit(int threads) : impl_(new Impl) {
    if (threads > 0)
        impl_->control.reset(new tbb::global_control(tbb::global_control::max_allowed_parallelism, threads));
}
ThreadLimit::~ThreadLimit() = default;

}  // namespace lpm

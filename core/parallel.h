// The project's only door to TBB. Work is split into fixed chunks so that any
// reduction done by the caller in chunk order is independent of the thread count.
#pragma once

#include <cstddef>
#include <functional>
#include <memory>

namespace lpm {

/// Calls body(begin, end) for fixed chunks [k*grain, min(n,(k+1)*grain)) in parallel.
void parallelForChunks(std::size_t n, std::size_t grain, const std::function<void(std::size_t, std::size_t)>& body);

/// The sum of part(begin, end) over the same fixed chunks, computed in parallel and added
/// in chunk order: the same double for any thread count.
double parallelSumOfChunks(std::size_t n, std::size_t grain,
                           const std::function<double(std::size_t, std::size_t)>& part);

/// Number of worker threads currently allowed.
int maxThreads();

/// Limits TBB's worker count while alive (0 = no limit).
class ThreadLimit {
public:
    explicit ThreadLimit(int threads);
    ~ThreadLimit();
    ThreadLimit(const ThreadLimit&) = delete;
    ThreadLimit& operator=(const ThreadLimit&) = delete;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace lpm

// Fixed-chunk parallel loops and sums (core/parallel.h).
#include "core/parallel.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

using namespace lpm;

// The sum over fixed chunks is the same double for 1, 2 and 16 threads, and within
// rounding of the plain serial sum; an empty range sums to 0.
TEST(Parallel, SumOfChunksIsTheSameForAnyThreadCount) {
    std::vector<double> x(100003);
    for (size_t i = 0; i < x.size(); ++i) x[i] = std::sin(0.37 * double(i)) * (1.0 + 1e-3 * double(i % 97));
    const auto part = [&](size_t b, size_t e) {
        double s = 0;
        for (size_t i = b; i < e; ++i) s += x[i];
        return s;
    };
    double serial = 0, scale = 0;
    for (double v : x) serial += v, scale += std::fabs(v);
    std::vector<double> sums;
    for (int threads : {1, 2, 16}) {
        ThreadLimit limit(threads);
        sums.push_back(parallelSumOfChunks(x.size(), 1000, part));
    }
    EXPECT_EQ(sums[0], sums[1]);
    EXPECT_EQ(sums[0], sums[2]);
    EXPECT_NEAR(sums[0], serial, 1e-12 * scale);
    EXPECT_EQ(parallelSumOfChunks(0, 1000, part), 0.0);
}

// FlushDenormals (core/flush_denormals.h): inside its scope a product below float's normal
// range is zero, and the mode it found is restored after; every parallel task runs in
// that mode (core/parallel.cpp), whatever thread runs it.
#include "core/flush_denormals.h"

#include <gtest/gtest.h>

#include <cstddef>
#include <limits>
#include <vector>

#include "core/parallel.h"

using namespace lpm;

namespace {

/// Whether a product below float's normal range (FLT_MIN / 16) comes out as zero in the
/// current mode (volatile: computed at run time).
bool flushing() {
    volatile float smallest = std::numeric_limits<float>::min(), sixteenth = 0.0625f;
    return smallest * sixteenth == 0.0f;
}

}  // namespace

#if defined(__SSE__) || defined(__x86_64__)

TEST(FlushDenormals, ZeroesBelowNormalInsideItsScopeAndRestoresAfter) {
    ASSERT_FALSE(flushing()) << "the test's thread starts in the hardware's default mode";
    {
        const FlushDenormals flush;
        EXPECT_TRUE(flushing());
        {
            const FlushDenormals nested;
            EXPECT_TRUE(flushing());
        }
        EXPECT_TRUE(flushing()) << "a nested scope restores what the outer one set";
    }
    EXPECT_FALSE(flushing());
}

TEST(FlushDenormals, EveryParallelTaskRunsFlushed) {
    const ThreadLimit two(2);
    std::vector<int> flushed(256, 0);
    parallelForChunks(flushed.size(), 1, [&](std::size_t b, std::size_t e) {
        for (std::size_t i = b; i < e; ++i) flushed[i] = flushing() ? 1 : 0;
    });
    for (std::size_t i = 0; i < flushed.size(); ++i) EXPECT_EQ(flushed[i], 1) << i;
    EXPECT_FALSE(flushing()) << "the caller's mode is left as it was";
}

#else

TEST(FlushDenormals, ZeroesBelowNormalInsideItsScopeAndRestoresAfter) { GTEST_SKIP() << "x86 MXCSR only"; }

#endif

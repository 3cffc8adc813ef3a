// core/scratch_pool: pooled blocks are reused best-fit, the pool does not grow past what is
// in use at once, blocks are whole huge pages, and small requests stay on the heap.
#include "core/scratch_pool.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <string>
#include <thread>
#include <vector>

#include "smaps.h"

namespace lpm {
namespace {

constexpr std::size_t kMiB = std::size_t(1) << 20;
constexpr std::size_t kFloatsPerMiB = kMiB / sizeof(float);

TEST(ScratchPool, ReturnedBlockIsReusedBestFit) {
    releaseScratchPool();
    float* small = nullptr;
    {
        ScratchBlock a(4 * kFloatsPerMiB), b(8 * kFloatsPerMiB);
        small = a.data();
        EXPECT_EQ(scratchPoolBytes(), 12 * kMiB);
    }
    ScratchBlock c(3 * kFloatsPerMiB);  // both fit: the smaller one
    EXPECT_EQ(c.data(), small);
    EXPECT_EQ(c.capacity(), 4 * kFloatsPerMiB);
    EXPECT_EQ(scratchPoolBytes(), 12 * kMiB);
}

TEST(ScratchPool, GrowingReleasesFreeBlocksThatDoNotFit) {
    releaseScratchPool();
    {
        ScratchBlock a(4 * kFloatsPerMiB), b(6 * kFloatsPerMiB);
    }
    ScratchBlock big(16 * kFloatsPerMiB);
    EXPECT_EQ(scratchPoolBytes(), 16 * kMiB);  // the 4 and 6 MiB blocks went
    EXPECT_EQ(releaseScratchPool(), 0u);       // the 16 MiB one is in use
}

TEST(ScratchPool, BlocksAreWholeHugePagesAndWritable) {
    releaseScratchPool();
    ScratchBlock a(kFloatsPerMiB + 1);
    EXPECT_EQ(reinterpret_cast<std::uintptr_t>(a.data()) % (2 * kMiB), 0u);
    EXPECT_EQ(a.capacity(), 2 * kMiB / sizeof(float));
    for (std::size_t i = 0; i < a.capacity(); ++i) a.data()[i] = float(i);
    EXPECT_EQ(a.data()[a.capacity() - 1], float(a.capacity() - 1));
}

TEST(ScratchPool, BlocksAreAdvisedOntoHugePages) {
    const std::string modes = thpModes();
    if (!thpUsable(modes)) GTEST_SKIP() << "THP off: " << modes;
    releaseScratchPool();
    ScratchBlock a(3 * kFloatsPerMiB);  // below the old 4 MiB floor of the advice
    EXPECT_EQ(thpEligible(a.data()), 1) << "THP mode " << modes;
}

TEST(ScratchPool, SmallBlocksStayOnTheHeap) {
    releaseScratchPool();
    ScratchBlock a(1000);
    ASSERT_NE(a.data(), nullptr);
    EXPECT_GE(a.capacity(), 1000u);
    EXPECT_EQ(scratchPoolBytes(), 0u);
}

TEST(ScratchPool, ThreadsTakeAndReturnWithoutLosingBlocks) {
    releaseScratchPool();
    std::vector<std::thread> threads;
    for (int t = 0; t < 4; ++t)
        threads.emplace_back([t] {
            for (int i = 0; i < 200; ++i) {
                ScratchBlock b((1 + (i + t) % 3) * kFloatsPerMiB);
                b.data()[0] = float(i);
                b.data()[b.capacity() - 1] = float(t);
            }
        });
    for (auto& th : threads) th.join();
    // At most 4 blocks were in use at once, each at most 4 MiB (3 MiB rounded to pages).
    EXPECT_LE(scratchPoolBytes(), 16 * kMiB);
    const std::size_t held = scratchPoolBytes();
    EXPECT_EQ(releaseScratchPool(), held);  // every block came back
    EXPECT_EQ(scratchPoolBytes(), 0u);
}

}  // namespace
}  // namespace lpm

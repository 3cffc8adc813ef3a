// core/malloc_policy: zeroed buffers, reuse of their storage, and the huge-page advice.
#include "core/malloc_policy.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <cstring>
#include <fstream>
#include <string>

#include <sys/mman.h>
#include <sys/resource.h>
#include <unistd.h>

#include "core/math.h"
#include "core/parallel.h"

#include "smaps.h"

namespace lpm {
namespace {

TEST(MallocPolicy, AssignZeroedZeroesGrowsAndReusesStorage) {
    std::vector<float> v(1000, 7.0f);
    assignZeroed(v, 500);
    ASSERT_EQ(v.size(), 500u);
    for (float x : v) ASSERT_EQ(x, 0.0f);
    const float* kept = v.data();
    v.assign(500, 3.0f);
    assignZeroed(v, 800);  // within the old capacity: same storage
    EXPECT_EQ(v.data(), kept);
    for (float x : v) ASSERT_EQ(x, 0.0f);
    assignZeroed(v, size_t(3) << 20);  // grows: fresh storage, all zero
    ASSERT_EQ(v.size(), size_t(3) << 20);
    for (float x : v) ASSERT_EQ(x, 0.0f);

    std::vector<RGB> c(10, RGB(1.0f));
    assignZeroed(c, 20);
    for (const RGB& x : c) ASSERT_EQ(x.r + x.g + x.b, 0.0f);
}

TEST(MallocPolicy, AdviseIgnoresSmallAndNullRanges) {
    adviseHugePages(nullptr, size_t(64) << 20);
    std::vector<float> small(16);
    adviseHugePages(small.data(), small.size() * sizeof(float));
    EXPECT_EQ(small.size(), 16u);
}

TEST(MallocPolicy, LargeBuffersAreAdvisedOntoHugePages) {
    const std::string modes = thpModes();
    if (!thpUsable(modes)) GTEST_SKIP() << "THP off: " << modes;
    std::vector<float> v;
    assignZeroed(v, size_t(16) << 20);  // 64 MiB: its middle lies in whole 2 MiB pages
    EXPECT_EQ(thpEligible(v.data() + v.size() / 2), 1) << "THP mode " << modes;
}

// The policy also advises the main heap: a block below the mmap threshold (carved from the
// heap, not mapped on its own) lies in huge-page-eligible memory.
TEST(MallocPolicy, HeapBlocksAreAdvisedOntoHugePages) {
    const std::string modes = thpModes();
    if (!thpUsable(modes)) GTEST_SKIP() << "THP off: " << modes;
    if (!heapAdviceSupported()) GTEST_SKIP() << "no glibc heap in this build (sanitizer allocator or not Linux)";
    keepFreedBuffersForReuse();
    std::vector<float> v(size_t(2) << 20);  // 8 MiB, below the 32 MiB mmap threshold
    EXPECT_EQ(thpEligible(v.data() + v.size() / 2), 1) << "THP mode " << modes;
}

// populateInParallel faults a fresh range in, split over the threads, and leaves what
// was written before it alone (a range that begins and ends inside pages, as a heap block
// does).
TEST(MallocPolicy, PopulateInParallelFaultsInAndKeepsContents) {
    ThreadLimit two(2);
    if (maxThreads() < 2) GTEST_SKIP() << "needs 2 threads";
    const size_t page = size_t(sysconf(_SC_PAGESIZE)), bytes = (size_t(9) << 20) + 3 * page;
    void* map = mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    ASSERT_NE(map, MAP_FAILED);
    auto* base = static_cast<unsigned char*>(map);
    const size_t pages = bytes / page;
    std::vector<unsigned char> resident(pages);
    ASSERT_EQ(mincore(map, bytes, resident.data()), 0);
    size_t before = 0;
    for (unsigned char r : resident) before += r & 1;
    if (before != 0) {
        munmap(map, bytes);
        GTEST_SKIP() << "fresh anonymous pages already resident";
    }
    std::memset(base, 0x5a, size_t(1) << 20);  // the first MiB holds data
    populateInParallel(base + 100, bytes - 200);
    ASSERT_EQ(mincore(map, bytes, resident.data()), 0);
    size_t missing = 0;
    for (size_t i = 1; i + 1 < pages; ++i) missing += (resident[i] & 1) ? 0 : 1;
    if (missing == pages - 2 && !(resident[0] & 1)) {
        // Nothing faulted: a kernel before 5.14 (MADV_POPULATE_WRITE answers EINVAL).
        const int probe = madvise(base + (size_t(4) << 20), page, 23 /* MADV_POPULATE_WRITE */);
        if (probe != 0) {
            munmap(map, bytes);
            GTEST_SKIP() << "no MADV_POPULATE_WRITE here";
        }
    }
    EXPECT_EQ(missing, 0u) << "of " << pages - 2 << " whole pages inside the range";
    size_t changed = 0;
    for (size_t i = 0; i < (size_t(1) << 20); ++i) changed += base[i] != 0x5a;
    for (size_t i = size_t(1) << 20; i < bytes; ++i) changed += base[i] != 0;
    EXPECT_EQ(changed, 0u);
    munmap(map, bytes);
}

long minorFaults() {
    rusage ru{};
    getrusage(RUSAGE_SELF, &ru);
    return ru.ru_minflt;
}

// After prepareHeapForSmallBlocks, small blocks (an output tree's 6 KiB leaf buffers) come
// from resident heap memory: a fraction of the page faults that the same allocations take
// on fresh heap (one per 4 KiB page written).
TEST(MallocPolicy, PreparedHeapServesSmallBlocksWithoutFaults) {
    if (!heapAdviceSupported()) GTEST_SKIP() << "no glibc heap in this build (sanitizer allocator or not Linux)";
    ThreadLimit two(2);
    keepFreedBuffersForReuse();
    constexpr size_t kLeaf = 6 * 1024, kLeaves = 8000;  // 47 MiB
    auto allocateLeaves = [&](std::vector<void*>& into) {
        const long before = minorFaults();
        for (size_t i = 0; i < kLeaves; ++i) {
            into.push_back(std::malloc(kLeaf));
            std::memset(into.back(), 1, kLeaf);
        }
        return minorFaults() - before;
    };
    // Past the heap's first 192 MiB, which keepFreedBuffersForReuse advised (not touched).
    std::vector<void*> filler, control, prepared;
    for (int i = 0; i < 25; ++i) filler.push_back(std::malloc(size_t(8) << 20));
    const long onFreshHeap = allocateLeaves(control);  // kept: the next ones cannot reuse them
    auto freeAll = [](std::vector<void*>& v) {
        for (void* p : v) std::free(p);
    };
    if (onFreshHeap < long(kLeaves * kLeaf / 4096 / 2)) {
        freeAll(control);
        freeAll(filler);
        GTEST_SKIP() << "the heap's fresh pages fault " << onFreshHeap << " times for " << kLeaves
                     << " leaves here (huge pages everywhere?)";
    }
    prepareHeapForSmallBlocks(kLeaves * (kLeaf + 32));
    const long afterPreparing = allocateLeaves(prepared);
    freeAll(prepared);
    freeAll(control);
    freeAll(filler);
    EXPECT_LT(afterPreparing * 10, onFreshHeap) << afterPreparing << " faults against " << onFreshHeap;
}

size_t residentBytes() {
    std::ifstream statm("/proc/self/statm");
    size_t pages = 0, resident = 0;
    statm >> pages >> resident;
    return resident * 4096;
}

// Blocks below the mmap threshold stay resident when freed (kept for reuse) until
// returnFreedHeapPages gives their pages back: what the two-grid solve does before its
// coarse orders, whose buffers are mapped outside the heap.
TEST(MallocPolicy, FreedHeapPagesGoBackWhenAsked) {
    if (!heapAdviceSupported()) GTEST_SKIP() << "no glibc heap in this build (sanitizer allocator or not Linux)";
    keepFreedBuffersForReuse();
    constexpr size_t kBlock = size_t(8) << 20, kBlocks = 12;  // 96 MiB in blocks below the 32 MiB threshold
    void* blocks[kBlocks];
    for (void*& b : blocks) {
        b = std::malloc(kBlock);
        ASSERT_NE(b, nullptr);
        std::memset(b, 1, kBlock);
    }
    void* guard = std::malloc(4096);  // keeps the blocks off the heap's top
    const size_t touched = residentBytes();
    for (void* b : blocks) std::free(b);
    const size_t freed = residentBytes();
    returnFreedHeapPages();
    const size_t returned = residentBytes();
    std::free(guard);
    EXPECT_GT(freed + 64 * (size_t(1) << 20), touched) << "freed blocks left the heap without being asked";
    EXPECT_LT(returned + 64 * (size_t(1) << 20), freed)
        << "resident " << (freed >> 20) << " -> " << (returned >> 20) << " MiB";
}

}  // namespace
}  // namespace lpm

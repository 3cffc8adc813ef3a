// Allocator policy for bakes (core/malloc_policy.h).
#include "core/malloc_policy.h"

#include <algorithm>
#include <cstdint>
#include <cstdlib>  // defines __GLIBC__ on glibc
#include <vector>

#include <tbb/task_arena.h>

#include "core/parallel.h"

#if defined(__GLIBC__)
#include <malloc.h>
#endif
#if defined(__linux__)
#include <sys/mman.h>
#include <unistd.h>
#endif

namespace lpm {

namespace {

// glibc's own heap (a sanitizer's allocator replaces it) on Linux.
#if defined(__GLIBC__) && defined(__linux__) && !defined(__SANITIZE_ADDRESS__)
#define LPM_GLIBC_HEAP 1
#else
#define LPM_GLIBC_HEAP 0
#endif

void adviseHeapOntoHugePages() {
#if LPM_GLIBC_HEAP
    // Grow the main heap by 192 MiB in blocks below the mmap threshold (each touches only
    // its header page), advise the whole range, and free the blocks: they merge into the
    // heap's top, which stays below the trim threshold, so the allocations that follow
    // (the volume read's tree nodes, the solver's small buffers) are carved from advised
    // memory and fault in 2 MiB at a time. What glibc's own glibc.malloc.hugetlb=1 tunable
    // does, which a program cannot set for itself after it has started.
    constexpr std::size_t kBlock = std::size_t(16) << 20, kBlocks = 12;  // 192 MiB, below the trim threshold
    void* blocks[kBlocks] = {};
    std::uintptr_t lo = UINTPTR_MAX, hi = 0;
    for (void*& b : blocks) {
        b = std::malloc(kBlock);
        if (!b) break;
        lo = std::min(lo, reinterpret_cast<std::uintptr_t>(b));
        hi = std::max(hi, reinterpret_cast<std::uintptr_t>(b) + kBlock);
    }
    if (hi > lo) adviseHugePages(reinterpret_cast<void*>(lo), hi - lo);
    for (void* b : blocks) std::free(b);
#endif
}

// Set once keepFreedBuffersForReuse has fixed the mmap threshold at 32 MiB.
bool g_heapPolicy = false;

/// The whole `unit`-aligned blocks inside [p, p + bytes) (unit a power of two), as
/// [lo, hi); empty when hi <= lo.
struct AlignedRange {
    std::uintptr_t lo, hi;
};
[[maybe_unused]] AlignedRange alignedInside(const void* p, std::size_t bytes, std::uintptr_t unit) {
    const std::uintptr_t a = reinterpret_cast<std::uintptr_t>(p);
    return {(a + unit - 1) & ~(unit - 1), (a + bytes) & ~(unit - 1)};
}

}  // namespace

void prepareHeapForSmallBlocks(std::size_t bytes) {
#if LPM_GLIBC_HEAP
    constexpr std::size_t kBlock = std::size_t(16) << 20, kMost = std::size_t(224) << 20;
    if (!g_heapPolicy) return;
    std::vector<void*> blocks;
    for (std::size_t got = 0; got < std::min(bytes, kMost); got += kBlock) {
        void* b = std::malloc(kBlock);
        if (!b) break;
        blocks.push_back(b);
    }
    for (void* b : blocks) {
        adviseHugePages(b, kBlock);
        populateInParallel(b, kBlock);
    }
    for (void* b : blocks) std::free(b);
#else
    (void)bytes;
#endif
}

void returnFreedHeapPages() {
#if LPM_GLIBC_HEAP  // a sanitizer's allocator keeps its own pools
    malloc_trim(0);
#endif
}

bool heapAdviceSupported() { return LPM_GLIBC_HEAP != 0; }

void keepFreedBuffersForReuse() {
#if defined(__GLIBC__)
    // A fixed threshold also stops glibc's dynamic one, which raises itself only after a
    // mapped block is freed (and trims the heap at twice it).
    mallopt(M_MMAP_THRESHOLD, 32 << 20);
    mallopt(M_TRIM_THRESHOLD, 256 << 20);
    g_heapPolicy = true;
    adviseHeapOntoHugePages();
#endif
}

void populateInParallel(void* p, std::size_t bytes) {
#if defined(__linux__)
#ifndef MADV_POPULATE_WRITE
#define MADV_POPULATE_WRITE 23  // Linux 5.14; older kernels answer EINVAL (ignored)
#endif
    constexpr std::uintptr_t kPiece = std::uintptr_t(2) << 20;
    if (!p || bytes < 2 * kPiece || maxThreads() < 2) return;
    const AlignedRange pages = alignedInside(p, bytes, std::uintptr_t(sysconf(_SC_PAGESIZE)));
    const std::uintptr_t lo = pages.lo, hi = pages.hi;  // (a lambda cannot capture a structured binding in C++17)
    if (hi <= lo) return;
    // Pieces on 2 MiB boundaries, so each huge page is faulted by one thread.
    const std::uintptr_t first = (lo + kPiece) & ~(kPiece - 1);
    const std::size_t pieces = 1 + (hi > first ? (hi - first + kPiece - 1) / kPiece : 0);
    // Isolated: called inside a sweep job, the waiting thread must not start another job
    // (whose buffers would then be alive beside this one's).
    tbb::this_task_arena::isolate([&] {
        parallelForChunks(pieces, 1, [&](std::size_t b, std::size_t e) {
            for (std::size_t i = b; i < e; ++i) {
                const std::uintptr_t a = i == 0 ? lo : first + (i - 1) * kPiece;
                const std::uintptr_t z = std::min(hi, i == 0 ? first : a + kPiece);
                if (z > a) madvise(reinterpret_cast<void*>(a), z - a, MADV_POPULATE_WRITE);  // errors ignored
            }
        });
    });
#else
    (void)p;
    (void)bytes;
#endif
}

void discardPages(void* p, std::size_t bytes) {
#if defined(__linux__)
    if (!p) return;
    const auto [lo, hi] = alignedInside(p, bytes, std::uintptr_t(sysconf(_SC_PAGESIZE)));
    if (hi > lo) madvise(reinterpret_cast<void*>(lo), hi - lo, MADV_DONTNEED);  // best effort: errors ignored
#else
    (void)p;
    (void)bytes;
#endif
}

void adviseHugePages(void* p, std::size_t bytes) {
#if defined(__linux__) && defined(MADV_HUGEPAGE)
    constexpr std::uintptr_t kHuge = std::uintptr_t(2) << 20;
    if (!p || bytes < kHuge) return;
    const auto [lo, hi] = alignedInside(p, bytes, kHuge);
    if (hi > lo) madvise(reinterpret_cast<void*>(lo), hi - lo, MADV_HUGEPAGE);  // best effort: errors ignored
#else
    (void)p;
    (void)bytes;
#endif
}

}  // namespace lpm

// The process's allocator policy for bakes (glibc, Linux).
//
// 1. Freed buffers stay in the heap: the solver's per-pass buffers (sweep planes and ray
//    rows, batch accumulators, a few MiB to tens of MiB each, allocated and freed by every
//    pass and batch) would otherwise go back to the kernel when freed and be faulted in
//    again page by page at the next use. Measured on the 1M-voxel Mantaflow smoke
//    (docs/performance.md): 175k page faults per bake -> 67k, solve 4.1 -> 3.2 s on 2
//    threads, peak RSS +25 MiB.
// 2. Large buffers and the heap on transparent huge pages: a first touch of a 4 KiB page costs a trap
//    (about 7 us on this VM, most of it the hypervisor); the solver's big buffers are
//    advised MADV_HUGEPAGE before their first touch, so one fault maps 2 MiB
//    (`assignZeroed`). The kernel's THP mode here is "madvise": without the advice none
//    are used.
// 3. Buffers reused from pass to pass are allocated by the thread that runs the pass,
//    never inside a parallel body (PassRunner::reserveBuffers): glibc gives each thread
//    its own heap, and a block a worker allocated went back to that worker's heap and
//    stayed resident there (plume-1M at g = 0.6 peaked at 664 or 697 MiB from run to run,
//    depending on which thread had allocated the deposit buffers; now 662-667).
// 4. First touches shared out over the threads: a fresh huge page costs 1-3 ms to fault on
//    this VM, so a large buffer zeroed by one thread (or a heap region that thousands of
//    small blocks then fault 4 KiB at a time) kept the other thread waiting. New storage is
//    faulted in by all the threads before it is written (`populateInParallel`, in
//    `assignZeroed`), and the heap is readied so before the output trees are built
//    (`prepareHeapForSmallBlocks`). docs/performance.md, session 24.
#pragma once

#include <cstddef>
#include <vector>

namespace lpm {

/// Keeps freed blocks below 32 MiB in the heap for reuse (mmap threshold fixed at 32 MiB,
/// heap trimmed only above 256 MiB free), and advises the first 192 MiB of the main heap
/// onto huge pages (the volume read's tree nodes fault in 2 MiB at a time: the smoke's read
/// 0.085 -> 0.055 s). Call once, before any thread starts; a no-op outside glibc.
void keepFreedBuffersForReuse();

/// Readies `bytes` (at most 224 MiB: the heap's top is trimmed above 256 MiB) of the
/// main heap for many small blocks that come next, such as an output tree's leaves: the
/// heap grows by that much in 16 MiB blocks, advised onto huge pages, faulted in by all
/// the threads (populateInParallel) and freed again into the heap's top, where the small
/// blocks are then carved from resident memory. Without it they fault in 4 KiB at a time
/// on the thread that allocates them (plume-1M at SH order 2: nine output trees, 45k page
/// faults, 0.4 s). Only after keepFreedBuffersForReuse (else glibc maps 16 MiB blocks on
/// their own); a no-op outside glibc.
void prepareHeapForSmallBlocks(std::size_t bytes);

/// Gives the heap's free pages back to the kernel (glibc's malloc_trim): for the points
/// where the buffers kept for reuse will not be used again for a while and larger ones,
/// mapped outside the heap, come next (the two-grid solve's coarse orders). A no-op
/// outside glibc.
void returnFreedHeapPages();

/// Whether keepFreedBuffersForReuse advises the heap in this build (glibc on Linux, no
/// sanitizer allocator).
bool heapAdviceSupported();

/// Asks the kernel to back the whole 2 MiB pages inside [p, p + bytes) with transparent
/// huge pages. Best effort: nothing when no whole 2 MiB page lies inside, where THP is
/// off, or off Linux.
void adviseHugePages(void* p, std::size_t bytes);

/// Gives the whole pages inside [p, p + bytes) back to the kernel (MADV_DONTNEED) while the
/// block stays allocated: they read as zeros and are faulted in again when next written.
/// For a large buffer whose values wait elsewhere (core/held_sh.h): its address range stays
/// its own, so the values come back to the same storage, not to a new block the heap may
/// have to grow for. Best effort: elsewhere than Linux the pages stay resident.
void discardPages(void* p, std::size_t bytes);

/// Faults [p, p + bytes) in, zero-filled, with the pages shared out over the threads
/// (MADV_POPULATE_WRITE in 2 MiB pieces): on this VM a first touch costs about 1 ms per
/// MiB, and a buffer zeroed by one thread kept the others waiting. Contents are unchanged
/// (pages already present stay as they are). Best effort: nothing below 4 MiB, with one
/// thread, or where the kernel (before Linux 5.14) or the platform lacks it.
void populateInParallel(void* p, std::size_t bytes);

/// Makes room for n elements in v, in new storage advised onto huge pages when v must
/// grow (not touched: the first write faults it in). Returns v.
template <class T>
std::vector<T>& reserveOnHugePages(std::vector<T>& v, std::size_t n) {
    if (v.capacity() < n) {
        std::vector<T> fresh;
        fresh.reserve(n);
        adviseHugePages(fresh.data(), n * sizeof(T));
        v.swap(fresh);
    }
    return v;
}

/// v.assign(n, 0) for a large buffer: when v must grow, its new storage is advised onto
/// huge pages and faulted in by all the threads before the zeros are written. Returns v.
template <class T>
std::vector<T>& assignZeroed(std::vector<T>& v, std::size_t n) {
    if (v.capacity() < n) populateInParallel(reserveOnHugePages(v, n).data(), n * sizeof(T));
    v.assign(n, T{});
    return v;
}

/// v = src for a large buffer, into storage advised onto huge pages when v must grow.
/// Returns v.
template <class T>
std::vector<T>& assignCopy(std::vector<T>& v, const std::vector<T>& src) {
    reserveOnHugePages(v, src.size()).assign(src.begin(), src.end());
    return v;
}

}  // namespace lpm

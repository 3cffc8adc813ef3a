// Uninitialised scratch storage for the sweeps' ray rows, from a process-wide pool.
//
// Every sweep holds its rays' radiance in an arena of a few MiB (core/sweep.cpp), written
// before it is read, so it needs no zeroing. Allocated with new[] per sweep, the arenas
// of the first pass were faulted in 4 KiB at a time: on the 1M-voxel smoke 21k of the
// bake's 42k page faults, about 0.15 s of a 3.6 s 1-thread bake on this VM
// (docs/performance.md, session 14). Blocks from this pool are 2 MiB-aligned whole huge
// pages (advised MADV_HUGEPAGE before their first touch) and go back to the pool, not to
// the allocator, so later passes and bakes reuse them already mapped.
#pragma once

#include <cstddef>

namespace lpm {

/// A pooled block of at least `floats` floats, uninitialised, returned to the pool when
/// destroyed. The smallest free block that is large enough is reused; when none is, the
/// free blocks are released (so the pool holds no more than the largest set of blocks in
/// use at once) and a new one allocated. Thread-safe. Blocks under 1 MiB are plain heap
/// blocks, not pooled (the heap keeps those well).
class ScratchBlock {
public:
    explicit ScratchBlock(std::size_t floats);
    ~ScratchBlock();
    ScratchBlock(const ScratchBlock&) = delete;
    ScratchBlock& operator=(const ScratchBlock&) = delete;

    float* data() const { return p_; }
    std::size_t capacity() const { return cap_; }  ///< floats

private:
    float* p_ = nullptr;
    std::size_t cap_ = 0;
    bool pooled_ = false;
};

/// Frees the pool's free blocks (blocks in use are freed when they come back). Returns
/// the bytes freed.
std::size_t releaseScratchPool();

/// Bytes the pool holds: in use and free.
std::size_t scratchPoolBytes();

}  // namespace lpm

// The process's allocator policy for bakes (glibc): the solver's per-pass buffers (sweep
// planes and ray rows, batch accumulators, a few MiB to tens of MiB each, allocated and
// freed by every pass and batch) would otherwise go back to the kernel when freed and be
// faulted in again page by page at the next use. Measured on the 1M-voxel Mantaflow smoke
// (docs/performance.md): 175k page faults per bake -> 67k, solve 4.1 -> 3.2 s on 2 threads,
// peak RSS +25 MiB.
#pragma once

namespace lpm {

/// Keeps freed blocks below 32 MiB in the heap for reuse (mmap threshold fixed at 32 MiB,
/// heap trimmed only above 256 MiB free). Call once, before any thread starts; a no-op
/// outside glibc.
void keepFreedBuffersForReuse();

}  // namespace lpm

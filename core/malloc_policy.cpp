// Allocator policy for bakes (core/malloc_policy.h).
#include "core/malloc_policy.h"

#include <cstdlib>  // defines __GLIBC__ on glibc

#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace lpm {

void keepFreedBuffersForReuse() {
#if defined(__GLIBC__)
    // A fixed threshold also stops glibc's dynamic one, which raises itself only after a
    // mapped block is freed (and trims the heap at twice it).
    mallopt(M_MMAP_THRESHOLD, 32 << 20);
    mallopt(M_TRIM_THRESHOLD, 256 << 20);
#endif
}

}  // namespace lpm

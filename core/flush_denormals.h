// Denormal floats flushed to zero while solver work runs (docs/performance.md, "Session
// 54"). Light attenuating through a thick medium passes through float's denormal range
// (below 1.2e-38) on its way to zero, and on x86 every operation on a denormal takes a
// microcode assist of about 100 cycles: the environment pass of the 1M cumulus, 133
// optical depths across, swept 3.4x slower per segment than the passes after it. FTZ and
// DAZ (MXCSR) make those values zero instead; nothing a bake writes is that small (a
// radiance of 1e-38 against the environment's O(1)).
//
// Set around every parallel task (core/parallel.cpp) and for a solve's calling thread
// (solveLpm), and restored after both: every computation of a solve runs in the same mode
// whatever the thread count, and the caller's own mode is left as it was.
#pragma once

#if defined(__SSE__) || defined(__x86_64__)
#include <xmmintrin.h>
#endif

namespace lpm {

class FlushDenormals {
public:
#if defined(__SSE__) || defined(__x86_64__)
    FlushDenormals() : saved_(_mm_getcsr()) { _mm_setcsr(saved_ | kFtzDaz); }
    ~FlushDenormals() { _mm_setcsr(saved_); }
#else
    FlushDenormals() = default;  // other targets: the hardware's default mode
#endif
    FlushDenormals(const FlushDenormals&) = delete;
    FlushDenormals& operator=(const FlushDenormals&) = delete;

private:
#if defined(__SSE__) || defined(__x86_64__)
    static constexpr unsigned kFtzDaz = 0x8040;  ///< MXCSR bits 15 (flush to zero) and 6 (denormals are zero)
    unsigned saved_;
#endif
};

}  // namespace lpm

// Half-precision coarse buffers (core/half_buffer.h). The conversions are the bit-exact
// branch-light forms of F. Giesen's "float->half variants" (round to nearest even) and
// "half to float" (inline in the header), portable to any compiler (Debian's clang 14 has
// no _Float16 on x86).
#include "core/half_buffer.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "core/malloc_policy.h"
#include "core/parallel.h"

namespace lpm {

float largestFinite(const std::vector<float>& x) {
    std::vector<float> part((x.size() + (1 << 16) - 1) >> 16, 0.0f);
    parallelForChunks(x.size(), 1 << 16, [&](std::size_t b, std::size_t e) {
        float largest = 0;
        for (std::size_t i = b; i < e; ++i)
            if (std::isfinite(x[i])) largest = std::max(largest, std::fabs(x[i]));
        part[b >> 16] = largest;
    });
    float largest = 0;
    for (float p : part) largest = std::max(largest, p);
    return largest;
}

float HalfBuffer::scaleFor(float largest) {
    // largest / scale in [2^14, 2^15): below the half range's 65504, with a factor 2 to
    // spare. At least 2^-126 (float's smallest normal): the scale and its inverse are exact.
    return largest > 0 ? std::ldexp(1.0f, std::max(std::ilogb(largest) - 14, -126)) : 1.0f;
}

HalfBuffer HalfBuffer::encode(const std::vector<float>& x) {
    HalfBuffer out;
    out.scale = scaleFor(largestFinite(x));
    const float inverse = 1.0f / out.scale;  // a power of two: exact
    assignZeroed(out.bits, x.size());
    parallelForChunks(x.size(), 1 << 16, [&](std::size_t b, std::size_t e) {
        for (std::size_t i = b; i < e; ++i) out.bits[i] = halfFromFloat(x[i] * inverse);
    });
    return out;
}

}  // namespace lpm

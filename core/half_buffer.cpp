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

namespace {

std::uint32_t bitsOf(float x) {
    std::uint32_t u;
    std::memcpy(&u, &x, sizeof u);
    return u;
}

float floatOf(std::uint32_t u) {
    float x;
    std::memcpy(&x, &u, sizeof x);
    return x;
}

}  // namespace

std::uint16_t halfFromFloat(float x) {
    std::uint32_t f = bitsOf(x);
    const std::uint32_t sign = f & 0x80000000u;
    f ^= sign;
    std::uint32_t h;
    if (f >= 0x47800000u) {  // |x| >= 65536, infinity or NaN
        h = f > 0x7f800000u ? 0x7e00u : 0x7c00u;
    } else if (f < 0x38800000u) {                 // |x| < 2^-14: subnormal or zero; the FPU's addition rounds
        const float magic = floatOf(126u << 23);  // 0.5: ulp 2^-24, the subnormal step
        h = bitsOf(floatOf(f) + magic) - bitsOf(magic);
    } else {  // normal: rebias the exponent, round the 13 dropped bits to nearest even
        const std::uint32_t mantissaOdd = (f >> 13) & 1u;
        f += (std::uint32_t(15 - 127) << 23) + 0xfffu + mantissaOdd;
        h = f >> 13;  // a carry into exponent 31 is infinity, as it should be
    }
    return std::uint16_t(h | (sign >> 16));
}

HalfBuffer HalfBuffer::encode(const std::vector<float>& x) {
    float largest = 0;
    for (float v : x)
        if (std::isfinite(v)) largest = std::max(largest, std::fabs(v));
    HalfBuffer out;
    // largest / scale in [2^14, 2^15): below the half range's 65504, with a factor 2 to
    // spare. At least 2^-126 (float's smallest normal): the scale and its inverse are exact.
    if (largest > 0) out.scale = std::ldexp(1.0f, std::max(std::ilogb(largest) - 14, -126));
    const float inverse = 1.0f / out.scale;  // a power of two: exact
    assignZeroed(out.bits, x.size());
    parallelForChunks(x.size(), 1 << 16, [&](std::size_t b, std::size_t e) {
        for (std::size_t i = b; i < e; ++i) out.bits[i] = halfFromFloat(x[i] * inverse);
    });
    return out;
}

void HalfBuffer::negate() {
    parallelForChunks(bits.size(), 1 << 16, [&](std::size_t b, std::size_t e) {
        for (std::size_t i = b; i < e; ++i) bits[i] = std::uint16_t(bits[i] ^ 0x8000u);
    });
}

}  // namespace lpm

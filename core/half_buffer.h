// Coarse buffers held in half precision (IEEE 754 binary16) with one power-of-two scale:
// value i = half(bits[i]) x scale. Round to nearest even, so a stored value is within
// 2^-11 of the float relative to it (4.9e-4) wherever it is at least 2^-14 x scale
// (6.1e-5 x scale); the scale maps the buffer's largest finite magnitude into [2^14, 2^15),
// so nothing overflows and everything below 2^-29 of the largest value is stored with an
// absolute error of at most 2^-25 scale.
//
// Used for the two-grid cycle's coarse tail (docs/multires.md, "The tail in half
// precision"), where the rounded tail is both added to E and taken from r', so the
// rounding moves no energy, only the distribution of sources the next cycle corrects.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <vector>

namespace lpm {

/// Nearest binary16 to x (ties to even); beyond 65504 infinity, NaN stays NaN. Inline and
/// branch-free (all three cases computed, one selected), so loops over a buffer vectorize.
inline std::uint16_t halfFromFloat(float x) {
    std::uint32_t f;
    std::memcpy(&f, &x, sizeof f);
    const std::uint32_t sign = f & 0x80000000u;
    f ^= sign;
    // Normal: rebias the exponent, round the 13 dropped bits to nearest even (a carry into
    // exponent 31 is infinity, as it should be). Unsigned wrap-around where unused.
    const std::uint32_t normal = (f + (std::uint32_t(15 - 127) << 23) + 0xfffu + ((f >> 13) & 1u)) >> 13;
    // |x| < 2^-14, subnormal or zero: the FPU's addition to 0.5 (ulp 2^-24, the subnormal
    // step) rounds.
    constexpr std::uint32_t kHalfBits = 126u << 23;
    float magnitude, half, sum;
    std::memcpy(&magnitude, &f, sizeof f);
    std::memcpy(&half, &kHalfBits, sizeof f);
    sum = magnitude + half;
    std::uint32_t subnormal;
    std::memcpy(&subnormal, &sum, sizeof f);
    subnormal -= kHalfBits;
    const std::uint32_t special = f > 0x7f800000u ? 0x7e00u : 0x7c00u;  // NaN, else infinity
    const std::uint32_t h = f >= 0x47800000u ? special : (f < 0x38800000u ? subnormal : normal);
    return std::uint16_t(h | (sign >> 16));
}
/// The binary16 value `h` as a float (exact). Inline and branch-free (selects, not jumps),
/// so loops over a buffer vectorize: GMRES's Krylov basis is decoded in its inner products.
inline float floatFromHalf(std::uint16_t h) {
    constexpr std::uint32_t kShiftedExponent = 0x7c00u << 13;
    const std::uint32_t shifted = (std::uint32_t(h) & 0x7fffu) << 13;
    const std::uint32_t exponent = shifted & kShiftedExponent;
    // Rebias the exponent (15 -> 127); infinity and NaN go on to float's largest exponent.
    const std::uint32_t normal =
        shifted + (std::uint32_t(127 - 15) << 23) + (exponent == kShiftedExponent ? std::uint32_t(128 - 16) << 23 : 0u);
    // Zero and subnormals: renormalised by the FPU, (2^-14 + m 2^-24) - 2^-14.
    float renormalised, offset, x;
    const std::uint32_t subnormalBits = normal + (1u << 23), offsetBits = 113u << 23;
    std::memcpy(&renormalised, &subnormalBits, sizeof x);
    std::memcpy(&offset, &offsetBits, sizeof x);
    std::memcpy(&x, &normal, sizeof x);
    x = exponent == 0 ? renormalised - offset : x;
    std::uint32_t bits;
    std::memcpy(&bits, &x, sizeof bits);
    bits |= (std::uint32_t(h) & 0x8000u) << 16;
    std::memcpy(&x, &bits, sizeof x);
    return x;
}

/// The largest finite |x_i| (0 for none), in parallel chunks.
float largestFinite(const std::vector<float>& x);

struct HalfBuffer {
    std::vector<std::uint16_t> bits;
    float scale = 1.0f;  ///< a power of two

    /// x in half precision, the scale taken from its largest finite magnitude.
    static HalfBuffer encode(const std::vector<float>& x);
    /// The scale for a buffer whose largest finite magnitude is `largest`: a power of two
    /// that maps it into [2^14, 2^15), at least 2^-126 (1 for 0).
    static float scaleFor(float largest);
    float at(std::size_t i) const { return floatFromHalf(bits[i]) * scale; }
    std::size_t size() const { return bits.size(); }
};

}  // namespace lpm

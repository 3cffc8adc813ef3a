// Coarse buffers held in half precision (IEEE 754 binary16) with one power-of-two scale:
// value i = half(bits[i]) x scale. Round to nearest even, so a stored value is within
// 2^-11 of the float relative to it (4.9e-4) wherever it is at least 2^-14 x scale
// (6.1e-5 x scale); the scale maps the buffer's largest finite magnitude into [2^14, 2^15),
// so nothing overflows and everything below 2^-29 of the largest value is stored with an
// absolute error of at most 2^-25 scale. Negation is exact.
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

/// Nearest binary16 to x (ties to even); beyond 65504 infinity, NaN stays NaN.
std::uint16_t halfFromFloat(float x);
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

struct HalfBuffer {
    std::vector<std::uint16_t> bits;
    float scale = 1.0f;  ///< a power of two

    /// x in half precision, the scale taken from its largest finite magnitude.
    static HalfBuffer encode(const std::vector<float>& x);
    float at(std::size_t i) const { return floatFromHalf(bits[i]) * scale; }
    std::size_t size() const { return bits.size(); }
    /// -value for every element (the sign bit flipped: exact).
    void negate();
};

}  // namespace lpm

// bfloat16: a float's sign, its 8 exponent bits and the top 7 of its 23 mantissa bits
// (docs/performance.md, "Session 29"). Float's range, so no scale is needed (HalfBuffer's
// binary16 needs one); 8 significant bits: round to nearest even keeps a stored value
// within 2^-8 (0.39%) of the float relative to it, and the rounding errors of many values
// have zero mean.
//
// Used for the per-direction deposits of the separable fine passes after pass 0
// (core/separable_pass.cpp): each is written once by its sweep and read once by the fold,
// which sums it, weighted, with about a hundred other directions' into every SH
// coefficient, angular integral and coarse restriction, so a deposit's rounding reaches
// those sums divided among the directions (measured in docs/performance.md).
#pragma once

#include <cstdint>
#include <cstring>

namespace lpm {

/// A bfloat16 value: the upper 16 bits of a float.
struct Bf16 {
    std::uint16_t bits = 0;
};

/// Nearest bfloat16 to x (ties to even); a value within half an ulp of float's largest goes
/// to infinity, NaN stays NaN. Branch-free, so loops vectorize.
inline Bf16 bf16FromFloat(float x) {
    std::uint32_t f;
    std::memcpy(&f, &x, sizeof f);
    const std::uint32_t rounded = (f + 0x7fffu + ((f >> 16) & 1u)) >> 16;
    const std::uint32_t quiet = (f >> 16) | 0x40u;  // a NaN whose payload lies in the dropped bits stays NaN
    return Bf16{std::uint16_t((f & 0x7fffffffu) > 0x7f800000u ? quiet : rounded)};
}

/// The bfloat16 `h` as a float (exact).
inline float floatFromBf16(Bf16 h) {
    const std::uint32_t f = std::uint32_t(h.bits) << 16;
    float x;
    std::memcpy(&x, &f, sizeof x);
    return x;
}

}  // namespace lpm

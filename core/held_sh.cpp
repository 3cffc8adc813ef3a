// The SH result held compactly while the coarse grid solves (core/held_sh.h).
#include "core/held_sh.h"

#include <string>

#include "core/error.h"
#include "core/malloc_policy.h"
#include "core/parallel.h"

namespace lpm {

HeldSh::HeldSh(std::vector<float>& sh, int coeffs) : coeffs_(coeffs) {
    const size_t width = size_t(coeffs) * 3;
    if (coeffs < 2 || sh.size() % width != 0)
        throw Error("HeldSh", "an SH result of " + std::to_string(sh.size()) + " values in rows of " +
                                  std::to_string(coeffs) + " coefficients");
    const size_t rows = sh.size() / width, rest = width - 3;
    directional_.scale = HalfBuffer::scaleFor(largestFinite(sh));
    const float inverse = 1.0f / directional_.scale;  // a power of two: exact
    assignZeroed(band0_, rows * 3);
    assignZeroed(directional_.bits, rows * rest);
    parallelForChunks(rows, 1 << 12, [&](size_t b, size_t e) {
        for (size_t row = b; row < e; ++row) {
            const float* in = &sh[row * width];
            for (size_t c = 0; c < 3; ++c) band0_[row * 3 + c] = in[c];
            for (size_t i = 0; i < rest; ++i) directional_.bits[row * rest + i] = halfFromFloat(in[3 + i] * inverse);
        }
    });
    discardPages(sh.data(), sh.size() * sizeof(float));
}

void HeldSh::restore(std::vector<float>& sh) {
    const size_t width = size_t(coeffs_) * 3, rest = width - 3, rows = band0_.size() / 3;
    if (sh.size() != rows * width)
        throw Error("HeldSh",
                    "restoring " + std::to_string(rows) + " rows into " + std::to_string(sh.size()) + " values");
    parallelForChunks(rows, 1 << 12, [&](size_t b, size_t e) {
        for (size_t row = b; row < e; ++row) {
            float* out = &sh[row * width];
            for (size_t c = 0; c < 3; ++c) out[c] = band0_[row * 3 + c];
            for (size_t i = 0; i < rest; ++i) out[3 + i] = directional_.at(row * rest + i);
        }
    });
    band0_ = std::vector<float>();
    directional_ = HalfBuffer();
}

}  // namespace lpm

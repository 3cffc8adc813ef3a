// PCG32 (O'Neill 2014): small, fast, deterministic per stream. Monte Carlo code seeds
// one generator per voxel or pixel, so results do not depend on the thread count.
#pragma once

#include <cstdint>

namespace lpm {

class Pcg32 {
public:
    Pcg32(std::uint64_t seed, std::uint64_t stream) {
        inc_ = (stream << 1u) | 1u;
        state_ = 0;
        next();
        state_ += seed;
        next();
    }
    std::uint32_t next() {
        const std::uint64_t old = state_;
        state_ = old * 6364136223846793005ULL + inc_;
        const std::uint32_t xorshifted = std::uint32_t(((old >> 18u) ^ old) >> 27u);
        const std::uint32_t rot = std::uint32_t(old >> 59u);
        return (xorshifted >> rot) | (xorshifted << ((-rot) & 31));
    }
    /// Uniform in [0, 1).
    double uniform() {
        const std::uint64_t a = next() >> 5, b = next() >> 6;  // 53 bits
        return (double(a) * 67108864.0 + double(b)) * (1.0 / 9007199254740992.0);
    }

private:
    std::uint64_t state_, inc_;
};

}  // namespace lpm

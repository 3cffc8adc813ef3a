// The inner loop of the folds (core/pass_runner.cpp, core/separable_source.cpp): a
// direction's deposit (an RGB triple) times its per-coefficient fold coefficients, added to
// a voxel's row, written so that it vectorises.
#pragma once

namespace lpm {

/// An RGB triple repeated 8 times: 24 floats = 3 channels x 8 lanes.
struct RgbRepeat {
    float v[24];
    explicit RgbRepeat(const float* p) {
        for (int k = 0; k < 24; k += 3) {
            v[k] = p[0];
            v[k + 1] = p[1];
            v[k + 2] = p[2];
        }
    }
};

/// dst[i] += coef[i] * p[i % 3] for i < 3 count: coefficients repeated per channel times an
/// RGB triple, written so that it vectorises.
inline void addTimesRgb(float* __restrict dst, const float* __restrict coef, const RgbRepeat& p, int count) {
    int i = 0;
    for (; i + 24 <= 3 * count; i += 24)
        for (int k = 0; k < 24; ++k) dst[i + k] += coef[i + k] * p.v[k];
    // The rest in whole triples (i is a multiple of 3 here): an index modulo 3 made GCC
    // vectorise this tail with emulated gathers, slower than the 24-wide body it follows
    // (SH order 2: 27 = 24 + 3 floats per voxel and job).
    for (; i < 3 * count; i += 3) {
        dst[i] += coef[i] * p.v[0];
        dst[i + 1] += coef[i + 1] * p.v[1];
        dst[i + 2] += coef[i + 2] * p.v[2];
    }
}

}  // namespace lpm

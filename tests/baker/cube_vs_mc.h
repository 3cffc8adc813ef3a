// A constant cube baked and rendered by lpmbake against the Monte Carlo camera image of
// the same cube (core/mc_reference.h): shared by the edge and sun-term render tests.
#pragma once

#include <gtest/gtest.h>

#include <OpenImageIO/imageio.h>

#include <cmath>
#include <string>
#include <vector>

#include "core/mc_reference.h"

namespace lpmtest {

/// Ray through pixel coordinates (px, py) hits the MC cube [-h/2, (n - 1/2) h]^3.
inline bool hitsCube(const lpm::PinholeCamera& cam, double px, double py, int n, double h) {
    const lpm::Vec3 d = cam.rayDirection(px, py);
    double t0 = 0, t1 = 1e30;
    for (int a = 0; a < 3; ++a) {
        double ta = (-0.5 * h - cam.eye[a]) / d[a], tb = ((n - 0.5) * h - cam.eye[a]) / d[a];
        if (ta > tb) std::swap(ta, tb);
        t0 = std::max(t0, ta);
        t1 = std::min(t1, tb);
    }
    return t1 > t0;
}

inline std::vector<float> readRgb(const std::string& path, int w, int h) {
    auto in = OIIO::ImageInput::open(path);
    EXPECT_TRUE(in) << path;
    if (!in) return {};
    EXPECT_EQ(in->spec().width, w);
    EXPECT_EQ(in->spec().height, h);
    std::vector<float> img(size_t(w) * h * 3);
    in->read_image(0, 0, 0, 3, OIIO::TypeDesc::FLOAT, img.data());
    in->close();
    return img;
}

struct ImageError {
    int pixels = 0;        ///< pixels whose whole footprint sees the cube
    double meanRatio = 0;  ///< sum of render / sum of MC over those pixels and channels
    double relRms = 0;     ///< RMS of (render - MC) / mean MC
    double relNoise = 0;   ///< the same for the MC standard error
};

/// Compares `img` with `ref` on the pixels whose four corners all see the cube (the
/// silhouette pixels are left out: the preview shoots one ray per pixel centre, the
/// reference jitters over the pixel).
inline ImageError compareOnCube(const std::vector<float>& img, const lpm::McImage& ref, const lpm::PinholeCamera& cam,
                                int n, double h) {
    ImageError e;
    double se = 0, sum = 0, sumR = 0, noise = 0;
    for (int py = 0; py < cam.height; ++py)
        for (int px = 0; px < cam.width; ++px) {
            bool inside = true;
            for (int k = 0; k < 4; ++k) inside &= hitsCube(cam, px + (k & 1), py + (k >> 1), n, h);
            if (!inside) continue;
            ++e.pixels;
            const size_t p = size_t(py) * cam.width + px;
            for (int ch = 0; ch < 3; ++ch) {
                const double r = img[p * 3 + ch], mc = ref.mean[p * 3 + ch];
                se += (r - mc) * (r - mc);
                sum += mc;
                sumR += r;
                noise += ref.stdErr[p * 3 + ch] * ref.stdErr[p * 3 + ch];
            }
        }
    const int count = 3 * std::max(1, e.pixels);
    const double mean = sum / count;
    e.meanRatio = sumR / sum;
    e.relRms = std::sqrt(se / count) / mean;
    e.relNoise = std::sqrt(noise / count) / mean;
    return e;
}

}  // namespace lpmtest

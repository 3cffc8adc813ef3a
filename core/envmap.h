// Lat-long environment radiance in the working colour space, as a piecewise-constant
// function over pixels (nearest pixel, no interpolation: every consumer integrates the
// same function). Orientation follows OpenEXR's ImfEnvmap with +Y up: the top-left
// pixel is latitude +pi/2, longitude +pi; latitude 0 / longitude 0 is +Z; longitude
// +pi/2 is +X. For a direction d pointing TOWARD the light:
//   lat = asin(d.y), lon = atan2(d.x, d.z), u = (pi - lon) / (2 pi), v = (pi/2 - lat) / pi.
// rotateY rotates the whole environment by that many degrees about the image's +Y
// (right-handed). The scene's up axis says which world axis the image's +Y is: UpAxis::Y
// (default) uses the image frame as the world frame; UpAxis::Z (Blender, Mantaflow) turns
// the image frame by +90 degrees about +X, (x, y, z)_image -> (x, -z, y)_world, so the
// sky's zenith is world +Z and the image centre (longitude 0) faces world -Y.
#pragma once

#include <algorithm>
#include <cmath>
#include <memory>
#include <vector>

#include "core/math.h"

namespace lpm {

/// A pixel carrying a large share of the environment's power (a sun in an HDRI).
struct EnvHotPixel {
    int x = 0, y = 0;
    Vec3 toward;       ///< world direction toward the pixel's centre (unit)
    double omega = 0;  ///< the pixel's solid angle (sr)
    RGB radiance;
    double share = 0;  ///< share of the map's power (mean RGB x solid angle)
};

/// Which world axis is up for the environment (docs/conventions.md, "Up axis").
enum class UpAxis { Y, Z };

/// "y" or "z".
inline const char* upAxisName(UpAxis a) { return a == UpAxis::Z ? "z" : "y"; }

/// World direction of the environment image frame's direction `imageDir` before any
/// --env-rotate (the up-axis turn alone).
Vec3 upAxisToWorld(UpAxis a, const Vec3& imageDir);

class EnvMap {
public:
    EnvMap(int width, int height, std::vector<RGB> pixels, double rotateYDegrees = 0.0, float scale = 1.0f,
           UpAxis up = UpAxis::Y);
    /// The same from interleaved RGB floats (width x height x 3, rows top to bottom), kept
    /// as the map's pixels: a decoded file's values need no second copy (400 MB at 8K).
    EnvMap(int width, int height, std::vector<float> rgb, double rotateYDegrees = 0.0, float scale = 1.0f,
           UpAxis up = UpAxis::Y);
    static EnvMap constant(const RGB& radiance);

    int width() const { return width_; }
    int height() const { return height_; }
    RGB pixel(int x, int y) const {
        requirePixels();
        return at(size_t(y) * size_t(width_) + size_t(x));
    }

    /// Radiance arriving from direction `towardLight` (world space, unit).
    RGB lookup(const Vec3& towardLight) const;
    /// Bilinear interpolation between pixel centres (wrapping in longitude): for display
    /// only (preview backgrounds). Transport uses the piecewise-constant `lookup`.
    RGB lookupSmooth(const Vec3& towardLight) const;

    /// Importance-samples a direction toward the light with density proportional to
    /// the pixel's mean RGB times its solid angle. Returns radiance; pdf in 1/sr.
    /// pdf == 0 when the map is black.
    RGB sample(double u1, double u2, Vec3& towardLight, double& pdf) const;
    double pdf(const Vec3& towardLight) const;

    /// Partitions the sphere into width*sub x height*sub sub-pixels and calls
    /// f(direction toward light (world), solid angle, radiance) for each sub-pixel of the
    /// sub-pixel rows [y0, y1), row by row, left to right. Over all rows the solid angles
    /// sum to 4 pi exactly (up to rounding). Pixels with skip[y * width + x] != 0 are
    /// reported black when `skip` is given. Rows are independent: callers split them
    /// over threads.
    template <class F>
    void forEachSubPixelInRows(int sub, int y0, int y1, F&& f, const std::vector<unsigned char>* skip = nullptr) const;
    /// Pixels holding at least `minShare` of the map's power each, largest first, at
    /// most `maxCount`.
    std::vector<EnvHotPixel> hotPixels(double minShare, int maxCount) const;

    /// Frees the pixels (400 MB for an 8192 x 4096 map) once every binning a solve needs is
    /// made (core/lpm_cache.h): width, height, integral and maxValue stay; any later read
    /// of a pixel (lookup, sample, binning, hot pixels) throws Error.
    void releasePixels();
    bool hasPixels() const { return !released_; }
    /// Total power-like integral of mean RGB over the sphere (for diagnostics).
    double integral() const { return total_; }
    /// Largest pixel value (any channel).
    float maxValue() const { return maxValue_; }

private:
    RGB at(size_t i) const { return {rgb_[i * 3], rgb_[i * 3 + 1], rgb_[i * 3 + 2]}; }
    void requirePixels() const;
    void pixelOf(const Vec3& towardLight, int& px, int& py) const;
    /// Solid angle of a pixel of row y.
    double pixelSolidAngle(int y) const;
    /// Per-row cumulative sums of mean RGB x solid angle (height x (width + 1)), for
    /// sample(): built on its first call (a bake never samples; an 8192 x 4096 map's table
    /// is 268 MB), then kept; concurrent first calls build it alike and keep one.
    const std::vector<double>& columnCdf() const;
    Vec3 toWorld(const Vec3& imageDir) const { return rot_ * imageDir; }
    Vec3 toImage(const Vec3& worldDir) const { return rotInv_ * worldDir; }

    int width_, height_;
    std::vector<float> rgb_;  ///< interleaved RGB, rows top to bottom
    bool released_ = false;
    Mat3 rot_, rotInv_;
    // Sampling: the marginal over rows, and (columnCdf) the conditional over columns per row.
    std::vector<double> rowCdf_;  // height+1
    mutable std::shared_ptr<const std::vector<double>> colCdf_;
    double total_ = 0;
    float maxValue_ = 0;
};

template <class F>
void EnvMap::forEachSubPixelInRows(int sub, int y0, int y1, F&& f, const std::vector<unsigned char>* skip) const {
    requirePixels();
    sub = std::max(1, sub);
    const int W = width_ * sub, H = height_ * sub;
    const double dPhi = 2 * kPi / W;
    static const RGB black(0.f);
    std::vector<double> sinLon(static_cast<size_t>(W)), cosLon(static_cast<size_t>(W));  // each column centre
    for (int x = 0; x < W; ++x) {
        const double lon = kPi - 2 * kPi * ((x + 0.5) / W);
        sinLon[size_t(x)] = std::sin(lon);
        cosLon[size_t(x)] = std::cos(lon);
    }
    for (int y = std::max(0, y0); y < std::min(y1, H); ++y) {
        // Polar angles of the row's edges from +Y; the centre splits its solid angle in two.
        const double c0 = std::cos(y * kPi / H), c1 = std::cos((y + 1) * kPi / H);
        const double omega = dPhi * (c0 - c1);
        const double tc = std::acos(0.5 * (c0 + c1));
        const double s = std::sin(tc), c = std::cos(tc);
        const size_t row = size_t(y / sub) * size_t(width_);
        const unsigned char* skipRow = skip ? &(*skip)[row] : nullptr;
        for (int x = 0; x < W; ++x) {
            const RGB L = skipRow && skipRow[x / sub] ? black : at(row + size_t(x / sub));
            f(rot_ * Vec3(s * sinLon[size_t(x)], c, s * cosLon[size_t(x)]), omega, L);
        }
    }
}

}  // namespace lpm

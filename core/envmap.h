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

#include <functional>
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
    static EnvMap constant(const RGB& radiance);

    int width() const { return width_; }
    int height() const { return height_; }
    const RGB& pixel(int x, int y) const { return pixels_[size_t(y) * width_ + x]; }

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
    /// f(direction toward light (world), solid angle, radiance) for each. The solid
    /// angles sum to 4 pi exactly (up to rounding).
    /// Pixels with skip[y * width + x] != 0 are reported black when `skip` is given.
    void forEachSubPixel(int sub, const std::function<void(const Vec3&, double, const RGB&)>& f,
                         const std::vector<unsigned char>* skip = nullptr) const;

    /// Pixels holding at least `minShare` of the map's power each, largest first, at
    /// most `maxCount`.
    std::vector<EnvHotPixel> hotPixels(double minShare, int maxCount) const;

    /// Total power-like integral of mean RGB over the sphere (for diagnostics).
    double integral() const { return total_; }
    /// Largest pixel value (any channel).
    float maxValue() const { return maxValue_; }

private:
    void pixelOf(const Vec3& towardLight, int& px, int& py) const;
    Vec3 toWorld(const Vec3& imageDir) const { return rot_ * imageDir; }
    Vec3 toImage(const Vec3& worldDir) const { return rotInv_ * worldDir; }

    int width_, height_;
    std::vector<RGB> pixels_;
    Mat3 rot_, rotInv_;
    // Sampling tables: marginal over rows, conditional over columns per row.
    std::vector<double> rowCdf_;    // height+1
    std::vector<double> colCdf_;    // height*(width+1)
    std::vector<double> pixelPdf_;  // probability of each pixel
    double total_ = 0;
    float maxValue_ = 0;
};

}  // namespace lpm

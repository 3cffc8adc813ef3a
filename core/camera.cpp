// Pinhole camera (camera.h).
#include "core/camera.h"

#include <cmath>

namespace lpm {

Vec3 PinholeCamera::rayDirection(double px, double py) const {
    const Vec3 f = normalize(target - eye);
    const Vec3 r = normalize(cross(f, up));
    const Vec3 u = cross(r, f);
    const double th = std::tan(0.5 * fovYDeg * kPi / 180.0);
    const double aspect = double(width) / height;
    const double sx = (2 * (px / width) - 1) * th * aspect;
    const double sy = (1 - 2 * (py / height)) * th;
    return normalize(f + r * sx + u * sy);
}

}  // namespace lpm

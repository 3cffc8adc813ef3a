// A pinhole camera: the view of `lpmbake render`, of the Monte Carlo reference image
// (core/mc_reference.h) and of the Blender import (scripts/blender/lpm_import.py).
// Right-handed: forward f = normalize(target - eye), right r = normalize(f x up), image
// up u = r x f; pixel (px, py) with py = 0 the top row, fovYDeg the full vertical angle.
#pragma once

#include "core/math.h"

namespace lpm {

struct PinholeCamera {
    Vec3 eye{0, 0, 5}, target{0, 0, 0}, up{0, 1, 0};
    double fovYDeg = 40;
    int width = 64, height = 64;
    /// World-space direction through pixel coordinates (px, py) (py = 0 is the top row).
    Vec3 rayDirection(double px, double py) const;
};

}  // namespace lpm

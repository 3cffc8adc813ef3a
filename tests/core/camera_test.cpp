// Pinhole camera: the centre ray looks at the target, the top row up, the right column right,
// and the field of view spans fovYDeg vertically.
#include "core/camera.h"

#include <gtest/gtest.h>

#include <cmath>

using namespace lpm;

TEST(PinholeCamera, CentreTopAndRightFollowTheFrame) {
    PinholeCamera c;
    c.eye = {1, 2, 3};
    c.target = {1, 2, -7};  // looking along -Z
    c.up = {0, 1, 0};
    c.width = 200;
    c.height = 100;
    c.fovYDeg = 60;
    const Vec3 centre = c.rayDirection(100, 50);
    EXPECT_NEAR(centre.z, -1, 1e-12);
    // Top edge centre: 30 degrees above the axis.
    const Vec3 top = c.rayDirection(100, 0);
    EXPECT_NEAR(std::atan2(top.y, -top.z) * 180 / kPi, 30, 1e-9);
    // Right edge centre: +X (f x up = -Z x Y = +X), at atan(aspect * tan 30).
    const Vec3 right = c.rayDirection(200, 50);
    EXPECT_GT(right.x, 0);
    EXPECT_NEAR(std::atan2(right.x, -right.z), std::atan(2 * std::tan(kPi / 6)), 1e-9);
    EXPECT_NEAR(length(c.rayDirection(13.5, 77.25)), 1, 1e-12);
}

// Black-body emission for temperature grids: Planck's law integrated against the CIE 1931
// 2-degree colour-matching functions (the multi-lobe Gaussian fit of Wyman, Sloan and
// Shirley, JCGT 2(2), 2013), converted to linear Rec.709 (D65). Normalised so that a
// 6500 K black body has luminance Y = 1: values are relative radiance, scaled by the
// caller's intensity (see docs/cli.md, --temperature-grid).
#pragma once

#include "core/math.h"

namespace lpm {

/// CIE XYZ of a black body at `kelvin`, relative to Y(6500 K) = 1. Zero for kelvin <= 0.
Vec3 blackbodyXYZ(double kelvin);
/// Linear Rec.709 / sRGB primaries (D65) of blackbodyXYZ; negative components clamped to 0.
RGB blackbodyRec709(double kelvin);

}  // namespace lpm

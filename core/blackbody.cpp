#include "core/blackbody.h"

#include <algorithm>
#include <cmath>

namespace lpm {

namespace {

// Piecewise Gaussian of the Wyman-Sloan-Shirley fit.
double lobe(double l, double mu, double s1, double s2) {
    const double t = (l - mu) / (l < mu ? s1 : s2);
    return std::exp(-0.5 * t * t);
}

Vec3 cmf(double l) {
    return {
        1.056 * lobe(l, 599.8, 37.9, 31.0) + 0.362 * lobe(l, 442.0, 16.0, 26.7) - 0.065 * lobe(l, 501.1, 20.4, 26.2),
        0.821 * lobe(l, 568.8, 46.9, 40.5) + 0.286 * lobe(l, 530.9, 16.3, 31.1),
        1.217 * lobe(l, 437.0, 11.8, 36.0) + 0.681 * lobe(l, 459.0, 26.0, 13.8)};
}

// Planck spectral radiance (arbitrary constant factor) at wavelength nm, temperature K.
double planck(double nm, double kelvin) {
    const double l = nm * 1e-9;
    const double c2 = 1.4387769e-2;  // h c / k_B, m K
    const double x = c2 / (l * kelvin);
    if (x > 700) return 0.0;
    return 1.0 / (l * l * l * l * l * std::expm1(x));
}

Vec3 integrate(double kelvin) {
    Vec3 s{0, 0, 0};
    for (double nm = 360.5; nm < 830; nm += 1.0) {
        const double b = planck(nm, kelvin);
        const Vec3 c = cmf(nm);
        s = s + c * b;
    }
    return s;
}

}  // namespace

Vec3 blackbodyXYZ(double kelvin) {
    if (!(kelvin > 0) || !std::isfinite(kelvin)) return {0, 0, 0};
    static const double y6500 = integrate(6500.0).y;
    return integrate(kelvin) / y6500;
}

RGB blackbodyRec709(double kelvin) {
    const Vec3 c = blackbodyXYZ(kelvin);
    const double r = 3.2404542 * c.x - 1.5371385 * c.y - 0.4985314 * c.z;
    const double g = -0.9692660 * c.x + 1.8760108 * c.y + 0.0415560 * c.z;
    const double b = 0.0556434 * c.x - 0.2040259 * c.y + 1.0572252 * c.z;
    return {float(std::max(0.0, r)), float(std::max(0.0, g)), float(std::max(0.0, b))};
}

}  // namespace lpm

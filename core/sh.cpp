#include "core/sh.h"

#include <cmath>

namespace lpm {

void shEval(const Vec3& d, double o[16]) {
    const double x = d.x, y = d.y, z = d.z;
    o[0] = kY00;
    o[1] = 0.48860251190291992 * y;
    o[2] = 0.48860251190291992 * z;
    o[3] = 0.48860251190291992 * x;
    o[4] = 1.0925484305920792 * x * y;
    o[5] = 1.0925484305920792 * y * z;
    o[6] = 0.31539156525252005 * (3 * z * z - 1);
    o[7] = 1.0925484305920792 * x * z;
    o[8] = 0.54627421529603959 * (x * x - y * y);
    o[9] = 0.59004358992664352 * y * (3 * x * x - y * y);
    o[10] = 2.8906114426405538 * x * y * z;
    o[11] = 0.45704579946446572 * y * (5 * z * z - 1);
    o[12] = 0.37317633259011546 * z * (5 * z * z - 3);
    o[13] = 0.45704579946446572 * x * (5 * z * z - 1);
    o[14] = 1.4453057213202769 * z * (x * x - y * y);
    o[15] = 0.59004358992664352 * x * (x * x - 3 * y * y);
}

static double legendre(int l, double x) {
    double p0 = 1, p1 = x;
    if (l == 0) return p0;
    for (int k = 2; k <= l; ++k) {
        const double p2 = ((2 * k - 1) * x * p1 - (k - 1) * p0) / k;
        p0 = p1;
        p1 = p2;
    }
    return p1;
}

double capBandFactor(int l, double halfAngle) {
    if (l == 0 || halfAngle <= 0) return 1.0;
    const double mu = std::cos(halfAngle);
    const double om = 1.0 - mu;
    if (om < 1e-12) return 1.0;
    return (legendre(l - 1, mu) - legendre(l + 1, mu)) / ((2 * l + 1) * om);
}

}  // namespace lpm

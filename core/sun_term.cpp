// Exact sun term (sun_term.h).
#include "core/sun_term.h"

#include <cmath>

#include "core/phase.h"
#include "core/sh.h"

namespace lpm {

double sunTermPhase(const SunTerm& t, double g, const Vec3& w) {
    return henyeyGreenstein(dot(-t.toSun, w), g);
}

void addSunTermSh(const SunTerm& t, double g, int order, float T, double sign, float* coeffs) {
    double y[16];
    shEval(-t.toSun, y);
    const double half = 0.5 * t.angularDiameterDeg * kPi / 180.0;
    for (int k = 0; k < shCount(order); ++k) {
        const int l = shBand(k);
        const double a = sign * double(T) * y[k] * std::pow(g, l) * capBandFactor(l, half);
        for (int c = 0; c < 3; ++c) coeffs[k * 3 + c] += float(a * t.irradiance[c]);
    }
}

}  // namespace lpm

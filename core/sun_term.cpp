// Exact sun term (sun_term.h).
#include "core/sun_term.h"

#include <cmath>

#include "core/parallel.h"
#include "core/phase.h"
#include "core/sh.h"

namespace lpm {

double sunTermPhase(const SunTerm& t, double g, const Vec3& w) { return henyeyGreenstein(dot(-t.toSun, w), g); }

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

void removeSunTermsFromSh(std::vector<float>& sh, int order, const std::vector<SunTerm>& terms, double g) {
    const size_t stride = size_t(shCount(order)) * 3;
    parallelForChunks(sh.size() / stride, 4096, [&](size_t b, size_t e) {
        for (size_t v = b; v < e; ++v)
            for (const SunTerm& t : terms) addSunTermSh(t, g, order, t.transmittance[v], -1.0, &sh[v * stride]);
    });
}

}  // namespace lpm

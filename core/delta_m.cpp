// Delta-M similarity transform (core/delta_m.h).
#include "core/delta_m.h"

#include <string>

namespace lpm {

Medium deltaMScaled(const Medium& m, double f) {
    if (!(f >= 0 && f < 1)) throw Error("LPM", "delta-M fraction must be in [0, 1), got " + std::to_string(f));
    if (!(m.albedo.r == m.albedo.g && m.albedo.g == m.albedo.b))
        throw Error("LPM", "delta-M needs a grey albedo (the scaled extinction would differ per channel)");
    const double g = m.g, c = m.albedo.r;
    Medium sm = m;
    const float k = float(1 - c * f);
    for (float& sg : sm.sigmaT) sg *= k;
    sm.albedo = RGB(float(c * (1 - f) / (1 - c * f)));
    sm.g = (g - f) / (1 - f);
    return sm;
}

}  // namespace lpm

// Delta-M forward-peak truncation (Wiscombe 1977, J. Atmos. Sci. 34) with f = g^4: the
// forward peak's share f of the Henyey-Greenstein phase function is treated as
// unscattered light. Similarity transform:
//   sigma_t' = sigma_t (1 - c f),  c' = c (1 - f) / (1 - c f),  g' = (g - f) / (1 - f)
// keeps sigma_a (so absorption and emission are unchanged) and the transport moments; the
// propagation then sees a moderate g' that its bins can resolve. S is still that of the
// true phase function: its SH are g^l times those of the radiance. g^4 measured best of
// g^2, g^4, g^6 against MC (docs/accuracy.md); g^2, the delta-Eddington choice, truncates
// too much of the broad lobes at moderate g for 24 bins. The planner decides when it
// applies (core/solve_plan.h): g > 0 and a grey albedo.
#pragma once

#include "core/medium.h"

namespace lpm {

/// The delta-M scaled copy of `m` for truncation fraction f in [0, 1); m's albedo must be grey.
Medium deltaMScaled(const Medium& m, double f);

}  // namespace lpm

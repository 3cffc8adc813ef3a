#include "baker/stop_warning.h"

#include "baker/text_format.h"

namespace lpm {

std::string stopWarning(const LpmResult& res, double tolerance) {
    if (res.converged) return {};
    // Which cap stopped it decides what helps: more orders, or (the two-grid solve's cycles
    // run out, docs/performance.md "Session 44") full resolution.
    const std::string hint = res.stoppedAtCycleCap
                                 ? " (the two-grid solve ran its cycles out, so more orders would not help; "
                                   "--multires off iterates every order at full resolution: slower, more memory)"
                                 : " (raise --max-orders)";
    // The signed residual may meet the tolerance while the absolute one does not.
    const bool signedMet = res.residual <= tolerance && res.absoluteResidual > res.absoluteLine;
    const std::string measure = signedMet ? " within --tolerance " + fmt(tolerance) + ", its absolute value " +
                                                fmt(res.absoluteResidual) + " above " + fmt(res.absoluteLine)
                                          : " above --tolerance " + fmt(tolerance);
    return "the solver stopped after " + std::to_string(res.passes.size()) + " passes with residual " +
           fmt(res.residual) + measure + hint;
}

}  // namespace lpm

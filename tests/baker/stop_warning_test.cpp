// baker/stop_warning: the unconverged bake's warning names the measure that stopped short
// and what would help.
#include "baker/stop_warning.h"

#include <gtest/gtest.h>

namespace lpm {
namespace {

LpmResult stoppedAfter(int passes, double residual) {
    LpmResult r;
    r.passes.resize(size_t(passes));
    r.residual = residual;
    return r;
}

TEST(StopWarning, NoneWhenConverged) {
    LpmResult r = stoppedAfter(12, 1e-4);
    r.converged = true;
    EXPECT_EQ(stopWarning(r, 1e-3), "");
}

TEST(StopWarning, OrderCapAsksForMoreOrders) {
    const LpmResult r = stoppedAfter(3, 0.049);
    EXPECT_EQ(stopWarning(r, 1e-4),
              "the solver stopped after 3 passes with residual 0.049 above --tolerance 0.0001 (raise --max-orders)");
}

TEST(StopWarning, CycleCapPointsAtFullResolution) {
    LpmResult r = stoppedAfter(293, 0.011);
    r.stoppedAtCycleCap = true;
    r.absoluteResidual = 0.0653;
    r.absoluteLine = 0.01;
    const std::string w = stopWarning(r, 1e-3);
    EXPECT_NE(w.find("with residual 0.011 above --tolerance 0.001 (the two-grid solve ran its cycles out"),
              std::string::npos)
        << w;
    EXPECT_EQ(w.find("absolute"), std::string::npos) << w;  // the signed residual is what fell short
}

// A residual that changes sign between voxels: its signed power met the tolerance, its
// absolute power did not (the 64^3 cloud at albedo 0.99 and voxel optical depth 4 of
// docs/multires.md, "Diffusion tail"). The warning must not say "above --tolerance".
TEST(StopWarning, SignedResidualWithinToleranceNamesTheAbsoluteOne) {
    LpmResult r = stoppedAfter(22, 1.46e-5);
    r.stoppedAtCycleCap = true;
    r.absoluteResidual = 0.0121;
    r.absoluteLine = 0.01;
    EXPECT_EQ(stopWarning(r, 1e-3),
              "the solver stopped after 22 passes with residual 1.46e-05 within --tolerance 0.001, its absolute value "
              "0.0121 above 0.01 (the two-grid solve ran its cycles out, so more orders would not help; --multires "
              "off iterates every order at full resolution: slower, more memory)");
}

}  // namespace
}  // namespace lpm

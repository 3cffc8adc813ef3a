// Black body: normalisation, the Planckian locus at known temperatures, monotonic growth.
#include "core/blackbody.h"

#include <gtest/gtest.h>

using namespace lpm;

TEST(Blackbody, NormalisedAt6500KAndOnThePlanckianLocus) {
    const Vec3 c = blackbodyXYZ(6500);
    EXPECT_NEAR(c.y, 1.0, 1e-12);
    const double s = c.x + c.y + c.z;
    // CIE 1931 chromaticity of a 6500 K Planckian radiator: (0.3135, 0.3237).
    EXPECT_NEAR(c.x / s, 0.3135, 0.003);
    EXPECT_NEAR(c.y / s, 0.3237, 0.003);
    // 2856 K (CIE illuminant A): (0.4476, 0.4074).
    const Vec3 a = blackbodyXYZ(2856);
    EXPECT_NEAR(a.x / (a.x + a.y + a.z), 0.4476, 0.003);
    EXPECT_NEAR(a.y / (a.x + a.y + a.z), 0.4074, 0.003);
}

TEST(Blackbody, HotterIsBrighterAndBluer) {
    double lastY = 0, lastRatio = 1e30;
    for (double t : {800.0, 1500.0, 3000.0, 6500.0, 12000.0}) {
        const Vec3 c = blackbodyXYZ(t);
        EXPECT_GT(c.y, lastY);
        const double ratio = c.x / (c.x + c.y + c.z);  // chromaticity x falls as T rises
        EXPECT_LT(ratio, lastRatio);
        const double y = c.y;
        lastY = y;
        lastRatio = ratio;
    }
    const RGB fire = blackbodyRec709(1500);
    EXPECT_GT(fire.r, fire.g);
    EXPECT_GE(fire.g, fire.b);
    EXPECT_EQ(blackbodyRec709(0).r, 0.0f);
    EXPECT_EQ(blackbodyRec709(-5).g, 0.0f);
}

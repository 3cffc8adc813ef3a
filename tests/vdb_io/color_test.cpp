// vdb_io/color and data/config.ocio: golden values, roles, aliases, $OCIO precedence.
#include "vdb_io/color.h"

#include <gtest/gtest.h>

#include <cstdlib>

#include "test_helpers.h"
#include "vdb_io/io_error.h"

using namespace lpm;

// Golden values from the ecosystem notes (Bradford-adapted Rec.709 -> AP1).
TEST(Color, Rec709RedToACEScgGolden) {
    std::vector<float> px{1, 0, 0};
    convertColor(px, "lin_rec709", "ACEScg");
    EXPECT_NEAR(px[0], 0.613097, 2e-5);
    EXPECT_NEAR(px[1], 0.070194, 2e-5);
    EXPECT_NEAR(px[2], 0.020616, 2e-5);
    // and back
    convertColor(px, "ACEScg", "lin_rec709");
    EXPECT_NEAR(px[0], 1, 1e-5);
    EXPECT_NEAR(px[1], 0, 1e-5);
    EXPECT_NEAR(px[2], 0, 1e-5);
}

TEST(Color, MidGreyToSrgbGolden) {
    std::vector<float> px{0.18f, 0.18f, 0.18f};
    convertColor(px, "lin_rec709", "sRGB");
    for (float v : px) EXPECT_NEAR(v, 0.461356, 2e-5);
    // The display view used for PNG previews encodes the same way (grey stays grey in any
    // linear space, so start from the working space).
    std::vector<float> d{0.18f, 0.18f, 0.18f};
    convertToDisplay(d, "ACEScg");
    for (float v : d) EXPECT_NEAR(v, 0.461356, 2e-4);
}

TEST(Color, RolesAndAliases) {
    EXPECT_EQ(canonicalColorSpace("scene_linear"), "ACEScg");
    EXPECT_EQ(canonicalColorSpace("Linear"), "lin_rec709");  // what OIIO reports for EXR
    EXPECT_EQ(canonicalColorSpace("linear"), "lin_rec709");  // ... and for HDR
    EXPECT_TRUE(colorSpaceKnown("sRGB"));
    EXPECT_FALSE(colorSpaceKnown("no_such_space"));
    lpmtest::expectThrowWith<InputError>([] { canonicalColorSpace("no_such_space"); },
                                         {"no_such_space", "ACEScg", "config.ocio"});
}

TEST(Color, OcioEnvironmentVariableWins) {
    const std::string dir = lpmtest::scratchDir();
    const std::string cfg = dir + "/studio.ocio";
    std::ofstream(cfg) << "ocio_profile_version: 2.1\n"
                          "roles:\n  default: studio_linear\n  scene_linear: studio_linear\n"
                          "displays:\n  sRGB:\n    - !<View> {name: Raw, colorspace: studio_linear}\n"
                          "colorspaces:\n  - !<ColorSpace>\n    name: studio_linear\n    isdata: false\n";
    ::setenv("OCIO", cfg.c_str(), 1);
    EXPECT_EQ(ocioConfigPath(), cfg);
    EXPECT_TRUE(colorSpaceKnown("studio_linear"));
    EXPECT_FALSE(colorSpaceKnown("ACEScg"));
    ::unsetenv("OCIO");
    EXPECT_NE(ocioConfigPath(), cfg);
    EXPECT_TRUE(colorSpaceKnown("ACEScg"));
}

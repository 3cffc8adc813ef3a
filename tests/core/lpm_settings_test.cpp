// The solver's settings validate themselves: every range rule throws SettingError naming
// the field, so a front end can name its own flag; the defaults are valid.
#include "core/lpm_settings.h"

#include <gtest/gtest.h>

#include <functional>

#include "core/error.h"
#include "core/medium.h"

using namespace lpm;

namespace {

/// The field a broken copy of the defaults is rejected for ("" when it is accepted).
std::string rejectedField(const std::function<void(LpmSettings&)>& breakIt) {
    LpmSettings s;
    breakIt(s);
    try {
        s.validate();
    } catch (const SettingError& e) {
        EXPECT_NE(std::string(e.what()).find(e.field()), std::string::npos);
        return e.field();
    }
    return "";
}

}  // namespace

TEST(LpmSettings, EachRuleNamesItsField) {
    EXPECT_EQ(rejectedField([](LpmSettings&) {}), "");
    EXPECT_EQ(rejectedField([](LpmSettings& s) { s.directionsPerFace = kMaxDirectionsPerFace + 1; }),
              "directionsPerFace");
    EXPECT_EQ(rejectedField([](LpmSettings& s) { s.directionsPerFace = 0; }), "directionsPerFace");
    EXPECT_EQ(rejectedField([](LpmSettings& s) { s.raysPerVoxel = 17; }), "raysPerVoxel");
    EXPECT_EQ(rejectedField([](LpmSettings& s) { s.raysHigherOrders = 0; }), "raysHigherOrders");
    EXPECT_EQ(rejectedField([](LpmSettings& s) { s.raysHigherOrders = -1; }), "");
    EXPECT_EQ(rejectedField([](LpmSettings& s) { s.directionsPerFace = 4, s.binsPerFace = 3; }), "binsPerFace");
    EXPECT_EQ(rejectedField([](LpmSettings& s) { s.shOrder = 4; }), "shOrder");
    EXPECT_EQ(rejectedField([](LpmSettings& s) { s.tolerance = 0; }), "tolerance");
    EXPECT_EQ(rejectedField([](LpmSettings& s) { s.tolerance = NAN; }), "tolerance");
    EXPECT_EQ(rejectedField([](LpmSettings& s) { s.maxOrders = 0; }), "maxOrders");
    EXPECT_EQ(rejectedField([](LpmSettings& s) { s.deltaMAbove = 1; }), "deltaMAbove");
    EXPECT_EQ(rejectedField([](LpmSettings& s) { s.envHotShare = 1.5; }), "envHotShare");
    EXPECT_EQ(rejectedField([](LpmSettings& s) { s.multiresAfter = 0; }), "multiresAfter");
    EXPECT_EQ(rejectedField([](LpmSettings& s) { s.subdivide = kMaxSubdivide + 1; }), "subdivide");
    EXPECT_EQ(rejectedField([](LpmSettings& s) { s.cycleSmoothing = 5; }), "cycleSmoothing");
    EXPECT_EQ(rejectedField([](LpmSettings& s) { s.diffusionTail = 2; }), "diffusionTail");
    EXPECT_EQ(rejectedField([](LpmSettings& s) { s.extrapolationTolerance = -1; }), "extrapolationTolerance");
    EXPECT_EQ(rejectedField([](LpmSettings& s) { s.extrapolationTolerance = INFINITY; }), "extrapolationTolerance");
}

TEST(LpmSettings, MaterialAndSunsNameTheirFields) {
    auto field = [](const std::function<void()>& f) {
        try {
            f();
        } catch (const SettingError& e) {
            return e.field();
        }
        return std::string();
    };
    EXPECT_EQ(field([] { validateMaterial(RGB(0.5f, 1.2f, 0.5f), 0); }), "albedo");
    EXPECT_EQ(field([] { validateMaterial(RGB(0.5f), 1.0); }), "g");
    EXPECT_EQ(field([] { validateMaterial(RGB(1.f), -0.99); }), "");
    EXPECT_EQ(field([] { Sun{Vec3(0, 0, 0), RGB(1.f), 0.5}.validate(); }), "toSun");
    EXPECT_EQ(field([] { Sun{Vec3(0, 1, 0), RGB(-1.f), 0.5}.validate(); }), "irradiance");
    EXPECT_EQ(field([] { Sun{Vec3(0, 1, 0), RGB(1.f), 180}.validate(); }), "angularDiameterDeg");
}

// --quality presets (baker/quality.h): what each sets, that explicit knobs override it, and
// that each reaches its documented error on a real smoke (data/vdb/densityAndHeat.vdb,
// g = 0.6), measured by --verify (docs/verify.md).
#include "baker/quality.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "../vdb_io/test_helpers.h"
#include "core/error.h"
#include "run_helpers.h"
#include "vdb_io/bake_file.h"

using namespace lpm;
using lpmtest::dataPath;
using lpmtest::runLpmbake;

TEST(Quality, PresetsSetTheirKnobsUnlessGiven) {
    LpmSettings s;
    applyQuality("preview", s, {});
    EXPECT_EQ(s.directionsPerFace, 2);
    EXPECT_EQ(s.raysPerVoxel, 1);
    EXPECT_EQ(s.tolerance, 1e-2);
    EXPECT_EQ(s.multires, -1);
    LpmSettings p;
    p.directionsPerFace = 3;
    applyQuality("production", p, {"--directions-per-face"});
    EXPECT_EQ(p.directionsPerFace, 3);
    EXPECT_EQ(p.tolerance, 1e-4);
    EXPECT_EQ(p.multires, -1);
    // "default" is the library's defaults.
    LpmSettings d;
    applyQuality("default", d, {});
    const LpmSettings plain;
    EXPECT_EQ(d.directionsPerFace, plain.directionsPerFace);
    EXPECT_EQ(d.raysPerVoxel, plain.raysPerVoxel);
    EXPECT_EQ(d.tolerance, plain.tolerance);
    EXPECT_EQ(d.multires, plain.multires);
    EXPECT_THROW(applyQuality("best", d, {}), SettingError);
}

TEST(Quality, EachPresetReachesItsErrorOnARealSmoke) {
    const std::string dir = lpmtest::scratchDir();
    struct Expect {
        std::string preset;
        double maxHigh;  ///< the documented error: the estimate's 95% interval must lie below it
        int directions;
    };
    // docs/accuracy.md: preview about 5%, default 1-2%, production within 1%.
    double lastError = 1e9;
    for (const Expect& e : {Expect{"preview", 0.075, 2}, Expect{"default", 0.025, 4}, Expect{"production", 0.015, 6}}) {
        const std::string out = dir + "/" + e.preset + ".vdb", stats = dir + "/" + e.preset + ".json";
        const auto r = runLpmbake(
            {dataPath("vdb/densityAndHeat.vdb"), "--env", dataPath("env/rooftop_small.hdr"), "--g", "0.6",
             "--density-scale", "2", "--quality", e.preset, "--verify", "64", "--stats", stats, "-q", "-o", out},
            dir);
        ASSERT_EQ(r.code, 0) << r.err;
        const BakeFile b = readBakeFile(out);
        EXPECT_EQ(metaString(*b.meta, "lpm:quality"), e.preset);
        EXPECT_EQ(metaInt(*b.meta, "lpm:directions_per_face", 0), e.directions);
        const auto v = nlohmann::json::parse(lpmtest::readAll(stats))["verify"];
        EXPECT_LT(v["high"].get<double>(), e.maxHigh) << e.preset << " estimate " << v["error"];
        EXPECT_LT(v["error"].get<double>(), lastError) << e.preset;
        lastError = v["error"].get<double>();
        std::printf("%s: verify %.4f [%.4f, %.4f], solve %.2f s\n", e.preset.c_str(), v["error"].get<double>(),
                    v["low"].get<double>(), v["high"].get<double>(),
                    nlohmann::json::parse(lpmtest::readAll(stats))["timings_s"]["solve"].get<double>());
    }
    // An explicit knob overrides the preset.
    const auto r = runLpmbake({dataPath("vdb/densityAndHeat.vdb"), "--env", dataPath("env/rooftop_small.hdr"),
                               "--quality", "preview", "--directions-per-face", "3", "-q", "-o", dir + "/x.vdb"},
                              dir);
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(metaInt(*readBakeFile(dir + "/x.vdb").meta, "lpm:directions_per_face", 0), 3);
    EXPECT_EQ(metaDouble(*readBakeFile(dir + "/x.vdb").meta, "lpm:tolerance", 0), 1e-2);
    const auto bad = runLpmbake({dataPath("vdb/densityAndHeat.vdb"), "--env", dataPath("env/rooftop_small.hdr"),
                                 "--quality", "best", "-o", dir + "/y.vdb"},
                                dir);
    EXPECT_EQ(bad.code, 1);
    EXPECT_NE(bad.err.find("--quality"), std::string::npos) << bad.err;
}

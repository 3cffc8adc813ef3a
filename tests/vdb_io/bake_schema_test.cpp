// The bake metadata schema: typed writers refuse a key of another type, readers fall back
// on absent or mistyped keys, and schemaProblems names what a bake lacks.
#include "vdb_io/bake_schema.h"

#include <gtest/gtest.h>

#include <set>
#include <stdexcept>

using namespace lpm;

TEST(BakeSchema, TypedWritersAndReadersRoundTrip) {
    openvdb::MetaMap m;
    putDouble(m, bakekey::densityScale, 2.5);
    putVec3(m, bakekey::albedo, 0.1, 0.2, 0.3);
    putInt(m, bakekey::shOrder, 2);
    putString(m, bakekey::upAxis, "z");
    putBool(m, bakekey::rendererGrids, true);
    EXPECT_EQ(getDouble(m, bakekey::densityScale, 0), 2.5);
    EXPECT_FLOAT_EQ(getRgb(m, bakekey::albedo, RGB(0.f)).g, 0.2f);
    EXPECT_EQ(getInt(m, bakekey::shOrder, -1), 2);
    EXPECT_EQ(getString(m, bakekey::upAxis), "z");
    EXPECT_TRUE(getBool(m, bakekey::rendererGrids, false));
    EXPECT_EQ(getDouble(m, bakekey::g, -7), -7) << "absent: the fallback";
    EXPECT_THROW(putInt(m, bakekey::densityScale, 1), std::logic_error);
    EXPECT_THROW(putString(m, bakekey::albedo, "grey"), std::logic_error);
    m.insertMeta("lpm:g", openvdb::StringMetadata("0.5"));
    EXPECT_EQ(getDouble(m, bakekey::g, -7), -7) << "mistyped: the fallback";
    EXPECT_FALSE(hasKey(m, bakekey::g));
}

TEST(BakeSchema, KeysAreUniqueAndNamedLpm) {
    std::set<std::string> seen;
    for (const MetaKey& k : bakeSchema()) {
        EXPECT_EQ(k.name.rfind("lpm:", 0), 0u) << k.name;
        EXPECT_TRUE(seen.insert(k.name).second) << k.name << " twice";
    }
    EXPECT_GT(seen.size(), 60u);
    EXPECT_EQ(sunTermKey(3, SunTermField::Irradiance).name, "lpm:sun_term_3_irradiance");
    EXPECT_EQ(sunTermKey(0, SunTermField::Grid).type, MetaType::String);
}

TEST(BakeSchema, ProblemsNameMissingAndMistypedKeys) {
    openvdb::MetaMap m;
    putInt(m, bakekey::formatVersion, 2);
    auto joined = [](const std::vector<std::string>& v) {
        std::string s;
        for (const auto& x : v) s += x + "\n";
        return s;
    };
    const std::string loose = joined(schemaProblems(m, false));
    EXPECT_NE(loose.find("no lpm:density_scale metadata (double)"), std::string::npos) << loose;
    EXPECT_EQ(loose.find("lpm:passes"), std::string::npos) << "not a shader key: only checked when complete";
    EXPECT_NE(joined(schemaProblems(m, true)).find("no lpm:passes metadata"), std::string::npos);
    m.insertMeta("lpm:density_scale", openvdb::StringMetadata("1"));
    EXPECT_NE(joined(schemaProblems(m, false)).find("lpm:density_scale is string, not double"), std::string::npos);
    // A sun term needs its fields.
    putInt(m, bakekey::sunTermCount, 1);
    const std::string sun = joined(schemaProblems(m, false));
    EXPECT_NE(sun.find("no lpm:sun_term_0_toward"), std::string::npos) << sun;
    EXPECT_NE(sun.find("no lpm:sun_term_g"), std::string::npos) << sun;
}

TEST(BakeSchema, ShaderParamsReadTheKeys) {
    openvdb::MetaMap m;
    putDouble(m, bakekey::densityScale, 3);
    putString(m, bakekey::upAxis, "z");
    putInt(m, bakekey::sunTermCount, 1);
    putVec3(m, sunTermKey(0, SunTermField::Toward), 0, 0, 2);
    putVec3(m, sunTermKey(0, SunTermField::Irradiance), 1, 2, 3);
    putString(m, sunTermKey(0, SunTermField::Grid), "sun_transmittance_0");
    const ShaderParams p = readShaderParams(m);
    EXPECT_EQ(p.densityScale, 3);
    EXPECT_EQ(p.up, UpAxis::Z);
    ASSERT_EQ(p.sunTerms.size(), 1u);
    EXPECT_DOUBLE_EQ(p.sunTerms[0].toward.z, 1.0) << "normalised";
    EXPECT_FLOAT_EQ(p.sunTerms[0].irradiance.b, 3.f);
    EXPECT_EQ(readShaderParams(openvdb::MetaMap()).up, UpAxis::Y) << "absent up axis: y";
}

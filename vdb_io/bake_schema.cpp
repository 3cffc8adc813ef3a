// The bake's metadata schema (bake_schema.h).
#include "vdb_io/bake_schema.h"

#include <stdexcept>

namespace lpm {

const char* metaTypeName(MetaType t) {
    switch (t) {
        case MetaType::String:
            return "string";
        case MetaType::Double:
            return "double";
        case MetaType::Int:
            return "int32";
        case MetaType::Int64:
            return "int64";
        case MetaType::Bool:
            return "bool";
        case MetaType::Vec3d:
            return "vec3d";
        case MetaType::Vec3i:
            return "vec3i";
    }
    return "?";
}

MetaKey sunTermKey(int k, SunTermField f) {
    static const char* fields[] = {"toward", "irradiance", "angle_deg", "source", "grid"};
    static const MetaType types[] = {MetaType::Vec3d, MetaType::Vec3d, MetaType::Double, MetaType::String,
                                     MetaType::String};
    return MetaKey{"lpm:sun_term_" + std::to_string(k) + "_" + fields[int(f)], types[int(f)], true,
                   f != SunTermField::Source, ""};
}

const std::vector<MetaKey>& bakeSchema() {
    using namespace bakekey;
    static const std::vector<MetaKey> all = {formatVersion,
                                             version,
                                             shOrder,
                                             shCount,
                                             shBasis,
                                             shGrids,
                                             shNegativeLobes,
                                             quantity,
                                             usage,
                                             units,
                                             frame,
                                             upAxis,
                                             workingColorspace,
                                             densityGrid,
                                             densityScale,
                                             albedo,
                                             g,
                                             phaseFunction,
                                             rendererGrids,
                                             envFile,
                                             envColorspace,
                                             envRotateYDeg,
                                             envScale,
                                             envOrientation,
                                             sunCount,
                                             suns,
                                             temperatureGrid,
                                             temperatureScale,
                                             temperatureOffset,
                                             temperatureIntensity,
                                             temperatureConvention,
                                             emissionGrid,
                                             emissionScale,
                                             emissionConvention,
                                             lights,
                                             quality,
                                             directionsPerFace,
                                             raysPerVoxel,
                                             raysHigherOrders,
                                             binsPerFace,
                                             tolerance,
                                             maxOrders,
                                             subdivide,
                                             multires,
                                             multiresAfter,
                                             separableSources,
                                             sourceShape,
                                             deltaM,
                                             envHotShare,
                                             solveScale,
                                             solveGridDims,
                                             solveVoxelSize,
                                             krylov,
                                             solver,
                                             passes,
                                             residual,
                                             converged,
                                             decisions,
                                             inputFile,
                                             inputGrid,
                                             inputGridIndex,
                                             empty,
                                             sanitizedValues,
                                             storage,
                                             timeReadS,
                                             timeEnvS,
                                             timeSolveS,
                                             timings,
                                             commandLine,
                                             settings,
                                             settingsDigest,
                                             sunTermCount,
                                             sunTermG,
                                             sunTermConvention,
                                             verifyError,
                                             verifyErrorLow,
                                             verifyErrorHigh,
                                             verifyConfidence,
                                             verifyProbes,
                                             verifyPaths,
                                             verifyNoise,
                                             verifySeconds,
                                             verifyMaxError,
                                             verifyFailed};
    return all;
}

namespace {

void expectType(const MetaKey& k, MetaType t) {
    if (k.type != t)
        throw std::logic_error("metadata key " + std::string(k.name) + " is " + metaTypeName(k.type) + ", written as " +
                               metaTypeName(t));
}

const std::string& name(const MetaKey& k) { return k.name; }

}  // namespace

void putString(openvdb::MetaMap& m, const MetaKey& k, const std::string& v) {
    expectType(k, MetaType::String);
    m.insertMeta(name(k), openvdb::StringMetadata(v));
}
void putDouble(openvdb::MetaMap& m, const MetaKey& k, double v) {
    expectType(k, MetaType::Double);
    m.insertMeta(name(k), openvdb::DoubleMetadata(v));
}
void putInt(openvdb::MetaMap& m, const MetaKey& k, int v) {
    expectType(k, MetaType::Int);
    m.insertMeta(name(k), openvdb::Int32Metadata(v));
}
void putInt64(openvdb::MetaMap& m, const MetaKey& k, std::int64_t v) {
    expectType(k, MetaType::Int64);
    m.insertMeta(name(k), openvdb::Int64Metadata(openvdb::Int64(v)));
}
void putBool(openvdb::MetaMap& m, const MetaKey& k, bool v) {
    expectType(k, MetaType::Bool);
    m.insertMeta(name(k), openvdb::BoolMetadata(v));
}
void putVec3(openvdb::MetaMap& m, const MetaKey& k, double x, double y, double z) {
    expectType(k, MetaType::Vec3d);
    m.insertMeta(name(k), openvdb::Vec3DMetadata(openvdb::Vec3d(x, y, z)));
}
void putVec3i(openvdb::MetaMap& m, const MetaKey& k, int x, int y, int z) {
    expectType(k, MetaType::Vec3i);
    m.insertMeta(name(k), openvdb::Vec3IMetadata(openvdb::Vec3i(x, y, z)));
}

std::string getString(const openvdb::MetaMap& m, const MetaKey& k, const std::string& fallback) {
    if (auto s = m.getMetadata<openvdb::StringMetadata>(name(k))) return s->value();
    return fallback;
}
double getDouble(const openvdb::MetaMap& m, const MetaKey& k, double fallback) {
    if (auto d = m.getMetadata<openvdb::DoubleMetadata>(name(k))) return d->value();
    if (auto f = m.getMetadata<openvdb::FloatMetadata>(name(k))) return f->value();
    return fallback;
}
int getInt(const openvdb::MetaMap& m, const MetaKey& k, int fallback) {
    if (auto i = m.getMetadata<openvdb::Int32Metadata>(name(k))) return i->value();
    return fallback;
}
bool getBool(const openvdb::MetaMap& m, const MetaKey& k, bool fallback) {
    if (auto b = m.getMetadata<openvdb::BoolMetadata>(name(k))) return b->value();
    return fallback;
}
Vec3 getVec3(const openvdb::MetaMap& m, const MetaKey& k, const Vec3& fallback) {
    if (auto v = m.getMetadata<openvdb::Vec3DMetadata>(name(k)))
        return {v->value().x(), v->value().y(), v->value().z()};
    return fallback;
}
RGB getRgb(const openvdb::MetaMap& m, const MetaKey& k, const RGB& fallback) {
    if (!hasKey(m, k)) return fallback;
    const Vec3 v = getVec3(m, k, {});
    return RGB(float(v.x), float(v.y), float(v.z));
}

bool hasKey(const openvdb::MetaMap& m, const MetaKey& k) {
    switch (k.type) {
        case MetaType::String:
            return bool(m.getMetadata<openvdb::StringMetadata>(name(k)));
        case MetaType::Double:
            return bool(m.getMetadata<openvdb::DoubleMetadata>(name(k)));
        case MetaType::Int:
            return bool(m.getMetadata<openvdb::Int32Metadata>(name(k)));
        case MetaType::Int64:
            return bool(m.getMetadata<openvdb::Int64Metadata>(name(k)));
        case MetaType::Bool:
            return bool(m.getMetadata<openvdb::BoolMetadata>(name(k)));
        case MetaType::Vec3d:
            return bool(m.getMetadata<openvdb::Vec3DMetadata>(name(k)));
        case MetaType::Vec3i:
            return bool(m.getMetadata<openvdb::Vec3IMetadata>(name(k)));
    }
    return false;
}

std::vector<std::string> schemaProblems(const openvdb::MetaMap& m, bool complete) {
    std::vector<std::string> why;
    auto check = [&](const MetaKey& k, bool required) {
        if (hasKey(m, k)) return;
        if (m[name(k)]) why.push_back(name(k) + " is " + m[name(k)]->typeName() + ", not " + metaTypeName(k.type));
        else if (required) why.push_back("no " + name(k) + " metadata (" + metaTypeName(k.type) + ")");
    };
    for (const MetaKey& k : bakeSchema()) check(k, k.required && (complete || k.shader));
    const int suns = getInt(m, bakekey::sunTermCount, 0);
    for (int s = 0; s < suns; ++s)
        for (SunTermField f : {SunTermField::Toward, SunTermField::Irradiance, SunTermField::Grid})
            check(sunTermKey(s, f), true);
    if (suns > 0) check(bakekey::sunTermG, true);
    return why;
}

ShaderParams readShaderParams(const openvdb::MetaMap& m) {
    using namespace bakekey;
    ShaderParams p;
    p.formatVersion = getInt(m, formatVersion, 0);
    p.densityGrid = getString(m, densityGrid, "density");
    p.densityScale = getDouble(m, densityScale, 1.0);
    p.albedo = getRgb(m, albedo, p.albedo);
    p.g = getDouble(m, g, 0.0);
    p.shOrder = getInt(m, shOrder, 0);
    p.workingColorspace = getString(m, workingColorspace, "ACEScg");
    p.up = getString(m, upAxis, "y") == "z" ? UpAxis::Z : UpAxis::Y;
    p.envRotateYDeg = getDouble(m, envRotateYDeg, 0.0);
    p.envScale = getDouble(m, envScale, 1.0);
    p.rendererGrids = getBool(m, rendererGrids, false);
    p.sunTermG = getDouble(m, sunTermG, 0.0);
    const int n = getInt(m, sunTermCount, 0);
    for (int k = 0; k < n; ++k) {
        ShaderSun s;
        const Vec3 t = getVec3(m, sunTermKey(k, SunTermField::Toward), {0, 1, 0});
        s.toward = length(t) > 0 ? normalize(t) : Vec3(0, 1, 0);
        s.irradiance = getRgb(m, sunTermKey(k, SunTermField::Irradiance), RGB(0.f));
        s.angleDeg = getDouble(m, sunTermKey(k, SunTermField::AngleDeg), 0.0);
        s.grid = getString(m, sunTermKey(k, SunTermField::Grid), "");
        p.sunTerms.push_back(s);
    }
    return p;
}

}  // namespace lpm

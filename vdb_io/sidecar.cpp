// Sidecar JSON of a bake (sidecar.h).
#include "vdb_io/sidecar.h"

#include <cmath>

#include "vdb_io/atomic_file.h"
#include "vdb_io/bake_schema.h"

namespace lpm {

namespace {

using nlohmann::json;

json number(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }

/// One metadata value as JSON; null for a type a bake does not write.
json metaValue(const openvdb::Metadata& m) {
    if (const auto* s = dynamic_cast<const openvdb::StringMetadata*>(&m)) return s->value();
    if (const auto* d = dynamic_cast<const openvdb::DoubleMetadata*>(&m)) return number(d->value());
    if (const auto* f = dynamic_cast<const openvdb::FloatMetadata*>(&m)) return number(f->value());
    if (const auto* i = dynamic_cast<const openvdb::Int32Metadata*>(&m)) return i->value();
    if (const auto* l = dynamic_cast<const openvdb::Int64Metadata*>(&m)) return l->value();
    if (const auto* b = dynamic_cast<const openvdb::BoolMetadata*>(&m)) return b->value();
    if (const auto* v = dynamic_cast<const openvdb::Vec3DMetadata*>(&m))
        return json::array({number(v->value().x()), number(v->value().y()), number(v->value().z())});
    if (const auto* v = dynamic_cast<const openvdb::Vec3IMetadata*>(&m))
        return json::array({v->value().x(), v->value().y(), v->value().z()});
    return nullptr;
}

json shaderBlock(const openvdb::MetaMap& meta) {
    json shader = json::object();
    for (const MetaKey& k : bakeSchema()) {
        if (!k.shader || !hasKey(meta, k)) continue;
        shader[k.name.substr(4)] = metaValue(*meta[k.name]);  // without "lpm:"
    }
    if (!shader.contains("up_axis")) shader["up_axis"] = "y";
    json suns = json::array();
    const int n = getInt(meta, bakekey::sunTermCount, 0);
    for (int s = 0; s < n; ++s) {
        json t = json::object();
        const size_t prefix = std::string("lpm:sun_term_" + std::to_string(s) + "_").size();
        for (SunTermField f :
             {SunTermField::Grid, SunTermField::Toward, SunTermField::Irradiance, SunTermField::AngleDeg}) {
            const MetaKey k = sunTermKey(s, f);
            if (hasKey(meta, k)) t[k.name.substr(prefix)] = metaValue(*meta[k.name]);
        }
        suns.push_back(t);
    }
    shader["sun_terms"] = suns;
    return shader;
}

}  // namespace

json sidecarJson(const std::string& bakePath, const std::vector<std::string>& grids, const openvdb::MetaMap& meta) {
    json j = json::object();
    const size_t slash = bakePath.find_last_of('/');
    j["bake"] = slash == std::string::npos ? bakePath : bakePath.substr(slash + 1);
    j["format_version"] = getInt(meta, bakekey::formatVersion, 0);
    j["grids"] = grids;
    j["shader"] = shaderBlock(meta);
    json all = json::object();
    for (auto it = meta.beginMeta(); it != meta.endMeta(); ++it)
        if (it->first.rfind("lpm:", 0) == 0 && !metaValue(*it->second).is_null())
            all[it->first] = metaValue(*it->second);
    j["metadata"] = all;
    return j;
}

void writeSidecar(const std::string& path, const std::string& bakePath, const std::vector<std::string>& grids,
                  const openvdb::MetaMap& meta, const std::vector<std::string>& protect) {
    writeTextFileAtomically("sidecar", path, sidecarJson(bakePath, grids, meta).dump(2) + "\n", protect);
}

}  // namespace lpm

// Sidecar JSON of a bake (sidecar.h).
#include "baker/sidecar.h"

#include <cmath>
#include <fstream>
#include <sstream>

#include "baker/text_format.h"
#include "vdb_io/atomic_file.h"
#include "vdb_io/io_error.h"

namespace lpm {

namespace {

std::string number(double v) { return std::isfinite(v) ? fmtExact(v) : "null"; }

/// One metadata value as JSON, or "" for a type a bake does not write.
std::string jsonValue(const openvdb::Metadata& m) {
    if (const auto* s = dynamic_cast<const openvdb::StringMetadata*>(&m)) return "\"" + jsonEscape(s->value()) + "\"";
    if (const auto* d = dynamic_cast<const openvdb::DoubleMetadata*>(&m)) return number(d->value());
    if (const auto* f = dynamic_cast<const openvdb::FloatMetadata*>(&m)) return number(f->value());
    if (const auto* i = dynamic_cast<const openvdb::Int32Metadata*>(&m)) return std::to_string(i->value());
    if (const auto* l = dynamic_cast<const openvdb::Int64Metadata*>(&m)) return std::to_string(l->value());
    if (const auto* b = dynamic_cast<const openvdb::BoolMetadata*>(&m)) return b->value() ? "true" : "false";
    if (const auto* v = dynamic_cast<const openvdb::Vec3DMetadata*>(&m))
        return "[" + number(v->value().x()) + ", " + number(v->value().y()) + ", " + number(v->value().z()) + "]";
    if (const auto* v = dynamic_cast<const openvdb::Vec3IMetadata*>(&m))
        return "[" + std::to_string(v->value().x()) + ", " + std::to_string(v->value().y()) + ", " +
               std::to_string(v->value().z()) + "]";
    return "";
}

}  // namespace

std::string metadataJson(const openvdb::MetaMap& meta, const std::string& indent) {
    std::ostringstream j;
    j << "{";
    bool first = true;
    for (auto it = meta.beginMeta(); it != meta.endMeta(); ++it) {
        if (it->first.rfind("lpm:", 0) != 0) continue;
        const std::string v = jsonValue(*it->second);
        if (v.empty()) continue;
        j << (first ? "\n" : ",\n") << indent << "  \"" << jsonEscape(it->first) << "\": " << v;
        first = false;
    }
    j << "\n" << indent << "}";
    return j.str();
}

void writeSidecar(const std::string& path, const std::string& bakePath, const std::vector<std::string>& grids,
                  const openvdb::MetaMap& meta, const std::vector<std::string>& protect) {
    std::ostringstream j;
    const size_t slash = bakePath.find_last_of('/');
    j << "{\n  \"bake\": \"" << jsonEscape(slash == std::string::npos ? bakePath : bakePath.substr(slash + 1))
      << "\",\n  \"grids\": [";
    for (size_t i = 0; i < grids.size(); ++i) j << (i ? ", " : "") << "\"" << jsonEscape(grids[i]) << "\"";
    j << "],\n  \"metadata\": " << metadataJson(meta, "  ") << "\n}\n";
    AtomicOutput out(path, protect);
    {
        std::ofstream f(out.tempPath());
        f << j.str();
        f.close();
        if (!f) throw OutputError("sidecar", "cannot write '" + out.tempPath() + "'");
    }
    out.commit();
}

}  // namespace lpm

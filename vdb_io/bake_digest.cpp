// Content digest of a bake (bake_digest.h).
#include "vdb_io/bake_digest.h"

#include <cstdio>
#include <sstream>

#include "vdb_io/io_error.h"

namespace lpm {

namespace {

struct Digest {
    std::uint64_t h = 0xcbf29ce484222325ull;
    void bytes(const void* p, size_t n) { h = fnv1a(p, n, h); }
    void text(const std::string& s) {
        const std::uint64_t n = s.size();
        bytes(&n, sizeof n);
        bytes(s.data(), s.size());
    }
    template <typename T>
    void value(const T& v) {
        bytes(&v, sizeof v);
    }
};

template <typename GridT>
void addActiveValues(Digest& d, const GridT& grid) {
    for (auto it = grid.cbeginValueOn(); it; ++it) {
        const openvdb::CoordBBox b = it.getBoundingBox();  // one voxel, or a tile
        d.value(b.min().x()), d.value(b.min().y()), d.value(b.min().z());
        d.value(b.max().x()), d.value(b.max().y()), d.value(b.max().z());
        const auto v = *it;
        d.value(v);
    }
}

void addGrid(Digest& d, const openvdb::GridBase& g, const std::string& path) {
    d.text(g.getName());
    d.text(g.valueType());
    d.text(openvdb::GridBase::gridClassToString(g.getGridClass()));
    const openvdb::Mat4d m = g.transform().baseMap()->getAffineMap()->getMat4();
    for (int r = 0; r < 4; ++r)
        for (int c = 0; c < 4; ++c) d.value(m(r, c));
    if (const auto* f = dynamic_cast<const openvdb::FloatGrid*>(&g)) addActiveValues(d, *f);
    else if (const auto* v = dynamic_cast<const openvdb::Vec3SGrid*>(&g)) addActiveValues(d, *v);
    else
        throw InputError("digest", "'" + path + "': grid '" + g.getName() + "' of type " + g.valueType() +
                                       " is not one a bake holds");
}

}  // namespace

std::uint64_t fnv1a(const void* data, size_t bytes, std::uint64_t h) {
    const auto* p = static_cast<const unsigned char*>(data);
    for (size_t i = 0; i < bytes; ++i) {
        h ^= p[i];
        h *= 0x100000001b3ull;
    }
    return h;
}

bool isVolatileBakeMeta(const std::string& key) {
    return key.rfind("lpm:time_", 0) == 0 || key == "lpm:timings" || key == "lpm:command_line";
}

std::uint64_t bakeContentDigest(const BakeFile& f) {
    Digest d;
    // MetaMap is ordered by key; Metadata::write gives the exact bytes of each value.
    for (auto it = f.meta->beginMeta(); it != f.meta->endMeta(); ++it) {
        if (isVolatileBakeMeta(it->first)) continue;
        d.text(it->first);
        d.text(it->second->typeName());
        std::ostringstream bytes;
        it->second->write(bytes);
        d.text(bytes.str());
    }
    for (const auto& g : f.grids) addGrid(d, *g, f.path);
    return d.h;
}

std::string hex64(std::uint64_t v) {
    char buf[17];
    std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(v));
    return buf;
}

}  // namespace lpm

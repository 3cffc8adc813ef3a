// `lpmbake info BAKED.vdb`: grids, metadata, value ranges and NaN counts of a bake, and
// whether it is a valid one (exit 0) or not (exit 2).
#include <cmath>
#include <iomanip>
#include <iostream>
#include <limits>
#include <ostream>

#include "baker/options.h"
#include "vdb_io/bake_digest.h"
#include "vdb_io/bake_file.h"

namespace lpm {

namespace {

struct Range {
    double lo[3], hi[3];
    std::uint64_t nonFinite = 0, count = 0;
    int channels = 1;
    Range() {
        for (int c = 0; c < 3; ++c) lo[c] = std::numeric_limits<double>::infinity(), hi[c] = -lo[c];
    }
    void add(int c, double v) {
        if (!std::isfinite(v)) return;
        lo[c] = std::min(lo[c], v);
        hi[c] = std::max(hi[c], v);
    }
};

template <typename GridT, typename F>
Range scan(const GridT& g, int channels, F get) {
    Range r;
    r.channels = channels;
    for (auto it = g.cbeginValueOn(); it; ++it) {
        bool bad = false;
        for (int c = 0; c < channels; ++c) {
            const double v = get(*it, c);
            if (!std::isfinite(v)) bad = true;
            r.add(c, v);
        }
        const std::uint64_t n = it.isVoxelValue() ? 1 : it.getBoundingBox().volume();
        r.count += n;
        if (bad) r.nonFinite += n;
    }
    return r;
}

}  // namespace

int runInfo(const InfoOptions& o, std::ostream& out, const Log& log) {
    if (o.bake.empty()) throw UsageError("info: no file given");
    BakeFile f = readBakeFile(o.bake);  // throws InputError for unreadable files
    if (o.digest) {
        const std::vector<std::string> problems = validateBake(f);
        if (!problems.empty()) {
            std::cerr << "lpmbake: error: info: '" << o.bake << "' is not a valid lpmbake bake: " << problems.front()
                      << "\n";
            return kExitInput;
        }
        out << hex64(bakeContentDigest(f)) << "\n";
        return kExitOk;
    }
    out << "file: " << o.bake << "\n";
    out << "grids: " << f.grids.size() << "\n";
    std::uint64_t nonFinite = 0;
    out << std::setprecision(6);
    for (const auto& g : f.grids) {
        out << "  " << g->getName() << ": " << g->valueType() << ", class "
            << openvdb::GridBase::gridClassToString(g->getGridClass());
        out << ", vector type " << openvdb::GridBase::vecTypeToString(g->getVectorType());
        const openvdb::Vec3d vs = g->voxelSize();
        out << ", voxel size " << vs.x() << " x " << vs.y() << " x " << vs.z();
        out << ", " << g->activeVoxelCount() << " active voxels";
        if (g->activeVoxelCount() > 0) {
            const openvdb::CoordBBox b = g->evalActiveVoxelBoundingBox();
            out << ", index bbox " << b.min() << ".." << b.max();
        }
        Range r;
        bool ranged = true;
        if (auto fg = openvdb::gridPtrCast<openvdb::FloatGrid>(g))
            r = scan(*fg, 1, [](float v, int) { return double(v); });
        else if (auto vg = openvdb::gridPtrCast<openvdb::Vec3SGrid>(g))
            r = scan(*vg, 3, [](const openvdb::Vec3s& v, int c) { return double(v[c]); });
        else ranged = false;
        if (ranged && r.count > 0) {
            out << ", range";
            for (int c = 0; c < r.channels; ++c) out << (c ? " / " : " ") << "[" << r.lo[c] << ", " << r.hi[c] << "]";
        }
        if (ranged) out << ", NaN/Inf voxels " << r.nonFinite;
        out << "\n";
        nonFinite += r.nonFinite;
    }
    out << "metadata:\n";
    for (auto it = f.meta->beginMeta(); it != f.meta->endMeta(); ++it)
        out << "  " << it->first << " = " << it->second->str() << "\n";

    std::vector<std::string> problems = validateBake(f);
    if (nonFinite > 0) problems.push_back(std::to_string(nonFinite) + " voxel(s) hold NaN or infinite values");
    if (problems.empty()) {
        out << "valid lpmbake bake: yes\n";
        return kExitOk;
    }
    out << "valid lpmbake bake: no\n";
    for (const auto& p : problems) out << "  problem: " << p << "\n";
    // Not a crash, but the command failed: the one-line error format of every other failure.
    std::cerr << "lpmbake: error: info: '" << o.bake << "' is not a valid lpmbake bake: " << problems.front() << "\n";
    return kExitInput;
}

}  // namespace lpm

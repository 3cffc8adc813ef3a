// Compares the grids of two bakes value by value: what `lpmbake info --digest` cannot say
// when only the metadata differs (the digest covers the decisions' text too). Per grid:
// active values, how many differ (or are active in one file only), the largest absolute
// difference and the relative L1 difference sum|a - b| / sum|a|.
//   lpm_compare_bakes A.vdb B.vdb
// Exit status: 0 when every grid of A is in B with the same active voxels and bit-equal
// values (and B has no other grid), 1 when they differ, 2 on a read error.
#include <cmath>
#include <cstdio>
#include <exception>
#include <set>
#include <string>

#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>

namespace {

struct GridDiff {
    std::size_t values = 0, differ = 0;
    double maxAbs = 0, sumAbsDiff = 0, sumAbs = 0;
};

double magnitude(float v) { return std::fabs(double(v)); }
double magnitude(const openvdb::Vec3s& v) {
    return std::fabs(double(v[0])) + std::fabs(double(v[1])) + std::fabs(double(v[2]));
}

/// Values of `a` against `b` (same grid type), then b's active voxels that a lacks.
template <class GridT>
GridDiff compareGrids(const GridT& a, const GridT& b) {
    GridDiff d;
    auto acc = b.getConstAccessor();
    for (auto it = a.cbeginValueOn(); it; ++it) {
        ++d.values;
        const auto va = *it;
        if (!acc.isValueOn(it.getCoord())) {
            ++d.differ;
            continue;
        }
        const auto vb = acc.getValue(it.getCoord());
        const double diff = magnitude(va - vb);
        d.differ += !(va == vb);
        d.maxAbs = std::max(d.maxAbs, diff);
        d.sumAbsDiff += diff;
        d.sumAbs += magnitude(va);
    }
    auto accA = a.getConstAccessor();
    for (auto it = b.cbeginValueOn(); it; ++it) d.differ += !accA.isValueOn(it.getCoord());
    return d;
}

bool sameType(const openvdb::GridBase& a, const openvdb::GridBase& b) { return a.type() == b.type(); }

}  // namespace

int main(int argc, char** argv) {
    if (argc != 3) {
        std::fprintf(stderr, "usage: lpm_compare_bakes A.vdb B.vdb\n");
        return 2;
    }
    try {
        openvdb::initialize();
        openvdb::io::File fa(argv[1]), fb(argv[2]);
        fa.open();
        fb.open();
        const openvdb::GridPtrVecPtr ga = fa.getGrids(), gb = fb.getGrids();
        std::set<std::string> inA;
        bool differ = false;
        for (const openvdb::GridBase::Ptr& a : *ga) {
            inA.insert(a->getName());
            openvdb::GridBase::Ptr b;
            for (const openvdb::GridBase::Ptr& g : *gb)
                if (g->getName() == a->getName()) b = g;
            if (!b || !sameType(*a, *b)) {
                std::printf("%s: %s\n", a->getName().c_str(), b ? "types differ" : "missing in B");
                differ = true;
                continue;
            }
            GridDiff d;
            if (auto fa32 = openvdb::gridPtrCast<openvdb::FloatGrid>(a))
                d = compareGrids(*fa32, *openvdb::gridPtrCast<openvdb::FloatGrid>(b));
            else if (auto va = openvdb::gridPtrCast<openvdb::Vec3SGrid>(a))
                d = compareGrids(*va, *openvdb::gridPtrCast<openvdb::Vec3SGrid>(b));
            else {
                std::printf("%s: type %s not compared\n", a->getName().c_str(), a->type().c_str());
                differ = true;
                continue;
            }
            std::printf("%s: %zu values, %zu differ, largest difference %.3g, relative L1 %.3g\n", a->getName().c_str(),
                        d.values, d.differ, d.maxAbs, d.sumAbs > 0 ? d.sumAbsDiff / d.sumAbs : 0.0);
            differ = differ || d.differ > 0;
        }
        for (const openvdb::GridBase::Ptr& b : *gb)
            if (!inA.count(b->getName())) {
                std::printf("%s: missing in A\n", b->getName().c_str());
                differ = true;
            }
        std::printf("%s\n", differ ? "grids differ" : "grids identical");
        return differ ? 1 : 0;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "lpm_compare_bakes: %s\n", e.what());
        return 2;
    }
}

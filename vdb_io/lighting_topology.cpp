// The lighting grids' topology (see lighting_topology.h for the rule and why one voxel).
#include "vdb_io/lighting_topology.h"

#include <algorithm>
#include <atomic>
#include <cmath>

#include <openvdb/tools/Morphology.h>
#include <openvdb/tools/Prune.h>
#include <openvdb/tree/LeafManager.h>

#include "vdb_io/bake_file.h"

namespace lpm {

namespace {

/// Adds the kLightingShell dilation (26-neighbourhood: faces, edges, corners) to `tree`'s
/// active voxels: the one rule the topology, the solver's flags and the check share.
template <class TreeT>
void dilateByLightingShell(TreeT& tree) {
    openvdb::tools::dilateActiveValues(tree, kLightingShell, openvdb::tools::NN_FACE_EDGE_VERTEX,
                                       openvdb::tools::EXPAND_TILES);
}

}  // namespace

bool hasSolvedValue(const DenseBake& b, const openvdb::Coord& c) {
    if (!b.sh) return false;
    const int n[3] = {b.nx, b.ny, b.nz};
    if (b.scale == 1.0 && !b.affine) {
        const openvdb::Coord d = c - b.blockMin;
        for (int a = 0; a < 3; ++a)
            if (d[a] < 0 || d[a] >= n[a]) return false;
        return b.index(d.x(), d.y(), d.z()) != Medium::npos;
    }
    // Continuous dense coordinate of c's centre, voxel centres at integers: inside
    // [0, n - 1] the value is an interpolation between solved voxels, outside a clamp
    // (1e-6 of a voxel is rounding in the block's placement, not an extrapolation). The
    // stencil is the one writeBake uses.
    constexpr double kSlack = 1e-6;
    int lo[3], hi[3];
    for (int a = 0; a < 3; ++a) {
        const double u = b.blockCoord(c, a) - 0.5;
        if (!(u >= -kSlack && u <= double(n[a] - 1) + kSlack)) return false;
        lo[a] = std::min(int(std::floor(std::clamp(u, 0.0, double(n[a] - 1)))), std::max(0, n[a] - 2));
        hi[a] = std::min(lo[a] + 1, n[a] - 1);
    }
    for (int k = 0; k < 8; ++k)
        if (b.index((k & 1) ? hi[0] : lo[0], (k & 2) ? hi[1] : lo[1], (k & 4) ? hi[2] : lo[2]) == Medium::npos)
            return false;
    return true;
}

LightingTopology lightingTopology(const openvdb::FloatGrid& density, const DenseBake& b) {
    LightingTopology t;
    t.grid = openvdb::MaskGrid::create(false);
    t.grid->setTransform(density.transform().copy());
    t.grid->tree().topologyUnion(density.tree());
    t.grid->tree().voxelizeActiveTiles();
    if (!b.sh) return t;
    const openvdb::Index64 before = t.grid->activeVoxelCount();
    dilateByLightingShell(t.grid->tree());
    // Keep a shell voxel only where the solver computed S (never extrapolate); the
    // density's own voxels stay whatever happens.
    std::atomic<std::uint64_t> dropped{0};
    openvdb::tree::LeafManager<openvdb::MaskTree> leaves(t.grid->tree());
    leaves.foreach ([&](openvdb::MaskTree::LeafNodeType& leaf, size_t) {
        auto acc = density.getConstAccessor();  // accessors are not thread-safe: one per leaf
        std::vector<openvdb::Index> off;        // (a mask leaf's value iterator cannot switch voxels off)
        for (auto it = leaf.getValueMask().beginOn(); it; ++it) {
            const openvdb::Coord c = leaf.offsetToGlobalCoord(it.pos());
            if (!acc.isValueOn(c) && !hasSolvedValue(b, c)) off.push_back(it.pos());
        }
        for (openvdb::Index n : off) leaf.setValueOff(n);
        dropped += off.size();
    });
    openvdb::tools::pruneInactive(t.grid->tree());
    t.shellDropped = dropped;
    t.shellVoxels = t.grid->activeVoxelCount() - before;
    return t;
}

std::vector<std::uint8_t> lightingVoxelFlags(const openvdb::FloatGrid& density, const openvdb::Coord& blockMin,
                                             const Medium& m) {
    openvdb::MaskGrid lit(false);
    lit.tree().topologyUnion(density.tree());
    lit.tree().voxelizeActiveTiles();
    dilateByLightingShell(lit.tree());
    lit.tree().voxelizeActiveTiles();
    std::vector<std::uint8_t> flags(m.voxelCount(), 0);
    // Leaves in parallel: each voxel's flag is written by the one leaf holding it.
    openvdb::tree::LeafManager<const openvdb::MaskTree> leaves(lit.tree());
    leaves.foreach ([&](const openvdb::MaskTree::LeafNodeType& leaf, size_t) {
        for (auto it = leaf.cbeginValueOn(); it; ++it) {
            const openvdb::Coord d = it.getCoord() - blockMin;
            if (d.x() < 0 || d.y() < 0 || d.z() < 0 || d.x() >= m.nx || d.y() >= m.ny || d.z() >= m.nz) continue;
            const size_t v = m.index(d.x(), d.y(), d.z());
            if (v != Medium::npos) flags[v] = 1;
        }
    });
    return flags;
}

std::uint64_t missingShellVoxels(const openvdb::FloatGrid& density, const openvdb::Vec3SGrid& lighting) {
    openvdb::MaskGrid need(false);
    need.tree().topologyUnion(density.tree());
    dilateByLightingShell(need.tree());
    need.tree().topologyDifference(lighting.tree());
    return need.activeVoxelCount();
}

}  // namespace lpm

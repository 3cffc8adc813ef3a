// Writing and reading the baked VDB (see bake_file.h for the layout).
#include "vdb_io/bake_file.h"
#include "vdb_io/bake_schema.h"
#include "vdb_io/renderer_grids.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <memory>
#include <stdexcept>
#include <vector>

#include <openvdb/io/File.h>
#include <openvdb/tree/LeafManager.h>

#include "core/malloc_policy.h"
#include "core/sh.h"
#include "vdb_io/atomic_file.h"
#include "vdb_io/io_error.h"
#include "vdb_io/lighting_topology.h"
#include "vdb_io/vdb_file.h"
#include "vdb_io/volume_reader.h"

namespace lpm {

namespace {

constexpr float kHalfMax = 65504.f;

/// Trilinear weights of the dense block at an input voxel: 8 dense indices and weights.
struct Stencil {
    size_t index[8];
    float weight[8];
};

/// Where input voxel `c` (centre at index c) falls between the block's voxel centres: the
/// continuous dense coordinate is (c - corner) * scale - 0.5; outside the outermost centres
/// the value is clamped (the border voxel's value, not an extrapolation).
Stencil stencilAt(const DenseBake& b, const openvdb::Coord& c) {
    const int n[3] = {b.nx, b.ny, b.nz};
    int i0[3], i1[3];
    float t[3];
    for (int a = 0; a < 3; ++a) {
        const double u = std::clamp(b.blockCoord(c, a) - 0.5, 0.0, double(n[a] - 1));
        i0[a] = std::min(int(std::floor(u)), std::max(0, n[a] - 2));
        i1[a] = std::min(i0[a] + 1, n[a] - 1);
        t[a] = float(u - i0[a]);
    }
    Stencil s;
    for (int k = 0; k < 8; ++k) {
        const int x = (k & 1) ? i1[0] : i0[0], y = (k & 2) ? i1[1] : i0[1], z = (k & 4) ? i1[2] : i0[2];
        s.index[k] = b.index(x, y, z);
        s.weight[k] = ((k & 1) ? t[0] : 1 - t[0]) * ((k & 2) ? t[1] : 1 - t[1]) * ((k & 4) ? t[2] : 1 - t[2]);
    }
    return s;
}

/// An empty grid of type GridT with `topo`'s transform and active voxels, all values 0.
template <typename GridT>
typename GridT::Ptr zeroGridLike(const openvdb::MaskGrid& topo) {
    typename GridT::Ptr g = GridT::create(typename GridT::ValueType(0));
    g->setTransform(topo.transform().copy());
    g->tree().topologyUnion(topo.tree());
    return g;
}

/// Where an input voxel's value comes from in the dense block: at scale 1 the dense voxel
/// holding it (`single`); otherwise a trilinear stencil. `inside` is false where scale 1
/// leaves the voxel outside the block.
struct DensePlace {
    Stencil stencil;
    size_t single = Medium::npos;
    bool interpolate = false, inside = false;
};

DensePlace densePlace(const DenseBake& b, const openvdb::Coord& c) {
    DensePlace p;
    if (b.scale != 1.0 || b.affine) {
        p.stencil = stencilAt(b, c);
        p.interpolate = p.inside = true;
        return p;
    }
    const openvdb::Coord d = c - b.blockMin;
    if (d.x() < 0 || d.y() < 0 || d.z() < 0 || d.x() >= b.nx || d.y() >= b.ny || d.z() >= b.nz) return p;
    p.single = b.index(d.x(), d.y(), d.z());
    p.inside = p.single != Medium::npos;  // always, for readVolume's blocks: every tile read from is stored
    return p;
}

/// The value at a place from value(denseIndex).
template <typename ValueT, typename F>
ValueT valueAt(const DensePlace& p, F value) {
    if (!p.interpolate) return value(p.single);
    ValueT v(0);
    for (int k = 0; k < 8; ++k)
        if (p.stencil.weight[k] != 0.f && p.stencil.index[k] != Medium::npos)
            v += value(p.stencil.index[k]) * p.stencil.weight[k];
    return v;
}

/// `count` grids on `topo`'s topology whose active voxels take value(denseIndex, k), grid
/// k (valueAt). One walk over the voxels finds each voxel's dense place for all the grids
/// (the SH grids were filled one at a time: the sparse index lookups nine times over). lightingTopology() keeps only
/// voxels with solved values, so no stencil index is npos there; the density's own voxels always have one from
/// readVolume's block.
template <typename GridT = openvdb::Vec3SGrid, typename F>
std::vector<typename GridT::Ptr> fillGrids(const openvdb::MaskGrid& topo, const DenseBake& b, int count, F value) {
    using TreeT = typename GridT::TreeType;
    using ValueT = typename GridT::ValueType;
    std::vector<typename GridT::Ptr> grids;
    std::vector<std::unique_ptr<openvdb::tree::LeafManager<TreeT>>> leaves;
    for (int k = 0; k < count; ++k) {
        grids.push_back(zeroGridLike<GridT>(topo));
        leaves.push_back(std::make_unique<openvdb::tree::LeafManager<TreeT>>(grids.back()->tree()));
        if (leaves.back()->leafCount() != leaves.front()->leafCount())
            throw std::logic_error("fillGrids: copies of one topology with different leaf counts");
    }
    if (count == 0) return grids;
    leaves.front()->foreach ([&](typename TreeT::LeafNodeType& first, size_t n) {
        std::vector<typename TreeT::LeafNodeType*> leaf(size_t(count), nullptr);
        for (int k = 0; k < count; ++k) leaf[size_t(k)] = &leaves[size_t(k)]->leaf(n);
        for (auto it = first.cbeginValueOn(); it; ++it) {
            const DensePlace p = densePlace(b, it.getCoord());
            if (!p.inside) continue;
            for (int k = 0; k < count; ++k)
                leaf[size_t(k)]->setValueOnly(it.pos(), valueAt<ValueT>(p, [&](size_t i) { return value(i, k); }));
        }
    });
    return grids;
}

/// fillGrids of one grid.
template <typename GridT = openvdb::Vec3SGrid, typename F>
typename GridT::Ptr fillGrid(const openvdb::MaskGrid& topo, const DenseBake& b, F value) {
    return fillGrids<GridT>(topo, b, 1, [&](size_t i, int) { return value(i); }).front();
}

/// The heap `vec3Grids` Vec3f grids and `floatGrids` float grids built on `topo` take: a
/// leaf node and its value buffer per leaf.
std::size_t outputTreeBytes(const openvdb::MaskGrid& topo, std::size_t vec3Grids, std::size_t floatGrids) {
    using Vec3Leaf = openvdb::Vec3STree::LeafNodeType;
    using FloatLeaf = openvdb::FloatTree::LeafNodeType;
    constexpr std::size_t kBlockOverhead = 16;  // glibc's chunk header, rounded
    const std::size_t vec3Leaf = sizeof(Vec3Leaf) + Vec3Leaf::SIZE * sizeof(openvdb::Vec3s) + 2 * kBlockOverhead;
    const std::size_t floatLeaf = sizeof(FloatLeaf) + FloatLeaf::SIZE * sizeof(float) + 2 * kBlockOverhead;
    return topo.tree().leafCount() * (vec3Grids * vec3Leaf + floatGrids * floatLeaf);
}

double maxAbs(const openvdb::Vec3SGrid& g) {
    double m = 0;
    for (auto it = g.cbeginValueOn(); it; ++it)
        for (int c = 0; c < 3; ++c) m = std::max(m, double(std::fabs((*it)[c])));
    return m;
}

/// The SH grids sh_0 .. sh_{coeffs-1} on `topo` (zeros for an empty bake), named and tagged.
std::vector<openvdb::Vec3SGrid::Ptr> shGrids(const openvdb::MaskGrid& topo, const DenseBake& b) {
    std::vector<openvdb::Vec3SGrid::Ptr> sh;
    if (b.sh)
        sh = fillGrids(topo, b, b.coeffs, [&](size_t i, int k) {
            const float* p = b.shAt(i);
            return p ? openvdb::Vec3s(p[k * 3], p[k * 3 + 1], p[k * 3 + 2]) : openvdb::Vec3s(0.0f);
        });
    else
        for (int k = 0; k < b.coeffs; ++k) sh.push_back(zeroGridLike<openvdb::Vec3SGrid>(topo));
    for (int k = 0; k < b.coeffs; ++k) {
        const openvdb::Vec3SGrid::Ptr& g = sh[size_t(k)];
        g->setName("sh_" + std::to_string(k));
        g->setGridClass(openvdb::GRID_UNKNOWN);    // order >= 1 terms go negative: not a fog volume
        g->setVectorType(openvdb::VEC_INVARIANT);  // colour, not a vector: DCCs must not rotate it
        const int l = shBand(k);
        g->insertMeta("lpm:sh_index", openvdb::Int32Metadata(k));
        g->insertMeta("lpm:sh_l", openvdb::Int32Metadata(l));
        g->insertMeta("lpm:sh_m", openvdb::Int32Metadata(k - l * l - l));
    }
    return sh;
}

/// The direction-averaged S grid: b.scatter's values, else sh_0's times Y00 (so it needs
/// only the grid, not the SH values).
openvdb::Vec3SGrid::Ptr scatterGridOf(const openvdb::MaskGrid& topo, const DenseBake& b,
                                      const openvdb::Vec3SGrid& sh0) {
    openvdb::Vec3SGrid::Ptr s;
    if (b.scatter) {
        s = fillGrid(topo, b, [&](size_t i) {
            const float* p = b.scatter + i * 3;
            return openvdb::Vec3s(p[0], p[1], p[2]);
        });
    } else if (!b.sh) {
        s = zeroGridLike<openvdb::Vec3SGrid>(topo);
    } else {
        s = zeroGridLike<openvdb::Vec3SGrid>(topo);
        // The same topology, so the same leaves in the same order.
        openvdb::tree::LeafManager<const openvdb::Vec3STree> from(sh0.tree());
        openvdb::tree::LeafManager<openvdb::Vec3STree> to(s->tree());
        if (from.leafCount() != to.leafCount()) throw std::logic_error("scatterGridOf: sh_0 has another topology");
        const float y = float(kY00);
        to.foreach ([&](openvdb::Vec3STree::LeafNodeType& leaf, size_t n) {
            const openvdb::Vec3STree::LeafNodeType& src = from.leaf(n);
            for (auto it = leaf.beginValueOn(); it; ++it) it.setValue(src.getValue(it.pos()) * y);
        });
    }
    s->setName("scatter");
    s->setGridClass(openvdb::GRID_FOG_VOLUME);
    s->setVectorType(openvdb::VEC_INVARIANT);
    s->insertMeta("lpm:description", openvdb::StringMetadata("direction-averaged S = sh_0 * 0.282095"));
    return s;
}

}  // namespace

BakeWriteReport writeBake(const openvdb::FloatGrid& density, const DenseBake& b, const openvdb::MetaMap& meta,
                          const BakeWriteOptions& o) {
    const auto t0 = std::chrono::steady_clock::now();
    initOpenVdb();
    BakeWriteReport rep;
    AtomicOutput out(o.path, o.inputs);  // checks the path before any work

    // The lighting grids' topology: the input's active voxels (tiles voxelised so every
    // grid can hold per-voxel values) and the shell a trilinear lookup reads around them.
    const LightingTopology lt = lightingTopology(density, b);
    const openvdb::MaskGrid::Ptr topo = lt.grid;
    rep.voxelsWritten = topo->activeVoxelCount();
    rep.shellVoxels = lt.shellVoxels;
    rep.shellDropped = lt.shellDropped;
    if (lt.shellDropped > 0)
        rep.warnings.push_back(std::to_string(lt.shellDropped) +
                               " voxel(s) of the one-voxel shell around the density "
                               "have no solved S (solve block too small) and are left inactive: the volume's edge "
                               "renders dark there");

    // The SH grids first; then the SH values (the solver's rows) are freed before the
    // other grids are built, so the write holds one copy of the SH at a time.
    prepareHeapForSmallBlocks(outputTreeBytes(*topo, size_t(b.coeffs), 0));
    openvdb::GridPtrVec grids;
    const std::vector<openvdb::Vec3SGrid::Ptr> sh = shGrids(*topo, b);
    for (const openvdb::Vec3SGrid::Ptr& g : sh) {
        if (o.half) rep.maxAbsValue = std::max(rep.maxAbsValue, maxAbs(*g));  // for its warning only
        grids.push_back(g);
    }
    if (b.releaseSh) {
        std::vector<float>().swap(*b.releaseSh);  // its values are in the grids now
        returnFreedHeapPages();
    }
    prepareHeapForSmallBlocks(outputTreeBytes(*topo, b.emission ? 2 : 1, b.sunTransmittance.size()));
    const openvdb::Vec3SGrid::Ptr scatterGrid = scatterGridOf(*topo, b, *sh.front());
    grids.push_back(scatterGrid);
    openvdb::Vec3SGrid::Ptr emissionGrid;
    for (size_t k = 0; k < b.sunTransmittance.size(); ++k) {
        const float* tr = b.sunTransmittance[k];
        openvdb::FloatGrid::Ptr t = fillGrid<openvdb::FloatGrid>(*topo, b, [&](size_t i) { return tr[i]; });
        t->setName(sunTransmittanceGridName(int(k)));
        t->setGridClass(openvdb::GRID_FOG_VOLUME);
        t->insertMeta("lpm:description",
                      openvdb::StringMetadata("transmittance toward sun " + std::to_string(k) + " (lpm:sun_term_" +
                                              std::to_string(k) + "_*): S += E T p_HG"));
        grids.push_back(t);
    }
    if (b.emission) {
        openvdb::Vec3SGrid::Ptr e = fillGrid(*topo, b, [&](size_t i) {
            const RGB& c = b.emission[i];
            return openvdb::Vec3s(c.r, c.g, c.b);
        });
        e->setName("emission");
        e->setGridClass(openvdb::GRID_FOG_VOLUME);
        e->setVectorType(openvdb::VEC_INVARIANT);
        e->insertMeta("lpm:description", openvdb::StringMetadata("emitted radiance L_e (scaled) used by the bake"));
        grids.push_back(e);
        emissionGrid = e;
    }
    if (o.writeDensity) {
        // Its tree shared, not copied (the write only reads it); name and class on the copy.
        openvdb::FloatGrid::Ptr d = openvdb::ConstPtrCast<openvdb::FloatGrid>(density.copy());
        d->setName(o.densityName);
        d->setGridClass(openvdb::GRID_FOG_VOLUME);
        grids.push_back(d);
    }
    if (o.rendererGrids) {
        const RendererGrids rg = makeRendererGrids(density, *scatterGrid, emissionGrid.get(), o.densityScale, o.albedo);
        grids.push_back(rg.extinction);
        grids.push_back(rg.source);
    }
    if (o.half) {
        if (rep.maxAbsValue > kHalfMax)
            rep.warnings.push_back("--half: SH values reach " + std::to_string(rep.maxAbsValue) +
                                   ", above the half-float maximum 65504; they will be stored as infinity");
        for (auto& g : grids) g->setSaveFloatAsHalf(true);
    }

    for (const auto& g : grids) rep.gridNames.push_back(g->getName());
    try {
        openvdb::io::File f(out.tempPath());
        // Uncompressed by default: zip shrinks the noisy floats of lighting grids by only
        // 1-11% and takes 80% of the write (docs/output_format.md). zip rather than Blosc
        // when asked: Blosc version mismatches have broken reads elsewhere.
        f.setCompression(o.zip ? openvdb::io::COMPRESS_ZIP | openvdb::io::COMPRESS_ACTIVE_MASK
                               : openvdb::io::COMPRESS_ACTIVE_MASK);
        f.write(grids, meta);
        f.close();
        // Read the grid list back: catches short writes (disk full) before the rename.
        openvdb::io::File check(out.tempPath());
        check.open(false);
        const size_t n = check.readAllGridMetadata()->size();
        check.close();
        if (n != grids.size())
            throw OutputError("output", "wrote " + std::to_string(grids.size()) + " grids to '" + out.tempPath() +
                                            "' but read back " + std::to_string(n));
    } catch (const OutputError&) {
        throw;
    } catch (const std::exception& e) {
        // OpenVDB reports a full disk as whatever failed next (even "grid type is not
        // registered"): name the file system's state when it explains the failure.
        const std::string why = out.failureReason();
        throw OutputError("output", "cannot write '" + o.path + "': " + (why.empty() ? std::string(e.what()) : why));
    }
    out.commit();
    rep.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return rep;
}

BakeFile readBakeFile(const std::string& path) {
    initOpenVdb();
    BakeFile f;
    f.path = path;
    VdbFile file(path);
    f.meta = file.fileMetadata();
    f.grids = file.readAllGrids();
    f.shOrder = getInt(*f.meta, bakekey::shOrder, -1);
    std::string densityName = getString(*f.meta, bakekey::densityGrid, "density");
    for (int k = 0;; ++k) {
        openvdb::Vec3SGrid::Ptr g;
        for (auto& base : f.grids)
            if (base->getName() == "sh_" + std::to_string(k)) g = openvdb::gridPtrCast<openvdb::Vec3SGrid>(base);
        if (!g) break;
        f.sh.push_back(g);
    }
    for (int k = 0;; ++k) {
        openvdb::FloatGrid::Ptr g;
        for (auto& base : f.grids)
            if (base->getName() == sunTransmittanceGridName(k)) g = openvdb::gridPtrCast<openvdb::FloatGrid>(base);
        if (!g) break;
        f.sunTransmittance.push_back(g);
    }
    for (auto& base : f.grids) {
        if (base->getName() == "scatter") f.scatter = openvdb::gridPtrCast<openvdb::Vec3SGrid>(base);
        if (base->getName() == "emission") f.emission = openvdb::gridPtrCast<openvdb::Vec3SGrid>(base);
        if (base->getName() == densityName && !f.density) f.density = openvdb::gridPtrCast<openvdb::FloatGrid>(base);
    }
    return f;
}

std::vector<std::string> validateBake(const BakeFile& f) {
    std::vector<std::string> why;
    const int version = getInt(*f.meta, bakekey::formatVersion, -1);
    if (version < 0) {
        why.push_back("no lpm:format_version metadata (not written by lpmbake)");
        return why;
    }
    if (version > kBakeFormatVersion)
        why.push_back("lpm:format_version " + std::to_string(version) + " is newer than this lpmbake reads (" +
                      std::to_string(kBakeFormatVersion) + ")");
    for (const std::string& p : schemaProblems(*f.meta, false)) why.push_back(p);
    if (f.shOrder < 0 || f.shOrder > kMaxShOrder) {
        why.push_back("missing or invalid lpm:sh_order");
    } else if (int(f.sh.size()) < shCount(f.shOrder)) {
        why.push_back("lpm:sh_order " + std::to_string(f.shOrder) + " needs " + std::to_string(shCount(f.shOrder)) +
                      " Vec3f grids sh_0..sh_" + std::to_string(shCount(f.shOrder) - 1) + ", found " +
                      std::to_string(f.sh.size()));
    }
    if (!f.scatter) why.push_back("no Vec3f grid named 'scatter'");
    const std::string dn = getString(*f.meta, bakekey::densityGrid, "");
    if (!dn.empty() && !f.density) why.push_back("lpm:density_grid names '" + dn + "' but there is no such float grid");
    for (const auto& g : f.sh)
        if (g->transform() != f.sh.front()->transform())
            why.push_back("grid '" + g->getName() + "' has a different transform from sh_0");
    const int suns = getInt(*f.meta, bakekey::sunTermCount, 0);
    if (suns != int(f.sunTransmittance.size()))
        why.push_back("lpm:sun_term_count is " + std::to_string(suns) + " but the file has " +
                      std::to_string(f.sunTransmittance.size()) + " float grids sun_transmittance_0..");
    return why;
}

double metaDouble(const openvdb::MetaMap& m, const std::string& key, double fallback) {
    if (auto d = m.getMetadata<openvdb::DoubleMetadata>(key)) return d->value();
    if (auto f = m.getMetadata<openvdb::FloatMetadata>(key)) return f->value();
    if (auto i = m.getMetadata<openvdb::Int32Metadata>(key)) return i->value();
    return fallback;
}
int metaInt(const openvdb::MetaMap& m, const std::string& key, int fallback) {
    if (auto i = m.getMetadata<openvdb::Int32Metadata>(key)) return i->value();
    if (auto i = m.getMetadata<openvdb::Int64Metadata>(key)) return int(i->value());
    return fallback;
}
std::string metaString(const openvdb::MetaMap& m, const std::string& key, const std::string& fallback) {
    if (auto s = m.getMetadata<openvdb::StringMetadata>(key)) return s->value();
    return fallback;
}
RGB metaRgb(const openvdb::MetaMap& m, const std::string& key, const RGB& fallback) {
    if (auto v = m.getMetadata<openvdb::Vec3DMetadata>(key))
        return RGB(float(v->value().x()), float(v->value().y()), float(v->value().z()));
    if (auto v = m.getMetadata<openvdb::Vec3SMetadata>(key)) return RGB(v->value().x(), v->value().y(), v->value().z());
    return fallback;
}

}  // namespace lpm

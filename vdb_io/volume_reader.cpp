// OpenVDB -> core Medium. See volume_reader.h for the conventions.
#include "vdb_io/volume_reader.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <iomanip>
#include <mutex>
#include <sstream>

#include <openvdb/io/File.h>
#include <openvdb/tools/GridOperators.h>
#include <openvdb/tools/Interpolation.h>
#include <openvdb/tools/LevelSetUtil.h>
#include <openvdb/tree/LeafManager.h>
#include <openvdb/util/logging.h>

#include "core/blackbody.h"
#include "core/parallel.h"
#include "vdb_io/color.h"
#include "vdb_io/io_error.h"
#include "vdb_io/lighting_topology.h"
#include "vdb_io/vdb_file.h"

namespace lpm {

namespace {

const char* kComp = "input";

std::string gridClassName(const openvdb::GridBase& g) { return openvdb::GridBase::gridClassToString(g.getGridClass()); }

bool isBad(float v) { return !std::isfinite(v) || v < 0.f; }

/// Counts NaN/Inf/negative active values; with `fix`, sets them to 0. Tiles included.
std::uint64_t scanBadValues(openvdb::FloatGrid& grid, bool fix, float& example) {
    std::uint64_t bad = 0;
    bool haveExample = false;
    for (auto it = grid.tree().beginValueOn(); it; ++it) {
        const float v = *it;
        if (!isBad(v)) continue;
        const std::uint64_t n = it.isVoxelValue() ? 1 : it.getBoundingBox().volume();
        bad += n;
        if (!haveExample) {
            example = v;
            haveExample = true;
        }
        if (fix) it.setValue(0.f);
    }
    return bad;
}

std::string listGrids(const std::vector<std::string>& grids) {
    if (grids.empty()) return "(none)";
    std::string s;
    for (size_t i = 0; i < grids.size(); ++i) s += (i ? ", " : "") + grids[i];
    return s;
}

/// Reads the `index`-th grid called `name` (OpenVDB addresses duplicates as "name[N]").
openvdb::GridBase::Ptr readNamed(VdbFile& file, const std::string& path, const std::string& name, int index,
                                 const openvdb::GridPtrVec& metas, const std::vector<std::string>& list,
                                 std::vector<std::string>& warnings, const char* what) {
    int count = 0;
    for (const auto& m : metas)
        if (m->getName() == name) ++count;
    if (count == 0)
        throw InputError(
            kComp, "'" + path + "' has no grid named '" + name + "' (" + what + "); grids present: " + listGrids(list));
    if (index < 0) {
        if (count > 1)
            warnings.push_back("'" + path + "' has " + std::to_string(count) + " grids named '" + name +
                               "'; using the first (choose with --grid-index 0.." + std::to_string(count - 1) + ")");
        index = 0;
    }
    if (index >= count)
        throw InputError(kComp, "--grid-index " + std::to_string(index) + " is out of range: '" + path + "' has " +
                                    std::to_string(count) + " grid(s) named '" + name + "'");
    return file.readGrid(index == 0 ? name : name + "[" + std::to_string(index) + "]");
}

/// Fills out.medium.emission (the block's dimensions are set): each dense voxel gets the
/// mean of k^3 trilinear samples of the emission grid at pos(x, y, z, jx, jy, jz) (world
/// space), times the emission scale. NaN/negative samples are errors unless sanitising.
template <typename PosFn>
void sampleEmission(const VolumeReadOptions& o, VolumeInput& out, PosFn pos, int k) {
    Medium& m = out.medium;
    m.emission.assign(m.voxelCount(), RGB(0.f));
    const float es = float(o.emissionScale);
    const float inv = 1.f / float(k * k * k);
    std::atomic<std::uint64_t> badE{0};
    // One sampler (and accessor) per chunk of z-slices: accessors are not thread-safe.
    auto sampleInto = [&](auto& egrid, auto toRgb) {
        using GridT = std::decay_t<decltype(egrid)>;
        parallelForChunks(size_t(m.nz), 1, [&](size_t z0, size_t z1) {
            auto acc = egrid.getConstAccessor();
            openvdb::tools::GridSampler<typename GridT::ConstAccessor, openvdb::tools::BoxSampler> s(acc,
                                                                                                     egrid.transform());
            auto sample = [&](const openvdb::Vec3d& w, bool& bad) {
                RGB e = toRgb(s.wsSample(w)) * es;
                for (int c = 0; c < 3; ++c)
                    if (!std::isfinite(e[c]) || e[c] < 0) {
                        bad = true;
                        e[c] = 0;
                    }
                return e;
            };
            for (size_t z = z0; z < z1; ++z)
                for (int y = 0; y < m.ny; ++y)
                    for (int x = 0; x < m.nx; ++x) {
                        const size_t vi = m.index(x, y, int(z));
                        if (vi == Medium::npos) continue;  // unallocated (empty) tile
                        bool b = false;
                        RGB e;
                        if (k == 1) {
                            e = sample(pos(x, y, int(z), 0, 0, 0), b);  // exactly the voxel-centre sample
                        } else {
                            for (int jz = 0; jz < k; ++jz)
                                for (int jy = 0; jy < k; ++jy)
                                    for (int jx = 0; jx < k; ++jx) e += sample(pos(x, y, int(z), jx, jy, jz), b);
                            e = e * inv;
                        }
                        if (b) ++badE;
                        m.emission[vi] = e;
                    }
        });
    };
    if (auto f = openvdb::gridPtrCast<openvdb::FloatGrid>(out.emission)) sampleInto(*f, [](float v) { return RGB(v); });
    else if (auto v = openvdb::gridPtrCast<openvdb::Vec3SGrid>(out.emission))
        sampleInto(*v, [](const openvdb::Vec3s& c) { return RGB(c.x(), c.y(), c.z()); });
    const std::string ew = "emission grid '" + o.emissionGrid + "'";
    if (badE > 0 && !o.sanitize)
        throw InputError(kComp, ew + " has NaN, infinite or negative radiance at " + std::to_string(badE.load()) +
                                    " voxel(s) (emission scale " + std::to_string(o.emissionScale) +
                                    "); pass --sanitize to clamp them to 0");
    if (badE > 0) out.warnings.push_back(ew + ": --sanitize clamped " + std::to_string(badE.load()) + " voxel(s) to 0");
}

/// Solve voxels of padding at --solve-scale S: at least `pad`, and enough that the centres
/// of the lighting shell's input voxels (kLightingShell past the active box) lie within the
/// span of the solve voxels' centres, so the bake interpolates S there instead of clamping.
/// The shell voxel bmin - shell sits at block coordinate (0.5 - shell) S + P, which must be
/// >= 0.5 (the first centre): P >= (shell - 0.5) S + 0.5; the high side gives the same bound.
/// 1 for S <= 1, 2 for S = 2, 5 for S = 8.
int solvePad(int pad, double S) { return std::max(pad, int(std::ceil((kLightingShell - 0.5) * S + 0.5 - 1e-9))); }

/// An input voxel (index along one axis) and its weight in a solve voxel.
struct Tap {
    int index;
    double weight;
};

/// The sheared block along the orthonormal axes e (solve voxel size h): low corner `lo`
/// and voxel counts. It covers the active box's voxels (index extents +-0.5) plus `pad`
/// solve voxels per side, and more where needed so that every lighting-shell voxel's centre
/// (kLightingShell past the box) lies at least half a solve voxel inside, between solve-voxel
/// centres: the bake interpolates S there, no clamp. The padding is whole solve voxels from
/// the voxels' extent, so the block stays aligned with it as without the shell.
void shearedBlockExtent(const openvdb::math::Transform& xf, const openvdb::Vec3d e[3], const openvdb::CoordBBox& bbox,
                        double h, int pad, double lo[3], double dims[3]) {
    // Projections of the box grown by `grow` index units on each axis e[i].
    auto extent = [&](double grow, double l[3], double u[3]) {
        for (int i = 0; i < 3; ++i) {
            l[i] = 1e300;
            u[i] = -1e300;
        }
        for (int k = 0; k < 8; ++k) {
            const openvdb::Vec3d c((k & 1) ? bbox.max().x() + grow : bbox.min().x() - grow,
                                   (k & 2) ? bbox.max().y() + grow : bbox.min().y() - grow,
                                   (k & 4) ? bbox.max().z() + grow : bbox.min().z() - grow);
            const openvdb::Vec3d p = xf.indexToWorld(c);
            for (int i = 0; i < 3; ++i) {
                l[i] = std::min(l[i], e[i].dot(p));
                u[i] = std::max(u[i], e[i].dot(p));
            }
        }
    };
    double vlo[3], vhi[3], slo[3], shi[3];
    extent(0.5, vlo, vhi);                     // the voxels' extents
    extent(double(kLightingShell), slo, shi);  // the shell voxels' centres
    for (int i = 0; i < 3; ++i) {
        const int padLo = std::max(pad, int(std::ceil((vlo[i] - slo[i]) / h + 0.5 - 1e-9)));
        const int padHi = std::max(pad, int(std::ceil((shi[i] - vhi[i]) / h + 0.5 - 1e-9)));
        lo[i] = vlo[i] - padLo * h;
        dims[i] = std::max(1.0, std::ceil((vhi[i] + padHi * h - lo[i]) / h - 1e-6));
    }
}

/// --solve-scale S != 1: builds out.medium on a grid with the input's axes and voxel size
/// / S (out.medium's voxelSize and localToWorld hold the input's on entry). See
/// volume_reader.h for the placement and the resampling rules.
/// Sheared (non-orthogonal) index axes: the solver needs an orthonormal voxel frame, so
/// the density is resampled onto cubic voxels in the frame Gram-Schmidt builds from the
/// index axes (first axis kept), voxel size = cube root of the input voxel volume divided
/// by --solve-scale. Each solve voxel averages 3^3 point samples of the input (nearest
/// input voxel); the bake maps back through the affine map recorded in out.solveGrid.
void resampleSheared(const openvdb::FloatGrid& grid, const openvdb::CoordBBox& bbox, int pad,
                     const VolumeReadOptions& o, const std::string& where, VolumeInput& out) {
    Medium& m = out.medium;
    const openvdb::math::Transform& xf = grid.transform();
    const openvdb::Vec3d w0 = xf.indexToWorld(openvdb::Vec3d(0, 0, 0));
    openvdb::Vec3d a[3], e[3];
    for (int i = 0; i < 3; ++i) {
        openvdb::Vec3d u(0, 0, 0);
        u[i] = 1;
        a[i] = xf.indexToWorld(u) - w0;
    }
    e[0] = a[0] / a[0].length();
    e[1] = a[1] - e[0] * e[0].dot(a[1]);
    e[1] /= e[1].length();
    e[2] = a[2] - e[0] * e[0].dot(a[2]) - e[1] * e[1].dot(a[2]);
    const double e2len = e[2].length();
    if (!(e[1].length() > 0) || !(e2len > 1e-12 * a[2].length()))
        throw InputError(kComp, where + " has a degenerate (flat) transform");
    e[2] /= e2len;
    const double det = std::fabs(a[0].dot(a[1].cross(a[2])));
    const double h = std::cbrt(det) / o.solveScale;
    double lo[3], dims[3];
    shearedBlockExtent(xf, e, bbox, h, pad, lo, dims);
    const double count = dims[0] * dims[1] * dims[2];
    if (count > double(o.maxDenseVoxels))
        throw InputError(kComp, where + ": its sheared transform is resampled to " + std::to_string(int(dims[0])) +
                                    "x" + std::to_string(int(dims[1])) + "x" + std::to_string(int(dims[2])) +
                                    " voxels, above the limit of " + std::to_string(o.maxDenseVoxels) +
                                    " (--max-voxels); use a smaller --solve-scale");
    m.allocate(int(dims[0]), int(dims[1]), int(dims[2]));
    m.voxelSize = {h, h, h};
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) m.localToWorld.m[r * 3 + c] = e[c][r];
    const openvdb::Vec3d origin = e[0] * lo[0] + e[1] * lo[1] + e[2] * lo[2];
    m.origin = {origin.x(), origin.y(), origin.z()};
    auto worldAt = [&](int x, int y, int z, double fx, double fy, double fz) {
        return origin + e[0] * ((x + fx) * h) + e[1] * ((y + fy) * h) + e[2] * ((z + fz) * h);
    };
    const float scale = float(o.densityScale);
    constexpr int q = 3;
    parallelForChunks(size_t(m.nz), 1, [&](size_t z0, size_t z1) {
        auto acc = grid.getConstAccessor();
        for (int z = int(z0); z < int(z1); ++z)
            for (int y = 0; y < m.ny; ++y)
                for (int x = 0; x < m.nx; ++x) {
                    double sum = 0;
                    for (int k = 0; k < q * q * q; ++k) {
                        const openvdb::Vec3d wp =
                            worldAt(x, y, z, (k % q + 0.5) / q, ((k / q) % q + 0.5) / q, (k / (q * q) + 0.5) / q);
                        const openvdb::Vec3d ip = xf.worldToIndex(wp);
                        const openvdb::Coord c(int(std::floor(ip.x() + 0.5)), int(std::floor(ip.y() + 0.5)),
                                               int(std::floor(ip.z() + 0.5)));
                        if (acc.isValueOn(c)) sum += acc.getValue(c);
                    }
                    m.sigmaT[m.index(x, y, z)] = float(sum / (q * q * q)) * scale;
                }
    });
    // Block coordinate of input index c: E^T (A c + w0 - origin) / h.
    out.solveGrid.affine = true;
    out.solveGrid.scale = 1.0 / h;
    for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) out.solveGrid.M[r][c] = e[r].dot(a[c]) / h;
        out.solveGrid.t[r] = e[r].dot(w0 - origin) / h;
    }
    if (out.emission)
        sampleEmission(
            o, out,
            [&](int x, int y, int z, int jx, int jy, int jz) { return worldAt(x, y, z, 0.5 + jx, 0.5 + jy, 0.5 + jz); },
            1);
    out.warnings.push_back(where + " has a sheared transform: resampled to " + std::to_string(m.nx) + "x" +
                           std::to_string(m.ny) + "x" + std::to_string(m.nz) + " cubic voxels of " + std::to_string(h) +
                           " in an orthonormal frame");
}

void resampleToSolveGrid(const openvdb::FloatGrid& grid, const openvdb::CoordBBox& bbox, int padIn,
                         const VolumeReadOptions& o, const std::string& where, VolumeInput& out) {
    const double S = o.solveScale;
    Medium& m = out.medium;
    const openvdb::math::Transform& xf = grid.transform();
    const int pad = solvePad(padIn, S);

    // Solve voxels per axis: enough to cover the bounding box (the 1e-6 keeps e.g. 10 * 0.3
    // = 3.0000000000000004 from adding a voxel), plus the pad on both sides. Computed in
    // double so that a huge S * extent is refused below rather than overflowing an int.
    double dims[3];
    for (int a = 0; a < 3; ++a) dims[a] = std::max(1.0, std::ceil(double(bbox.dim()[a]) * S - 1e-6)) + 2.0 * pad;
    const double count = dims[0] * dims[1] * dims[2];
    if (count > double(o.maxDenseVoxels)) {
        std::ostringstream msg;
        msg << where << ": --solve-scale " << S << " needs a dense solve block of " << std::fixed
            << std::setprecision(0) << dims[0] << "x" << dims[1] << "x" << dims[2] << " = " << count
            << " voxels, above the limit of " << o.maxDenseVoxels << " (--max-voxels); use a smaller --solve-scale";
        throw InputError(kComp, msg.str());
    }
    m.nx = int(dims[0]);
    m.ny = int(dims[1]);
    m.nz = int(dims[2]);
    openvdb::Vec3d c0;
    for (int a = 0; a < 3; ++a) {
        c0[a] = bbox.min()[a] - 0.5 - pad / S;
        m.voxelSize[a] /= S;
    }
    out.blockMin = bbox.min() - openvdb::Coord(pad);  // not used for S != 1; kept meaningful
    out.solveGrid.scale = S;
    out.solveGrid.corner = c0;
    const openvdb::Vec3d corner = xf.indexToWorld(c0);
    m.origin = {corner.x(), corner.y(), corner.z()};

    // Per axis, the input voxels each solve voxel reads and their weights. The 3D weights
    // are products (the voxels are boxes on the same axes). Only the active bounding box
    // can hold active values, so taps outside it are dropped.
    std::vector<std::vector<Tap>> taps[3];
    for (int a = 0; a < 3; ++a) {
        const int n = m.dim(a), bmin = bbox.min()[a], bmax = bbox.max()[a];
        taps[a].resize(size_t(n));
        for (int s = 0; s < n; ++s) {
            if (S < 1) {
                // The mean over the solve voxel of the piecewise-constant input (what
                // point sub-samples with nearest-voxel lookups converge to): input voxel i
                // covers [i - 0.5, i + 0.5) and weighs its overlap / the solve voxel's width.
                // Every input voxel's overlaps sum to its width, so optical depth is kept.
                const double lo = c0[a] + s / S, hi = c0[a] + (s + 1) / S;
                const int i0 = std::max(bmin, int(std::floor(lo + 0.5)));
                const int i1 = std::min(bmax, int(std::floor(hi + 0.5)));
                for (int i = i0; i <= i1; ++i) {
                    const double w = (std::min(hi, i + 0.5) - std::max(lo, i - 0.5)) * S;
                    if (w > 0) taps[a][size_t(s)].push_back({i, w});
                }
            } else {
                // Piecewise constant: the input voxel containing the solve voxel's centre.
                const int i = int(std::floor(c0[a] + (s + 0.5) / S + 0.5));
                if (i >= bmin && i <= bmax) taps[a][size_t(s)].push_back({i, 1.0});
            }
        }
    }

    m.sigmaT.assign(m.voxelCount(), 0.f);
    // Gather per solve voxel (each written once: no races; sums in a fixed order, so the
    // result does not depend on the thread count). Inactive voxels count as empty, as at S = 1.
    parallelForChunks(size_t(m.nz), 1, [&](size_t z0, size_t z1) {
        auto acc = grid.getConstAccessor();
        for (size_t z = z0; z < z1; ++z)
            for (int y = 0; y < m.ny; ++y)
                for (int x = 0; x < m.nx; ++x) {
                    double sum = 0;
                    for (const Tap& tz : taps[2][z])
                        for (const Tap& ty : taps[1][size_t(y)]) {
                            double row = 0;
                            for (const Tap& tx : taps[0][size_t(x)]) {
                                float v = 0;
                                if (acc.probeValue(openvdb::Coord(tx.index, ty.index, tz.index), v))
                                    row += tx.weight * double(v);
                            }
                            sum += tz.weight * ty.weight * row;
                        }
                    m.sigmaT[m.index(x, y, int(z))] = float(sum * o.densityScale);
                }
    });

    if (out.emission) {
        // S < 1: the mean of ceil(1/S)^3 stratified sub-samples (the emission grid may have
        // its own transform, so there is no exact overlap to use); S > 1: the centre sample.
        const int k = S < 1 ? int(std::ceil(1.0 / S - 1e-9)) : 1;
        sampleEmission(
            o, out,
            [&](int x, int y, int z, int jx, int jy, int jz) {
                const openvdb::Vec3d p(c0[0] + (x + (jx + 0.5) / k) / S, c0[1] + (y + (jy + 0.5) / k) / S,
                                       c0[2] + (z + (jz + 0.5) / k) / S);
                return xf.indexToWorld(p);
            },
            k);
    }
}

/// One flag per 8^3 tile of the S = 1 block (low corner index `lo`, `dim` voxels; order
/// tx + tnx*(ty + tny*tz)): set where the tile holds an active voxel or a voxel of the
/// lighting shell around one, so the solver computes S wherever the bake writes it. The
/// block's pad is at least kLightingShell, so every shell voxel is inside it.
std::vector<std::uint8_t> tilesToStore(const openvdb::FloatGrid& grid, const openvdb::Coord& lo,
                                       const openvdb::Coord& dim) {
    Medium probe;
    probe.nx = dim.x();
    probe.ny = dim.y();
    probe.nz = dim.z();
    std::vector<std::uint8_t> active(size_t(probe.tilesX()) * probe.tilesY() * probe.tilesZ(), 0);
    auto mark = [&](const openvdb::Coord& c) {  // the tiles of the voxels within the shell of c
        int t0[3], t1[3];
        for (int a = 0; a < 3; ++a) {
            const int d = c[a] - lo[a];
            t0[a] = (d - kLightingShell) / Medium::kTile;
            t1[a] = (d + kLightingShell) / Medium::kTile;
        }
        for (int tz = t0[2]; tz <= t1[2]; ++tz)
            for (int ty = t0[1]; ty <= t1[1]; ++ty)
                for (int tx = t0[0]; tx <= t1[0]; ++tx)
                    active[size_t(tx) + size_t(probe.tilesX()) * (size_t(ty) + size_t(probe.tilesY()) * tz)] = 1;
    };
    for (auto it = grid.tree().cbeginValueOn(); it; ++it) {
        if (it.isVoxelValue()) {
            mark(it.getCoord());
        } else {
            const openvdb::CoordBBox tb = it.getBoundingBox();
            for (auto c = tb.begin(); c; ++c) mark(*c);
        }
    }
    return active;
}

}  // namespace

void initOpenVdb() {
    static std::once_flag once;
    std::call_once(once, [] {
        openvdb::initialize();
        // OpenVDB's own log lines (e.g. duplicate grid names) would repeat our warnings in
        // another format; keep its errors only.
        openvdb::logging::setLevel(openvdb::logging::Level::Error);
    });
}

std::string describeGrid(const openvdb::GridBase& g) {
    std::ostringstream s;
    s << "'" << g.getName() << "' (" << g.valueType() << ", " << gridClassName(g) << ")";
    return s.str();
}

/// A Vec3f emission grid of black-body radiance from a temperature grid (Kelvin = value *
/// scale + offset), in the working colour space: intensity * blackbody(K), where a 6500 K
/// black body has luminance 1. Temperatures are tabulated every 10 K up to 40000 K.
openvdb::Vec3SGrid::Ptr temperatureToEmission(const openvdb::FloatGrid& t, const VolumeReadOptions& o) {
    constexpr int kSteps = 4001;
    constexpr double kStep = 10.0;
    std::vector<float> table(size_t(kSteps) * 3);
    for (int i = 0; i < kSteps; ++i) {
        const RGB c = blackbodyRec709(i * kStep);
        for (int k = 0; k < 3; ++k) table[size_t(i) * 3 + k] = c[k] * float(o.temperatureIntensity);
    }
    convertColor(table, "lin_rec709", o.workingSpace);
    auto e = openvdb::Vec3SGrid::create(openvdb::Vec3s(0.f));
    e->setTransform(t.transform().copy());
    e->setName(t.getName());
    e->tree().topologyUnion(t.tree());
    auto acc = e->getAccessor();
    std::uint64_t bad = 0;
    for (auto it = t.cbeginValueOn(); it; ++it) {
        const double kelvin = double(*it) * o.temperatureScale + o.temperatureOffset;
        if (!std::isfinite(kelvin)) {
            ++bad;
            continue;
        }
        const double x = std::clamp(kelvin / kStep, 0.0, double(kSteps - 1));
        const int i0 = std::min(int(x), kSteps - 2);
        const float f = float(x - i0);
        openvdb::Vec3s v;
        for (int k = 0; k < 3; ++k)
            v[k] = std::max(0.f, table[size_t(i0) * 3 + k] * (1 - f) + table[size_t(i0 + 1) * 3 + k] * f);
        if (it.isVoxelValue()) {
            acc.setValue(it.getCoord(), v);
        } else {
            e->fill(it.getBoundingBox(), v, true);
        }
    }
    if (bad > 0 && !o.sanitize)
        throw InputError(kComp, "temperature grid '" + o.temperatureGrid + "' has " + std::to_string(bad) +
                                    " NaN/infinite value(s); pass --sanitize to treat them as 0 K");
    return e;
}

void VolumeReadOptions::validate() const {
    auto finite = [](const char* field, double v) {
        if (!std::isfinite(v)) throw SettingError(kComp, field, "must be finite, got " + std::to_string(v));
    };
    auto nonNegative = [&](const char* field, double v) {
        finite(field, v);
        if (!(v >= 0)) throw SettingError(kComp, field, "must be finite and non-negative, got " + std::to_string(v));
    };
    nonNegative("densityScale", densityScale);
    nonNegative("emissionScale", emissionScale);
    finite("temperatureScale", temperatureScale);
    finite("temperatureOffset", temperatureOffset);
    nonNegative("temperatureIntensity", temperatureIntensity);
    if (!std::isfinite(solveScale) || solveScale < kMinSolveScale || solveScale > kMaxSolveScale)
        throw SettingError(kComp, "solveScale", "must be finite and in [0.05, 8], got " + std::to_string(solveScale));
    if (maxDenseVoxels == 0) throw SettingError(kComp, "maxDenseVoxels", "must be positive");
}

VolumeInput readVolume(const VolumeReadOptions& o) {
    o.validate();
    VolumeInput out;
    VdbFile file(o.path);
    openvdb::GridPtrVecPtr metas = file.gridMetadata();
    for (const auto& m : *metas) out.gridsInFile.push_back(describeGrid(*m));

    openvdb::GridBase::Ptr base =
        readNamed(file, o.path, o.gridName, o.gridIndex, *metas, out.gridsInFile, out.warnings, "density");
    const std::string where = "grid '" + o.gridName + "' in '" + o.path + "'";
    openvdb::FloatGrid::Ptr grid = openvdb::gridPtrCast<openvdb::FloatGrid>(base);
    if (!grid)
        throw InputError(kComp,
                         where + " holds " + base->valueType() +
                             " values; lpmbake needs a scalar float grid (choose one with --grid; grids present: " +
                             listGrids(out.gridsInFile) + ")");
    if (grid->getGridClass() == openvdb::GRID_LEVEL_SET) {
        if (!o.convertLevelSet)
            throw InputError(kComp, where +
                                        " is a level set (signed distance), not a density; convert it to a fog "
                                        "volume with openvdb::tools::sdfToFogVolume (or pass --convert-level-set "
                                        "to do so here)");
        // sdfToFogVolume: interior 0..1 ramp over the narrow band, 1 deep inside, inactive outside.
        openvdb::tools::sdfToFogVolume(*grid);
        out.warnings.push_back(where + " is a level set: converted to a fog volume (tools::sdfToFogVolume)");
    } else if (grid->getGridClass() != openvdb::GRID_FOG_VOLUME && grid->getGridClass() != openvdb::GRID_UNKNOWN) {
        out.warnings.push_back(where + " has grid class '" + gridClassName(*grid) + "'; treating it as a density");
    }

    if (!o.emissionGrid.empty()) {
        out.emission = readNamed(file, o.path, o.emissionGrid, -1, *metas, out.gridsInFile, out.warnings, "emission");
        if (!out.emission->isType<openvdb::FloatGrid>() && !out.emission->isType<openvdb::Vec3SGrid>())
            throw InputError(kComp, "emission grid '" + o.emissionGrid + "' in '" + o.path + "' holds " +
                                        out.emission->valueType() + " values; expected float or vec3s");
    }
    if (!o.temperatureGrid.empty()) {
        if (out.emission) throw InputError(kComp, "use either --emission-grid or --temperature-grid, not both");
        auto tb = readNamed(file, o.path, o.temperatureGrid, -1, *metas, out.gridsInFile, out.warnings, "temperature");
        auto t = openvdb::gridPtrCast<openvdb::FloatGrid>(tb);
        if (!t)
            throw InputError(kComp, "temperature grid '" + o.temperatureGrid + "' in '" + o.path + "' holds " +
                                        tb->valueType() + " values; expected float (Kelvin)");
        out.emission = temperatureToEmission(*t, o);
    }
    gridToMedium(*grid, o, out);  // sets out.density to the (possibly sanitised) copy
    return out;
}

void markWantedS(VolumeInput& v) {
    if (v.empty || v.solveGrid.scale != 1.0 || v.solveGrid.affine || !v.density) return;
    v.medium.wantedS = lightingVoxelFlags(*v.density, v.blockMin, v.medium);
}

void gridToMedium(const openvdb::FloatGrid& gridIn, const VolumeReadOptions& o, VolumeInput& out) {
    // Work on a grid we may modify (sanitising); the caller's shared pointer is replaced
    // only through out.density in readVolume, so copy when called directly.
    openvdb::FloatGrid::Ptr grid = gridIn.deepCopy();
    const std::string where = "grid '" + gridIn.getName() + "'" + (o.path.empty() ? "" : " in '" + o.path + "'");

    o.validate();
    if (!grid->transform().isLinear())
        throw InputError(kComp, where +
                                    " has a non-linear (frustum) transform; resample it to a linear transform "
                                    "first (e.g. openvdb::tools::resampleToMatch)");
    if (grid->background() != 0.f)
        out.warnings.push_back(where + " has background " + std::to_string(grid->background()) +
                               "; inactive voxels are treated as empty");

    float example = 0;
    const std::uint64_t bad = scanBadValues(*grid, o.sanitize, example);
    if (bad > 0 && !o.sanitize) {
        std::ostringstream s;
        s << where << " has " << bad << " NaN, infinite or negative value(s) (e.g. " << example
          << "); pass --sanitize to clamp them to 0";
        throw InputError(kComp, s.str());
    }
    if (bad > 0)
        out.warnings.push_back(where + ": --sanitize clamped " + std::to_string(bad) +
                               " NaN/infinite/negative value(s) to 0");
    out.sanitized = bad;
    out.activeVoxels = grid->activeVoxelCount();

    // Frame: index->world axis vectors give voxel sizes (lengths) and the rotation.
    const openvdb::math::Transform& xf = grid->transform();
    const openvdb::Vec3d o0 = xf.indexToWorld(openvdb::Vec3d(0, 0, 0));
    openvdb::Vec3d axis[3];
    Medium& m = out.medium;
    for (int a = 0; a < 3; ++a) {
        openvdb::Vec3d e(0, 0, 0);
        e[a] = 1;
        axis[a] = xf.indexToWorld(e) - o0;
        m.voxelSize[a] = axis[a].length();
        if (!(m.voxelSize[a] > 0) || !std::isfinite(m.voxelSize[a]))
            throw InputError(kComp, where + " has a degenerate transform (voxel size " +
                                        std::to_string(m.voxelSize[a]) + " along index axis " + std::to_string(a) +
                                        ")");
        axis[a] /= m.voxelSize[a];
    }
    bool sheared = false;
    for (int a = 0; a < 3; ++a)
        for (int b = a + 1; b < 3; ++b) sheared |= std::fabs(axis[a].dot(axis[b])) > 1e-5;
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) m.localToWorld.m[r * 3 + c] = axis[c][r];  // column c = world axis c

    if (out.activeVoxels == 0) {
        out.empty = true;
        out.warnings.push_back(where + " has no active voxels: writing an empty bake");
        out.density = grid;
        return;
    }
    const openvdb::CoordBBox bbox = grid->evalActiveVoxelBoundingBox();
    const int pad = std::max(kLightingShell, o.pad);  // the lighting shell must lie inside the block
    const double S = o.solveScale;
    if (!(S > 0) || !std::isfinite(S))
        throw InputError(kComp, "solve scale must be positive and finite, got " + std::to_string(S));
    if (sheared) {
        resampleSheared(*grid, bbox, pad, o, where, out);
        out.density = grid;
        return;
    }
    if (S != 1.0) {
        resampleToSolveGrid(*grid, bbox, pad, o, where, out);
        out.density = grid;
        return;
    }
    const openvdb::Coord lo = bbox.min() - openvdb::Coord(pad);
    const openvdb::Coord dim = bbox.dim() + openvdb::Coord(2 * pad);
    const std::uint64_t count = std::uint64_t(dim.x()) * dim.y() * dim.z();
    // The tile mask itself is one byte per 8^3 tile of the bounding box: refuse absurd boxes.
    if (count / Medium::kTileVoxels > (std::uint64_t(1) << 32))
        throw InputError(kComp, where + ": the active bounding box " + std::to_string(dim.x()) + "x" +
                                    std::to_string(dim.y()) + "x" + std::to_string(dim.z()) +
                                    " is too large to tile (more than 2^32 tiles of 8^3)");
    // Dense 8^3 tiles over the block; only the tiles tilesToStore() marks are allocated, so
    // memory follows the active region rather than its bounding box.
    {
        const std::vector<std::uint8_t> active = tilesToStore(*grid, lo, dim);
        std::uint64_t tiles = 0;
        for (std::uint8_t a : active) tiles += a;
        const std::uint64_t stored = tiles * Medium::kTileVoxels;
        if (stored > o.maxDenseVoxels)
            throw InputError(kComp, where + ": the active region needs " + std::to_string(tiles) + " tiles of 8^3 = " +
                                        std::to_string(stored) + " voxels (bounding box " + std::to_string(dim.x()) +
                                        "x" + std::to_string(dim.y()) + "x" + std::to_string(dim.z()) +
                                        "), above the limit of " + std::to_string(o.maxDenseVoxels) +
                                        " (--max-voxels; or solve on a coarser grid with --solve-scale below 1)");
        m.allocate(dim.x(), dim.y(), dim.z(), &active);
    }
    out.blockMin = lo;
    out.solveGrid.scale = 1.0;
    out.solveGrid.corner = openvdb::Vec3d(lo.x() - 0.5, lo.y() - 0.5, lo.z() - 0.5);
    const openvdb::Vec3d corner = xf.indexToWorld(openvdb::Vec3d(lo.x() - 0.5, lo.y() - 0.5, lo.z() - 0.5));
    m.origin = {corner.x(), corner.y(), corner.z()};

    const float scale = float(o.densityScale);
    auto put = [&](const openvdb::Coord& c, float v) {
        const openvdb::Coord d = c - lo;
        m.sigmaT[m.index(d.x(), d.y(), d.z())] = v * scale;
    };
    // Leaves in parallel (each voxel written once: no races), then active tiles.
    openvdb::tree::LeafManager<const openvdb::FloatTree> leaves(grid->tree());
    leaves.foreach ([&](const openvdb::FloatTree::LeafNodeType& leaf, size_t) {
        for (auto it = leaf.cbeginValueOn(); it; ++it) put(it.getCoord(), *it);
    });
    for (auto it = grid->tree().cbeginValueOn(); it; ++it) {
        if (it.isVoxelValue()) continue;
        const openvdb::CoordBBox tb = it.getBoundingBox();
        for (auto c = tb.begin(); c; ++c) put(*c, *it);
    }

    if (out.emission)
        sampleEmission(
            o, out,
            [&](int x, int y, int z, int, int, int) {
                return xf.indexToWorld(openvdb::Vec3d(lo.x() + x, lo.y() + y, lo.z() + z));
            },
            1);
    out.density = grid;
}

}  // namespace lpm

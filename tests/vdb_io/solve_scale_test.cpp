// --solve-scale in vdb_io: the resampled solve Medium (placement, down-sampling by the
// volume mean, up-sampling by the containing voxel, emission, the memory guard) and the
// interpolation of a resampled result back onto the input's voxels in writeBake.
#include <gtest/gtest.h>

#include <cmath>
#include <utility>

#include "test_helpers.h"
#include "vdb_io/bake_file.h"
#include "vdb_io/io_error.h"
#include "vdb_io/volume_reader.h"

using namespace lpm;

namespace {

VolumeInput toMedium(const openvdb::FloatGrid& g, double solveScale, double densityScale = 1.0) {
    VolumeReadOptions o;
    o.solveScale = solveScale;
    o.densityScale = densityScale;
    VolumeInput v;
    gridToMedium(g, o, v);
    return v;
}

/// Total optical "mass": sum of sigma_t * voxel volume (sigma_t integrated over space).
double opticalMass(const Medium& m) {
    double s = 0;
    for (float v : m.sigmaT) s += double(v);
    return s * m.voxelVolume();
}

/// A non-trivial density: a lumpy ball with odd extents, values varying voxel to voxel,
/// an active tile-free sparse topology, a rotated, translated, non-cubic transform.
openvdb::FloatGrid::Ptr lumpyGrid() {
    initOpenVdb();
    auto g = openvdb::FloatGrid::create(0.f);
    g->setName("density");
    auto xf = openvdb::math::Transform::createLinearTransform(1.0);
    xf->preScale(openvdb::Vec3d(0.3, 0.45, 0.6));
    xf->postRotate(0.4, openvdb::math::Y_AXIS);
    xf->postTranslate(openvdb::Vec3d(-2, 1, 5));
    g->setTransform(xf);
    for (int z = -6; z <= 8; ++z)
        for (int y = -3; y <= 9; ++y)
            for (int x = -7; x <= 5; ++x) {
                const double r2 = (x + 1) * (x + 1) / 36.0 + (y - 3) * (y - 3) / 36.0 + (z - 1) * (z - 1) / 49.0;
                if (r2 > 1) continue;
                g->tree().setValue(openvdb::Coord(x, y, z),
                                   float(1.5 + std::sin(0.7 * x + 1.3 * y) * std::cos(0.5 * z)));
            }
    return g;
}

}  // namespace

// The solve grid keeps the input's axes, divides the voxel size by S and starts at the
// active bounding box's low corner minus the padding: one solve voxel for S <= 1, and for
// S > 1 enough (2 at S = 2, 5 at S = 8) that the centre of the lighting shell's input voxels
// (one input voxel outside the box) lies between solve-voxel centres.
TEST(SolveScale, GridPlacement) {
    auto g = lumpyGrid();
    const VolumeInput ref = toMedium(*g, 1.0);
    const std::pair<double, int> cases[] = {{0.5, 1}, {0.3, 1}, {2.0, 2}, {3.0, 2}, {8.0, 5}};  // S, pad
    for (const auto& [S, pad] : cases) {
        const VolumeInput v = toMedium(*g, S);
        const Medium& m = v.medium;
        EXPECT_EQ(v.solveGrid.scale, S);
        for (int a = 0; a < 3; ++a) {
            EXPECT_NEAR(m.voxelSize[a], ref.medium.voxelSize[a] / S, 1e-12) << "S " << S;
            // bbox extent (input voxels) covered by whole solve voxels, plus the pad twice.
            const int extent = ref.medium.dim(a) - 2;
            EXPECT_EQ(m.dim(a), int(std::ceil(extent * S - 1e-6)) + 2 * pad) << "S " << S << " axis " << a;
            // The shell voxels bmin - 1 and bmax + 1: block coordinates of their centres
            // (voxel centres at integer + 0.5) within [0.5, n - 0.5].
            const openvdb::Coord lo = g->evalActiveVoxelBoundingBox().min() - openvdb::Coord(1);
            const openvdb::Coord hi = g->evalActiveVoxelBoundingBox().max() + openvdb::Coord(1);
            EXPECT_GE((lo[a] - v.solveGrid.corner[a]) * S, 0.5 - 1e-9) << "S " << S;
            EXPECT_LE((hi[a] - v.solveGrid.corner[a]) * S, m.dim(a) - 0.5 + 1e-9) << "S " << S;
        }
        for (int i = 0; i < 9; ++i) EXPECT_NEAR(m.localToWorld.m[i], ref.medium.localToWorld.m[i], 1e-12);
        const openvdb::Coord bmin = g->evalActiveVoxelBoundingBox().min();
        const openvdb::Vec3d c = g->transform().indexToWorld(
            openvdb::Vec3d(bmin.x() - 0.5 - pad / S, bmin.y() - 0.5 - pad / S, bmin.z() - 0.5 - pad / S));
        EXPECT_NEAR(m.origin.x, c.x(), 1e-9);
        EXPECT_NEAR(m.origin.y, c.y(), 1e-9);
        EXPECT_NEAR(m.origin.z, c.z(), 1e-9);
        EXPECT_NO_THROW(m.validate());
    }
}

// (c) Down-sampling averages over the solve voxel's volume: the integral of sigma_t over
// space (sum of sigma_t * voxel volume) is unchanged. Exact in real arithmetic for every
// S (overlap weights), so float rounding is all that is left: 1e-5 relative.
TEST(SolveScale, DownsamplingPreservesOpticalDepth) {
    auto g = lumpyGrid();
    const double ref = opticalMass(toMedium(*g, 1.0, 0.7).medium);
    ASSERT_GT(ref, 0);
    for (double S : {0.5, 0.3, 0.25, 0.05, 2.0}) {
        const Medium m = toMedium(*g, S, 0.7).medium;
        EXPECT_NEAR(opticalMass(m) / ref, 1.0, 1e-5) << "S " << S;
    }
}

// A one-voxel-thick sheet is not aliased away at S = 0.25: every solve voxel crossing it
// holds a quarter of its density (point samples at solve-voxel centres would miss it or
// quadruple it).
TEST(SolveScale, ThinSheetIsAveragedNotAliased) {
    initOpenVdb();
    auto g = openvdb::FloatGrid::create(0.f);
    g->fill(openvdb::CoordBBox(openvdb::Coord(0, 0, 5), openvdb::Coord(15, 15, 5)), 2.f, true);
    g->tree().voxelizeActiveTiles();
    // Widen the bounding box along z so the sheet sits inside the block, not on its edge.
    g->tree().setValueOn(openvdb::Coord(0, 0, 0), 0.f);
    g->tree().setValueOn(openvdb::Coord(0, 0, 15), 0.f);
    const Medium m = toMedium(*g, 0.25).medium;
    ASSERT_EQ(m.nz, 4 + 2);
    // Input z = 5 lies in [4 - 0.5, 8 - 0.5): solve z index 1 + 1 (pad).
    for (int y = 1; y <= 4; ++y)
        for (int x = 1; x <= 4; ++x) {
            EXPECT_FLOAT_EQ(m.sigmaT[m.index(x, y, 2)], 0.5f);
            EXPECT_FLOAT_EQ(m.sigmaT[m.index(x, y, 1)], 0.f);
            EXPECT_FLOAT_EQ(m.sigmaT[m.index(x, y, 3)], 0.f);
        }
}

// S > 1: piecewise constant, every solve voxel holds the input voxel containing its centre.
TEST(SolveScale, UpsamplingIsPiecewiseConstant) {
    auto g = lumpyGrid();
    const VolumeInput v = toMedium(*g, 2.0, 3.0);
    const Medium& m = v.medium;
    auto acc = g->getConstAccessor();
    for (int z = 0; z < m.nz; ++z)
        for (int y = 0; y < m.ny; ++y)
            for (int x = 0; x < m.nx; ++x) {
                const openvdb::Vec3d p = v.solveGrid.corner + openvdb::Vec3d(x + 0.5, y + 0.5, z + 0.5) / 2.0;
                const openvdb::Coord c(int(std::floor(p.x() + 0.5)), int(std::floor(p.y() + 0.5)),
                                       int(std::floor(p.z() + 0.5)));
                float d = 0;
                if (!acc.probeValue(c, d)) d = 0;
                ASSERT_FLOAT_EQ(m.sigmaT[m.index(x, y, z)], float(d * 3.0)) << x << "," << y << "," << z;
            }
}

// Emission is averaged over the solve voxel the same way (ceil(1/S)^3 sub-samples,
// trilinear lookups). At S = 0.5 the 2^3 sub-samples of a solve voxel fall on the centres
// of the input voxels it covers, so a constant emission cube gives its value in every solve
// voxel inside it, including the surface ones, and 0 in the padding.
TEST(SolveScale, EmissionResampled) {
    initOpenVdb();
    const std::string dir = lpmtest::scratchDir();
    auto d = lpmtest::cubeGrid(8, 1.f, 0.5);
    auto e = lpmtest::cubeGrid(8, 4.f, 0.5, "heat");
    lpmtest::writeVdb(dir + "/e.vdb", {d, e});
    VolumeReadOptions o;
    o.path = dir + "/e.vdb";
    o.emissionGrid = "heat";
    o.emissionScale = 0.5;
    o.solveScale = 0.5;
    const VolumeInput v = readVolume(o);
    const Medium& m = v.medium;
    ASSERT_EQ(m.nx, 4 + 2);
    ASSERT_TRUE(m.hasEmission());
    EXPECT_FLOAT_EQ(m.emission[m.index(2, 2, 2)].g, 2.f);        // input voxels 2..3 on each axis
    EXPECT_FLOAT_EQ(m.emission[m.index(1, 2, 4)].r, 2.f);        // input voxels 0..1 / 6..7: the surface
    EXPECT_FLOAT_EQ(m.emission[m.index(0, 2, 2)].r, 0.f);        // padding
    for (float s : m.sigmaT) EXPECT_TRUE(s == 0.f || s == 1.f);  // whole input voxels: exact means
    // S = 0.3: 4^3 sub-samples; inside the cube still the constant, and finite, >= 0 everywhere.
    o.solveScale = 0.3;
    const VolumeInput w = readVolume(o);
    EXPECT_FLOAT_EQ(w.medium.emission[w.medium.index(2, 2, 2)].b, 2.f);  // covers input 2.83..6.17: inside
    for (const RGB& c : w.medium.emission) EXPECT_TRUE(c.r >= 0.f && c.r <= 2.f);
}

// The dense solve block obeys --max-voxels; the message names the size and the remedy.
TEST(SolveScale, MaxVoxelsAppliesToTheSolveBlock) {
    auto g = lpmtest::cubeGrid(10, 1.f);
    VolumeReadOptions o;
    o.maxDenseVoxels = 8 * Medium::kTileVoxels;  // the S = 1 block (10 + 2 pad) fits: 2^3 tiles of 8^3
    VolumeInput v;
    EXPECT_NO_THROW(gridToMedium(*g, o, v));
    o.solveScale = 2;  // 20 + 2 x 2 pad = 24^3 does not
    lpmtest::expectThrowWith<InputError>(
        [&] {
            VolumeInput w;
            gridToMedium(*g, o, w);
        },
        {"24x24x24 = 13824", "--max-voxels", "smaller --solve-scale"});
    // A huge S on a huge extent is refused, not overflowed.
    auto big = lpmtest::cubeGrid(2, 1.f);
    big->tree().setValueOn(openvdb::Coord(1 << 28, 0, 0), 1.f);
    o.solveScale = 8;
    lpmtest::expectThrowWith<InputError>(
        [&] {
            VolumeInput w;
            gridToMedium(*big, o, w);
        },
        {"--max-voxels"});
}

// Mapping back: the dense values are interpolated trilinearly at the input voxel centres,
// so a field linear in space is reproduced exactly inside the block and clamped outside
// the outermost voxel centres.
TEST(SolveScale, WriteInterpolatesTrilinearly) {
    initOpenVdb();
    const std::string dir = lpmtest::scratchDir();
    auto density = lpmtest::cubeGrid(8, 1.f, 0.5);
    DenseBake b;
    b.scale = 0.5;
    b.corner = openvdb::Vec3d(-2.5);  // bbox corner -0.5 minus one solve voxel (2 input voxels)
    b.nx = b.ny = b.nz = 6;
    b.coeffs = 1;
    // Value at a dense voxel centre: linear in its index-space position.
    auto field = [](const openvdb::Vec3d& p) { return float(1.0 + 0.25 * p.x() - 0.5 * p.y() + 0.125 * p.z()); };
    std::vector<float> sh(size_t(6 * 6 * 6) * 3);
    for (int z = 0; z < 6; ++z)
        for (int y = 0; y < 6; ++y)
            for (int x = 0; x < 6; ++x) {
                const openvdb::Vec3d c = b.corner + openvdb::Vec3d(x + 0.5, y + 0.5, z + 0.5) / b.scale;
                const size_t i = size_t(x + 6 * (y + 6 * z));
                sh[i * 3 + 0] = field(c);
                sh[i * 3 + 1] = 2 * field(c);
                sh[i * 3 + 2] = 0.f;
            }
    b.sh = sh.data();
    BakeWriteOptions wo;
    wo.path = dir + "/b.vdb";
    BakeWriteReport rep = writeBake(*density, b, openvdb::MetaMap(), wo);
    EXPECT_EQ(rep.shellDropped, 0u);
    const BakeFile f = readBakeFile(wo.path);
    ASSERT_EQ(f.sh.size(), 1u);
    lpmtest::expectLightingTopology(*f.sh[0], *density);
    // Dense centres lie at index -1.5, 0.5, ..., 8.5: every input voxel (0..7) and every
    // shell voxel (-1 and 8) is inside, the field reproduced exactly.
    for (auto it = f.sh[0]->cbeginValueOn(); it; ++it) {
        const openvdb::Vec3d p = it.getCoord().asVec3d();
        EXPECT_NEAR((*it)[0], field(p), 1e-5) << it.getCoord();
        EXPECT_NEAR((*it)[1], 2 * field(p), 1e-5);
    }
    // Clamping: shrink the block so input voxel 7 lies beyond the last centre along x.
    b.nx = 5;  // centres up to index 6.5
    std::vector<float> sh5(size_t(5 * 6 * 6) * 3);
    for (int z = 0; z < 6; ++z)
        for (int y = 0; y < 6; ++y)
            for (int x = 0; x < 5; ++x)
                for (int c = 0; c < 3; ++c)
                    sh5[size_t(x + 5 * (y + 6 * z)) * 3 + c] = sh[size_t(x + 6 * (y + 6 * z)) * 3 + c];
    b.sh = sh5.data();
    rep = writeBake(*density, b, openvdb::MetaMap(), wo);
    const BakeFile f5 = readBakeFile(wo.path);
    auto acc = f5.sh[0]->getConstAccessor();
    const openvdb::Coord c7(7, 3, 4);
    EXPECT_NEAR(acc.getValue(c7)[0], field(openvdb::Vec3d(6.5, 3, 4)), 1e-5) << "clamped to the border centre";
    // The shell voxels beyond the last centre (the x = 8 plane, 10x10, and the x = 7 ring
    // around the density's face, 10x10 - 8x8) would be clamped too, i.e. extrapolated: they
    // are left out instead; the density's own voxels (x = 7) stay.
    EXPECT_EQ(rep.shellDropped, 100u + 36u);
    EXPECT_FALSE(acc.isValueOn(openvdb::Coord(8, 3, 4)));
    EXPECT_TRUE(acc.isValueOn(openvdb::Coord(-1, 3, 4)));
}

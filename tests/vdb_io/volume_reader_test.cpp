// vdb_io/volume_reader: grid selection, refusals, frames and values of the dense Medium.
#include "vdb_io/volume_reader.h"

#include <gtest/gtest.h>

#include <sys/resource.h>
#include <functional>

#include <openvdb/tools/LevelSetSphere.h>

#include "test_helpers.h"
#include "vdb_io/bake_file.h"
#include "vdb_io/io_error.h"
#include "vdb_io/lighting_topology.h"

using namespace lpm;
using lpmtest::dataPath;
using lpmtest::expectThrowWith;

namespace {

VolumeReadOptions opts(const std::string& path, const std::string& grid = "density") {
    VolumeReadOptions o;
    o.path = path;
    o.gridName = grid;
    return o;
}

bool hasWarning(const VolumeInput& v, const std::string& part) {
    for (const auto& w : v.warnings)
        if (w.find(part) != std::string::npos) return true;
    return false;
}

}  // namespace

// A grid with a known non-uniform scale and translation: origin, dims, values.
TEST(VolumeReader, BlockOriginVoxelSizeAndValues) {
    initOpenVdb();
    const std::string dir = lpmtest::scratchDir();
    auto g = openvdb::FloatGrid::create(0.f);
    g->setName("density");
    auto xf = openvdb::math::Transform::createLinearTransform(1.0);
    xf->preScale(openvdb::Vec3d(0.5, 1.0, 2.0));
    xf->postTranslate(openvdb::Vec3d(10, 20, 30));
    g->setTransform(xf);
    g->tree().setValue(openvdb::Coord(1, 2, 3), 2.0f);
    g->tree().setValue(openvdb::Coord(4, 2, 3), 1.0f);
    lpmtest::writeVdb(dir + "/a.vdb", {g});

    VolumeReadOptions o = opts(dir + "/a.vdb");
    o.densityScale = 3.0;
    const VolumeInput v = readVolume(o);
    const Medium& m = v.medium;
    EXPECT_FALSE(v.empty);
    EXPECT_EQ(v.activeVoxels, 2u);
    // bbox x 1..4, y 2..2, z 3..3, plus one voxel of padding on each side.
    EXPECT_EQ(m.nx, 6);
    EXPECT_EQ(m.ny, 3);
    EXPECT_EQ(m.nz, 3);
    EXPECT_EQ(v.blockMin, openvdb::Coord(0, 1, 2));
    EXPECT_NEAR(m.voxelSize.x, 0.5, 1e-12);
    EXPECT_NEAR(m.voxelSize.y, 1.0, 1e-12);
    EXPECT_NEAR(m.voxelSize.z, 2.0, 1e-12);
    // Low corner of dense voxel 0 = world position of index blockMin - 0.5.
    EXPECT_NEAR(m.origin.x, 10 + 0.5 * (0 - 0.5), 1e-12);
    EXPECT_NEAR(m.origin.y, 20 + 1.0 * (1 - 0.5), 1e-12);
    EXPECT_NEAR(m.origin.z, 30 + 2.0 * (2 - 0.5), 1e-12);
    EXPECT_FLOAT_EQ(m.sigmaT[m.index(1, 1, 1)], 6.0f);  // index (1,2,3)
    EXPECT_FLOAT_EQ(m.sigmaT[m.index(4, 1, 1)], 3.0f);  // index (4,2,3)
    EXPECT_FLOAT_EQ(m.sigmaT[m.index(2, 1, 1)], 0.0f);
    double sum = 0;
    for (float s : m.sigmaT) sum += s;
    EXPECT_DOUBLE_EQ(sum, 9.0);
    EXPECT_NO_THROW(m.validate());
}

// The rotation part of the transform becomes localToWorld (columns = world index axes).
TEST(VolumeReader, MemoryFollowsActiveTilesNotTheBoundingBox) {
    // Two 5^3 puffs 300 voxels apart: the bounding box is ~300^3 = 27M voxels, but only
    // the 8^3 tiles that hold active voxels are stored.
    initOpenVdb();
    const std::string dir = lpmtest::scratchDir();
    auto g = openvdb::FloatGrid::create(0.f);
    g->setName("density");
    g->fill(openvdb::CoordBBox(openvdb::Coord(0), openvdb::Coord(4)), 0.5f, true);
    g->fill(openvdb::CoordBBox(openvdb::Coord(300), openvdb::Coord(304)), 0.25f, true);
    g->tree().voxelizeActiveTiles();
    lpmtest::writeVdb(dir + "/far.vdb", {g});
    const VolumeInput v = readVolume(opts(dir + "/far.vdb"));
    const Medium& m = v.medium;
    EXPECT_TRUE(m.sparse());
    EXPECT_GT(m.blockVoxelCount(), 27000000u);
    EXPECT_LE(m.voxelCount(), 16 * Medium::kTileVoxels);  // at most 8 tiles per puff (pad may straddle)
    double optical = 0;
    for (float s : m.sigmaT) optical += s;
    EXPECT_NEAR(optical, 125 * 0.5 + 125 * 0.25, 1e-4);
    EXPECT_FLOAT_EQ(m.sigmaT[m.index(1 + 2, 1 + 2, 1 + 2)], 0.5f);  // index (2,2,2), pad 1
    EXPECT_EQ(m.index(150, 150, 150), Medium::npos);
    EXPECT_NO_THROW(m.validate());
}

// The bake writes S on the one-voxel shell around the active voxels, so the sparse block
// stores every 8^3 tile a shell voxel falls in (the solver computes S there), and only those.
TEST(VolumeReader, TilesHoldTheLightingShell) {
    initOpenVdb();
    auto g = openvdb::FloatGrid::create(0.f);
    for (int x : {0, 6, 40}) g->tree().setValue(openvdb::Coord(x, 0, 0), 1.f);
    VolumeInput v;
    gridToMedium(*g, opts(""), v);  // block x: index -1..41 (pad 1), block voxel = index + 1
    const Medium& m = v.medium;
    ASSERT_TRUE(m.sparse());
    EXPECT_NE(m.index(7, 1, 1), Medium::npos);   // index 6: tile 0
    EXPECT_NE(m.index(8, 1, 1), Medium::npos);   // index 7, its shell: tile 1, holds no active voxel
    EXPECT_EQ(m.index(16, 1, 1), Medium::npos);  // tile 2: nothing within a voxel
    EXPECT_EQ(m.index(39, 1, 1), Medium::npos);  // tile 4 (block 32..39): index 40's shell starts at block 40
    EXPECT_NE(m.index(42, 1, 1), Medium::npos);  // index 41, the shell of 40: tile 5
    EXPECT_EQ(m.storedTiles, 3u);
}

TEST(VolumeReader, RotatedTransformGivesLocalToWorld) {
    initOpenVdb();
    auto g = lpmtest::cubeGrid(3, 1.f, 0.25);
    g->transform().postRotate(0.7, openvdb::math::Y_AXIS);
    VolumeInput v;
    gridToMedium(*g, opts(""), v);
    for (int a = 0; a < 3; ++a) {
        openvdb::Vec3d e(0.0);
        e[a] = 1;
        const openvdb::Vec3d w = g->transform().indexToWorld(e) - g->transform().indexToWorld(openvdb::Vec3d(0.0));
        Vec3 local(0, 0, 0);
        local[a] = 1;
        const Vec3 r = v.medium.localToWorld * local;
        for (int c = 0; c < 3; ++c) EXPECT_NEAR(r[c], w[c] / 0.25, 1e-9) << "axis " << a;
        EXPECT_NEAR(v.medium.voxelSize[a], 0.25, 1e-12);
    }
}

TEST(VolumeReader, NonCubicVoxelsFromDensityAndHeat) {
    const VolumeInput v = readVolume(opts(dataPath("vdb/densityAndHeat.vdb")));
    ASSERT_FALSE(v.empty);
    // Compare with OpenVDB's own view of the transform, read independently.
    openvdb::io::File f(dataPath("vdb/densityAndHeat.vdb"));
    f.open(false);
    const openvdb::Vec3d vs = f.readGrid("density")->voxelSize();
    for (int a = 0; a < 3; ++a) EXPECT_NEAR(v.medium.voxelSize[a], vs[a], 1e-9);
    EXPECT_GT(std::fabs(v.medium.voxelSize.z - v.medium.voxelSize.x), 1e-3) << "the file has non-cubic voxels";
    EXPECT_NEAR(v.medium.voxelSize.x, 0.703, 0.001);  // data/README.md
    EXPECT_NEAR(v.medium.voxelSize.z, 0.716, 0.001);
    EXPECT_NO_THROW(v.medium.validate());
}

TEST(VolumeReader, CustomGridNameAndMissingGridListsGrids) {
    const std::string path = dataPath("vdb/torus01.vdb");
    expectThrowWith<InputError>([&] { readVolume(opts(path)); }, {"torus01.vdb", "'density'", "voxel_fog_density"});
    const VolumeInput v = readVolume(opts(path, "voxel_fog_density"));
    EXPECT_GT(v.activeVoxels, 0u);
    double sum = 0;
    for (float s : v.medium.sigmaT) sum += s;
    EXPECT_GT(sum, 0);
}

TEST(VolumeReader, DuplicateNamesUseGridIndex) {
    const std::string path = dataPath("vdb/grids_same_name.vdb");
    const VolumeInput first = readVolume(opts(path));
    EXPECT_TRUE(hasWarning(first, "3 grids named 'density'"));
    // Each index must select the grid at that position among the same-named grids.
    openvdb::io::File f(path);
    f.open(false);
    auto metas = f.readAllGridMetadata();
    std::vector<openvdb::math::Transform::Ptr> xfs;
    for (auto& m : *metas)
        if (m->getName() == "density") xfs.push_back(m->transformPtr());
    ASSERT_EQ(xfs.size(), 3u);
    std::vector<Vec3> origins;
    for (int i = 0; i < 3; ++i) {
        VolumeReadOptions o = opts(path);
        o.gridIndex = i;
        const VolumeInput v = readVolume(o);
        EXPECT_FALSE(hasWarning(v, "grids named")) << "an explicit index needs no warning";
        EXPECT_TRUE(*v.density->transformPtr() == *xfs[i]) << "grid index " << i;
        origins.push_back(v.medium.origin);
    }
    EXPECT_GT(length(origins[0] - origins[1]) + length(origins[1] - origins[2]), 0) << "three different grids";
    VolumeReadOptions o = opts(path);
    o.gridIndex = 3;
    expectThrowWith<InputError>([&] { readVolume(o); }, {"--grid-index 3", "3 grid(s)"});
}

TEST(VolumeReader, EmptyFrameAndNonFloatGrids) {
    const std::string path = dataPath("vdb/smoke_seq.0001.vdb");
    const VolumeInput v = readVolume(opts(path));
    EXPECT_TRUE(v.empty);
    EXPECT_EQ(v.activeVoxels, 0u);
    EXPECT_TRUE(hasWarning(v, "no active voxels"));
    expectThrowWith<InputError>([&] { readVolume(opts(path, "velocity")); }, {"velocity", "vec3s", "scalar float"});
    expectThrowWith<InputError>([&] { readVolume(opts(path, "obstacles")); }, {"obstacles", "int32"});
}

TEST(VolumeReader, LevelSetRefusedUnlessConverted) {
    initOpenVdb();
    const std::string dir = lpmtest::scratchDir();
    auto ls = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(2.0f, openvdb::Vec3f(0.f), 0.25f);
    ls->setName("density");
    lpmtest::writeVdb(dir + "/ls.vdb", {ls});
    VolumeReadOptions o = opts(dir + "/ls.vdb");
    expectThrowWith<InputError>([&] { readVolume(o); }, {"level set", "sdfToFogVolume", "--convert-level-set"});
    o.convertLevelSet = true;
    const VolumeInput v = readVolume(o);
    EXPECT_FALSE(v.empty);
    float lo = 1e9f, hi = -1e9f;
    for (float s : v.medium.sigmaT) lo = std::min(lo, s), hi = std::max(hi, s);
    EXPECT_EQ(lo, 0.f);
    EXPECT_FLOAT_EQ(hi, 1.f);  // fog volume: 1 deep inside
    EXPECT_EQ(v.density->getGridClass(), openvdb::GRID_FOG_VOLUME);
}

TEST(VolumeReader, BadValuesErrorOrSanitize) {
    initOpenVdb();
    const std::string dir = lpmtest::scratchDir();
    auto g = lpmtest::cubeGrid(4, 1.f, 1.0, "smoke");
    g->tree().setValue(openvdb::Coord(0, 0, 0), std::numeric_limits<float>::quiet_NaN());
    g->tree().setValue(openvdb::Coord(1, 0, 0), std::numeric_limits<float>::infinity());
    g->tree().setValue(openvdb::Coord(2, 0, 0), -1.f);
    lpmtest::writeVdb(dir + "/bad.vdb", {g});
    VolumeReadOptions o = opts(dir + "/bad.vdb", "smoke");
    expectThrowWith<InputError>([&] { readVolume(o); }, {"'smoke'", "3 NaN", "--sanitize"});
    o.sanitize = true;
    const VolumeInput v = readVolume(o);
    EXPECT_EQ(v.sanitized, 3u);
    EXPECT_TRUE(hasWarning(v, "clamped 3"));
    for (float s : v.medium.sigmaT) EXPECT_TRUE(std::isfinite(s) && s >= 0);
    // The sanitised grid is the one passed on (it is copied into the output).
    EXPECT_EQ(v.density->tree().getValue(openvdb::Coord(0, 0, 0)), 0.f);
}

TEST(VolumeReader, EmissionGridSampledAtVoxels) {
    initOpenVdb();
    const std::string dir = lpmtest::scratchDir();
    auto d = lpmtest::cubeGrid(6, 1.f, 0.5);
    auto e = lpmtest::cubeGrid(6, 4.f, 0.5, "heat");
    lpmtest::writeVdb(dir + "/e.vdb", {d, e});
    VolumeReadOptions o = opts(dir + "/e.vdb");
    o.emissionGrid = "heat";
    o.emissionScale = 0.25;
    const VolumeInput v = readVolume(o);
    ASSERT_TRUE(v.medium.hasEmission());
    const Medium& m = v.medium;
    // Interior voxel (index 2,2,2 -> dense 3,3,3): trilinear sampling of a constant.
    const RGB c = m.emission[m.index(3, 3, 3)];
    EXPECT_FLOAT_EQ(c.r, 1.f);
    EXPECT_FLOAT_EQ(c.b, 1.f);
    EXPECT_FLOAT_EQ(m.emission[m.index(0, 0, 0)].g, 0.f);  // padding, outside the grid
    o.emissionGrid = "nope";
    expectThrowWith<InputError>([&] { readVolume(o); }, {"'nope'", "emission"});
}

TEST(VolumeReader, UnreadableFiles) {
    const std::string dir = lpmtest::scratchDir();
    expectThrowWith<InputError>([&] { readVolume(opts(dir + "/missing.vdb")); }, {"missing.vdb"});
    // A truncated copy of a real file.
    const std::string bytes = lpmtest::readBytes(dataPath("vdb/torus01.vdb"));
    lpmtest::writeBytes(dir + "/cut.vdb", bytes.substr(0, bytes.size() / 2));
    expectThrowWith<InputError>([&] { readVolume(opts(dir + "/cut.vdb", "voxel_fog_density")); },
                                {"cut.vdb", "truncated", "ends at byte " + std::to_string(bytes.size())});
}

// A truncated file must be refused before OpenVDB reads grid data: past the end of the
// stream its chunk reader takes a length from an uninitialised variable and allocates
// that many bytes (seen as a 3.5 TB request under AddressSanitizer). Every cut point,
// from inside the header to one byte short, gives the same clean error.
TEST(VolumeReader, TruncatedAnywhereIsNamedAsTruncated) {
    const std::string dir = lpmtest::scratchDir();
    const std::string bytes = lpmtest::readBytes(dataPath("vdb/torus01.vdb"));
    ASSERT_GT(bytes.size(), 1000u);
    for (size_t cut : {size_t(10), size_t(40), size_t(300), bytes.size() / 4, bytes.size() - 100, bytes.size() - 1}) {
        SCOPED_TRACE("cut at byte " + std::to_string(cut));
        const std::string path = dir + "/cut" + std::to_string(cut) + ".vdb";
        lpmtest::writeBytes(path, bytes.substr(0, cut));
        try {
            readVolume(opts(path, "voxel_fog_density"));
            ADD_FAILURE() << "a file cut at byte " << cut << " was read";
        } catch (const InputError& e) {
            const std::string what = e.what();
            EXPECT_NE(what.find(path), std::string::npos) << what;
            EXPECT_EQ(what.find('\n'), std::string::npos) << what;
            EXPECT_NE(what.find("truncated"), std::string::npos) << what;
        }
    }
}

// Fuzzing findings (scripts/fuzz.sh): 75 kB corrupt VDBs whose grid-descriptor length
// fields made OpenVDB allocate and zero ~5.9 GB. They must fail cleanly, with bounded
// memory, and (since the layout check runs before OpenVDB) also under AddressSanitizer.
TEST(VolumeReader, CorruptHeaderFailsWithoutHugeAllocation) {
    rusage before{};
    ::getrusage(RUSAGE_SELF, &before);
    for (const std::string name : {"vdb_header_oom.vdb", "vdb_header_oom2.vdb"}) {
        lpmtest::expectThrowWith<InputError>(
            [&] { readVolume(opts(std::string(LPM_SOURCE_DIR) + "/tests/fuzz/regressions/" + name)); },
            {name, "corrupt", "a grid name at byte 40347 needs"});
    }
    rusage after{};
    ::getrusage(RUSAGE_SELF, &after);
    EXPECT_LT(after.ru_maxrss - before.ru_maxrss, 1024L * 1024L);  // KiB: under 1 GiB of growth
}

// The read options validate themselves (one home for their ranges); readVolume checks
// them before touching the file.
TEST(VolumeReader, OptionsNameTheFieldOutOfRange) {
    auto field = [](const std::function<void(VolumeReadOptions&)>& breakIt) {
        VolumeReadOptions o;
        breakIt(o);
        try {
            o.validate();
        } catch (const SettingError& e) {
            return e.field();
        }
        return std::string();
    };
    EXPECT_EQ(field([](VolumeReadOptions&) {}), "");
    EXPECT_EQ(field([](VolumeReadOptions& o) { o.densityScale = -1; }), "densityScale");
    EXPECT_EQ(field([](VolumeReadOptions& o) { o.emissionScale = INFINITY; }), "emissionScale");
    EXPECT_EQ(field([](VolumeReadOptions& o) { o.temperatureOffset = NAN; }), "temperatureOffset");
    EXPECT_EQ(field([](VolumeReadOptions& o) { o.solveScale = kMaxSolveScale * 1.01; }), "solveScale");
    EXPECT_EQ(field([](VolumeReadOptions& o) { o.solveScale = kMinSolveScale; }), "");
    VolumeReadOptions bad;
    bad.path = "/no/such/file.vdb";
    bad.solveScale = 0;
    EXPECT_THROW(readVolume(bad), SettingError);
}

// At scale 1 the solver can be told where the bake writes S (Medium::wantedS): exactly the
// stored voxels lightingTopology() makes active, on voxels, an active 8^3 tile and a
// voxel at the block's edge, and on a real file.
TEST(VolumeReader, WantedVoxelsAreTheLightingTopology) {
    initOpenVdb();
    auto synthetic = openvdb::FloatGrid::create(0.f);
    synthetic->setName("density");
    for (int x : {0, 6, 23}) synthetic->tree().setValue(openvdb::Coord(x, 3, -2), 1.f);
    synthetic->tree().setValue(openvdb::Coord(9, 9, 9), 0.f);            // active, empty: still written
    synthetic->tree().addTile(1, openvdb::Coord(16, 8, 0), 0.5f, true);  // an active 8^3 tile
    std::vector<VolumeInput> inputs(2);
    gridToMedium(*synthetic, opts(""), inputs[0]);
    inputs[1] = readVolume(opts(dataPath("vdb/densityAndHeat.vdb")));
    for (VolumeInput& v : inputs) {
        EXPECT_TRUE(v.medium.wantedS.empty()) << "marked only when asked";
        markWantedS(v);
        const Medium& m = v.medium;
        ASSERT_EQ(m.wantedS.size(), m.voxelCount());
        DenseBake b;
        b.blockMin = v.blockMin;
        b.nx = m.nx;
        b.ny = m.ny;
        b.nz = m.nz;
        const std::vector<float> sh(m.voxelCount() * 3, 0.f);
        b.sh = sh.data();
        b.layout = &m;
        const LightingTopology lt = lightingTopology(*v.density, b);
        size_t wanted = 0, disagree = 0;
        for (size_t i = 0; i < m.voxelCount(); ++i) {
            int x, y, z;
            m.coord(i, x, y, z);
            const bool inBlock = x >= 0 && y >= 0 && z >= 0 && x < m.nx && y < m.ny && z < m.nz;
            const bool lit = inBlock && lt.grid->tree().isValueOn(v.blockMin + openvdb::Coord(x, y, z));
            disagree += lit != (m.wantedS[i] != 0);
            wanted += m.wantedS[i];
        }
        EXPECT_EQ(disagree, 0u);
        EXPECT_EQ(wanted, lt.grid->activeVoxelCount());
        EXPECT_LT(wanted, m.voxelCount());
    }
}

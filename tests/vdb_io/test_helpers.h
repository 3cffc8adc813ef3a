// Helpers shared by the vdb_io and baker tests: scratch directories, small synthetic
// VDB files and lat-long images.
#pragma once

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>

#include <OpenImageIO/imageio.h>
#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>

#include "core/math.h"
#include "vdb_io/volume_reader.h"

namespace lpmtest {

inline std::string dataPath(const std::string& rel) { return std::string(LPM_SOURCE_DIR) + "/data/" + rel; }

/// A fresh, empty directory for the running test (build tree, unique per test name).
inline std::string scratchDir() {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    const std::filesystem::path p = std::filesystem::path(LPM_BINARY_DIR) / "test_scratch" /
                                    (std::string(info->test_suite_name()) + "." + info->name());
    std::filesystem::remove_all(p);
    std::filesystem::create_directories(p);
    return p.string();
}

/// The whole file as bytes (empty if it cannot be read).
inline std::string readBytes(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

inline void writeBytes(const std::string& path, const std::string& bytes) {
    std::ofstream(path, std::ios::binary | std::ios::trunc) << bytes;
}

inline void writeVdb(const std::string& path, openvdb::GridPtrVec grids) {
    lpm::initOpenVdb();
    openvdb::io::File f(path);
    f.write(grids);
    f.close();
}

/// A fog-volume cube [0, n)^3 of constant `value`, voxel size `voxel`, named `name`.
inline openvdb::FloatGrid::Ptr cubeGrid(int n, float value, double voxel = 1.0, const std::string& name = "density") {
    lpm::initOpenVdb();
    auto g = openvdb::FloatGrid::create(0.f);
    g->setName(name);
    g->setGridClass(openvdb::GRID_FOG_VOLUME);
    g->setTransform(openvdb::math::Transform::createLinearTransform(voxel));
    g->fill(openvdb::CoordBBox(openvdb::Coord(0), openvdb::Coord(n - 1)), value, true);
    g->tree().voxelizeActiveTiles();
    return g;
}

/// Checks that `g` (a lighting grid of a bake) is active exactly on the active voxels of
/// `density` and every voxel within one voxel of one along each axis (the 26-neighbour
/// shell, docs/output_format.md "Topology"), built here voxel by voxel.
template <typename GridT>
void expectLightingTopology(const GridT& g, const openvdb::FloatGrid& density) {
    openvdb::MaskGrid want(false);
    auto acc = want.getAccessor();
    for (auto it = density.cbeginValueOn(); it; ++it) {
        openvdb::CoordBBox b = it.getBoundingBox();  // one voxel, or an active tile
        b.expand(1);
        for (auto c = b.begin(); c; ++c) acc.setValueOn(*c);
    }
    openvdb::MaskGrid missing(false), extra(false);
    missing.tree().topologyUnion(want.tree());
    missing.tree().topologyDifference(g.tree());
    extra.tree().topologyUnion(g.tree());
    extra.tree().topologyDifference(want.tree());
    EXPECT_EQ(missing.activeVoxelCount(), 0u) << g.getName() << ": voxels of the shell not written";
    EXPECT_EQ(extra.activeVoxelCount(), 0u) << g.getName() << ": voxels beyond the shell";
}

/// Centre direction (toward the light) of lat-long pixel (x, y) of a WxH image, written
/// from the OpenEXR ImfEnvmap formulas independently of core/envmap.cpp:
/// lon = pi - 2 pi u, lat = pi/2 - pi v, d = (cos lat sin lon, sin lat, cos lat cos lon).
inline lpm::Vec3 latLongDir(double x, double y, int w, int h) {
    const double u = (x + 0.5) / w, v = (y + 0.5) / h;
    const double lon = lpm::kPi - 2 * lpm::kPi * u, lat = lpm::kPi / 2 - lpm::kPi * v;
    return {std::cos(lat) * std::sin(lon), std::sin(lat), std::cos(lat) * std::cos(lon)};
}

/// Writes a float RGB EXR whose pixel (x, y) is f(direction of the pixel centre).
inline void writeLatLong(const std::string& path, int w, int h, const std::function<lpm::RGB(const lpm::Vec3&)>& f) {
    std::vector<float> px(size_t(w) * h * 3);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            const lpm::RGB c = f(latLongDir(x, y, w, h));
            for (int k = 0; k < 3; ++k) px[(size_t(y) * w + x) * 3 + k] = c[k];
        }
    auto out = OIIO::ImageOutput::create(path);
    ASSERT_TRUE(out);
    OIIO::ImageSpec spec(w, h, 3, OIIO::TypeDesc::FLOAT);
    ASSERT_TRUE(out->open(path, spec));
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::FLOAT, px.data()));
    out->close();
}

/// Expects `f` to throw an exception of type E whose message contains every string of `parts`.
template <typename E, typename F>
void expectThrowWith(F f, const std::vector<std::string>& parts) {
    try {
        f();
        ADD_FAILURE() << "no exception";
    } catch (const E& e) {
        const std::string m = e.what();
        for (const auto& p : parts) EXPECT_NE(m.find(p), std::string::npos) << "'" << p << "' not in: " << m;
    }
}

}  // namespace lpmtest

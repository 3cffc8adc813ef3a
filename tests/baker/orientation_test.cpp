// Lighting direction end to end: a sun (--sun, direction toward the sun) and an
// environment hot spot in the same direction must light a volume from the same side.
// With HG g > 0, S(x, w) peaks where light travels, w = -toward, so the l = 1 terms
// (sh_1 ~ y, sh_2 ~ z, sh_3 ~ x) have the sign of -toward. This ties together the CLI
// parsing, the lat-long loader (ImfEnvmap orientation), --env-rotate and the solver.
#include <gtest/gtest.h>

#include "../vdb_io/test_helpers.h"
#include "run_helpers.h"
#include "vdb_io/bake_file.h"

using namespace lpm;
using lpmtest::runLpmbake;

namespace {

std::string vec(const Vec3& d) {
    std::ostringstream s;
    s << d.x << "," << d.y << "," << d.z;
    return s.str();
}

/// l = 1 coefficients (red channel) of the centre voxel, as (x, y, z) components.
Vec3 firstBand(const std::string& path) {
    const BakeFile b = readBakeFile(path);
    EXPECT_GE(b.sh.size(), 4u);
    if (b.sh.size() < 4) return {};
    const openvdb::Coord c(4, 4, 4);
    return {b.sh[3]->tree().getValue(c)[0], b.sh[1]->tree().getValue(c)[0], b.sh[2]->tree().getValue(c)[0]};
}

void expectSameSide(const Vec3& band1, const Vec3& toward, const std::string& what) {
    for (int a = 0; a < 3; ++a) {
        EXPECT_LT(band1[a] * toward[a], 0)
            << what << ": axis " << a << " coefficient " << band1[a] << " toward " << toward[a];
    }
}

}  // namespace

TEST(Orientation, SunAndEnvironmentHotSpotAgree) {
    const std::string dir = lpmtest::scratchDir();
    lpmtest::writeVdb(dir + "/cube.vdb", {lpmtest::cubeGrid(9, 0.3f)});
    const Vec3 toward = normalize(Vec3(0.5, 0.6, -0.62));
    // Hot spot: pixels within 12 degrees of `toward`, black elsewhere.
    lpmtest::writeLatLong(dir + "/spot.exr", 128, 64, [&](const Vec3& d) {
        return dot(d, toward) > std::cos(12 * kPi / 180) ? RGB(50.f) : RGB(0.f);
    });
    const std::vector<std::string> common = {
        "--g", "0.6", "--sh-order", "1", "--albedo", "0.5", "--directions-per-face", "3", "--tolerance", "1e-2", "-q"};
    auto bake = [&](std::vector<std::string> a) {
        a.insert(a.begin(), dir + "/cube.vdb");
        a.insert(a.end(), common.begin(), common.end());
        const auto r = runLpmbake(a, dir);
        EXPECT_EQ(r.code, 0) << r.err;
    };
    bake({"--sun", vec(toward), "-o", dir + "/sun.vdb"});
    bake({"--env", dir + "/spot.exr", "-o", dir + "/env.vdb"});
    const Vec3 s = firstBand(dir + "/sun.vdb"), e = firstBand(dir + "/env.vdb");
    expectSameSide(s, toward, "sun");
    expectSameSide(e, toward, "environment hot spot");
    // Same direction, not just the same octant: the l = 1 vectors are nearly parallel.
    EXPECT_GT(dot(normalize(s), normalize(e)), 0.95);

    // --env-rotate 90 moves the hot spot to R_y(90) * toward.
    const Vec3 rotated = Mat3::rotation({0, 1, 0}, kPi / 2) * toward;
    bake({"--env", dir + "/spot.exr", "--env-rotate", "90", "-o", dir + "/env_rot.vdb"});
    bake({"--sun", vec(rotated), "-o", dir + "/sun_rot.vdb"});
    const Vec3 er = firstBand(dir + "/env_rot.vdb"), sr = firstBand(dir + "/sun_rot.vdb");
    expectSameSide(er, rotated, "rotated environment");
    expectSameSide(sr, rotated, "sun toward the rotated direction");
    EXPECT_GT(dot(normalize(er), normalize(sr)), 0.95);

    // --up-axis z turns the image frame: the spot lies at upAxisToWorld(Z, toward).
    const Vec3 zUp = upAxisToWorld(UpAxis::Z, toward);
    bake({"--env", dir + "/spot.exr", "--up-axis", "z", "-o", dir + "/env_z.vdb"});
    bake({"--sun", vec(zUp), "-o", dir + "/sun_z.vdb"});
    const Vec3 ez = firstBand(dir + "/env_z.vdb"), sz = firstBand(dir + "/sun_z.vdb");
    expectSameSide(ez, zUp, "Z-up environment");
    EXPECT_GT(dot(normalize(ez), normalize(sz)), 0.95);
    EXPECT_EQ(metaString(*readBakeFile(dir + "/env_z.vdb").meta, "lpm:up_axis"), "z");
}

// A sky (bright upper half of the image, dark lower half) lights a thick cube from the
// scene's up axis: +Y by default, +Z with --up-axis z (a Blender or Mantaflow volume).
TEST(Orientation, SkyLightsFromTheUpAxis) {
    const std::string dir = lpmtest::scratchDir();
    lpmtest::writeVdb(dir + "/cube.vdb", {lpmtest::cubeGrid(9, 2.0f)});
    lpmtest::writeLatLong(dir + "/sky.exr", 64, 32, [](const Vec3& d) { return d.y > 0 ? RGB(1.f) : RGB(0.f); });
    auto scatterAt = [&](const std::string& up, const openvdb::Coord& c) {
        const std::string out = dir + "/sky_" + up + ".vdb";
        const auto r = runLpmbake({dir + "/cube.vdb", "--env", dir + "/sky.exr", "--up-axis", up, "-o", out,
                                   "--directions-per-face", "2", "--tolerance", "1e-2", "-q"},
                                  dir);
        EXPECT_EQ(r.code, 0) << r.err;
        return readBakeFile(out).scatter->tree().getValue(c)[1];
    };
    const openvdb::Coord top(4, 8, 4), bottom(4, 0, 4), zTop(4, 4, 8), zBottom(4, 4, 0);
    EXPECT_GT(scatterAt("y", top), 3 * scatterAt("y", bottom));
    EXPECT_GT(scatterAt("z", zTop), 3 * scatterAt("z", zBottom));
    // Under a Z-up sky the cube's +Y and -Y faces are sides: lit alike within 10%.
    const float side1 = scatterAt("z", top), side2 = scatterAt("z", bottom);
    EXPECT_NEAR(side1, side2, 0.1 * side1);
}

// An overhead sun lights the top of a thick cube more than its bottom (direction-averaged
// S, the 'scatter' grid): the lit side faces the sun.
TEST(Orientation, OverheadSunLightsTheTop) {
    const std::string dir = lpmtest::scratchDir();
    lpmtest::writeVdb(dir + "/cube.vdb", {lpmtest::cubeGrid(9, 2.0f)});
    const auto r = runLpmbake({dir + "/cube.vdb", "--sun", "0,1,0", "-o", dir + "/o.vdb", "--directions-per-face", "2",
                               "--tolerance", "1e-2", "-q"},
                              dir);
    ASSERT_EQ(r.code, 0) << r.err;
    const BakeFile b = readBakeFile(dir + "/o.vdb");
    const float top = b.scatter->tree().getValue(openvdb::Coord(4, 8, 4))[1];
    const float bottom = b.scatter->tree().getValue(openvdb::Coord(4, 0, 4))[1];
    EXPECT_GT(top, 3 * bottom) << "top " << top << " bottom " << bottom;
}

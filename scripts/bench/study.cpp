// The accuracy study's reference and comparison (scripts/accuracy/run.sh, docs/accuracy.md).
//
//   lpm_study reference IN.vdb --bake FRAMING.vdb [--grid G] [--density-scale S] [--albedo A]
//             [--g G] [--env SKY] [--up-axis y|z] [--sun X,Y,Z --sun-irradiance E] [--voxels K]
//             [--temperature-grid T --temperature-scale K --temperature-offset K]
//             [--samples N] [--size WxH] [--spp S] -o REF.json
//     Monte Carlo reference (core/mc_reference.h) of the scene as lpmbake reads it: band 0..2
//     SH of S at K voxels drawn uniformly among those with density, and a camera image
//     (lpmbake render's default framing of FRAMING.vdb, 40 degrees) of the light the volume
//     scatters or emits (no environment behind it), each with its standard errors.
//   lpm_study sky OUT.exr
//     A lat-long sky (blue gradient, dark ground) with a sun in the map: one pixel at 35
//     degrees elevation holding about 60% of the map's power (for the hot-pixel extraction).
//   lpm_study compare REF.json BAKE.vdb
//     One JSON line: the bake's band-0 and band-1..2 errors at the reference voxels (the
//     exact sun terms added back), and `lpmbake render`'s image (black background, 4x4 rays
//     a pixel) against
//     the reference image, relative L1 per pixel and over 4x4 blocks, with the reference's
//     own noise beside each figure.
#include <OpenImageIO/imageio.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <string>

#include "core/sun_term.h"
#include "tests/core/lpm_vs_mc.h"
#include "vdb_io/bake_render.h"
#include "vdb_io/bake_schema.h"
#include "vdb_io/env_reader.h"
#include "vdb_io/volume_reader.h"

using namespace lpm;
using nlohmann::json;

namespace {

std::string arg(int argc, char** argv, const std::string& key, const std::string& fallback) {
    for (int i = 1; i + 1 < argc; ++i)
        if (key == argv[i]) return argv[i + 1];
    return fallback;
}

Vec3 vec3(const std::string& s) {
    Vec3 v;
    if (std::sscanf(s.c_str(), "%lf,%lf,%lf", &v.x, &v.y, &v.z) != 3) throw Error("study", "bad vector " + s);
    return v;
}

int reference(int argc, char** argv) {
    VolumeReadOptions ro;
    ro.path = argv[2];
    ro.gridName = arg(argc, argv, "--grid", "density");
    ro.densityScale = std::stod(arg(argc, argv, "--density-scale", "1"));
    ro.temperatureGrid = arg(argc, argv, "--temperature-grid", "");
    ro.temperatureScale = std::stod(arg(argc, argv, "--temperature-scale", "1"));
    ro.temperatureOffset = std::stod(arg(argc, argv, "--temperature-offset", "0"));
    VolumeInput vol = readVolume(ro);
    Medium& m = vol.medium;
    m.albedo = RGB(std::stof(arg(argc, argv, "--albedo", "0.9")));
    m.g = std::stod(arg(argc, argv, "--g", "0"));
    EnvInput envIn;
    Lights lights;
    if (!arg(argc, argv, "--env", "").empty()) {
        EnvReadOptions eo;
        eo.path = arg(argc, argv, "--env", "");
        eo.up = arg(argc, argv, "--up-axis", "y") == "z" ? UpAxis::Z : UpAxis::Y;
        envIn = readEnvironment(eo);
        lights.env = envIn.env.get();
    }
    if (!arg(argc, argv, "--sun", "").empty())
        lights.suns.push_back({normalize(vec3(arg(argc, argv, "--sun", ""))),
                               RGB(std::stof(arg(argc, argv, "--sun-irradiance", "1"))), 0.53});
    const int order = m.g == 0.0 ? 0 : 2;
    const std::vector<size_t> voxels = test::sampleVoxels(m, std::stoi(arg(argc, argv, "--voxels", "64")));
    const int samples = std::stoi(arg(argc, argv, "--samples", "4096"));
    const std::vector<McVoxelEstimate> est = mcVoxelSH(m, lights, voxels, samples, order);
    json jv = json::array();
    for (size_t i = 0; i < voxels.size(); ++i) {
        int x, y, z;
        m.coord(voxels[i], x, y, z);
        jv.push_back({{"ijk", {vol.blockMin.x() + x, vol.blockMin.y() + y, vol.blockMin.z() + z}},
                      {"mean", est[i].mean},
                      {"stderr", est[i].stdErr}});
    }
    int w = 64, h = 64;
    std::sscanf(arg(argc, argv, "--size", "64x64").c_str(), "%dx%d", &w, &h);
    const PinholeCamera cam = framingCamera(readBakeFile(arg(argc, argv, "--bake", "")), 40.0, w, h);
    McSettings noBackground;
    noBackground.background = false;
    const McImage img = mcRenderImage(m, lights, cam, std::stoi(arg(argc, argv, "--spp", "256")), noBackground);
    const json out = {{"sh_order", order},
                      {"env", arg(argc, argv, "--env", "")},
                      {"samples", samples},
                      {"voxels", jv},
                      {"camera",
                       {{"eye", {cam.eye.x, cam.eye.y, cam.eye.z}},
                        {"target", {cam.target.x, cam.target.y, cam.target.z}},
                        {"up", {cam.up.x, cam.up.y, cam.up.z}},
                        {"fov", cam.fovYDeg},
                        {"size", {w, h}}}},
                      {"image", {{"mean", img.mean}, {"stderr", img.stdErr}}}};
    std::ofstream(arg(argc, argv, "-o", "ref.json")) << out.dump() << "\n";
    return 0;
}

/// The bake's SH at the reference voxels, [voxel][k][rgb], with the exact sun terms added
/// back (the reference counts every sun's single scattering in S).
LpmResult bakeAtVoxels(const BakeFile& b, const json& ref, int order) {
    LpmResult r;
    r.shOrder = order;
    r.coeffs = shCount(order);
    std::vector<SunTerm> terms;
    for (int k = 0; k < metaInt(*b.meta, bakekey::sunTermCount.name, 0); ++k) {
        SunTerm t;
        const auto toward = b.meta->metaValue<openvdb::Vec3d>(sunTermKey(k, SunTermField::Toward).name);
        const auto e = b.meta->metaValue<openvdb::Vec3d>(sunTermKey(k, SunTermField::Irradiance).name);
        t.toSun = {toward.x(), toward.y(), toward.z()};
        t.irradiance = RGB(float(e.x()), float(e.y()), float(e.z()));
        t.angularDiameterDeg = b.meta->metaValue<double>(sunTermKey(k, SunTermField::AngleDeg).name);
        terms.push_back(t);
    }
    const double g = metaDouble(*b.meta, bakekey::g.name, 0.0);
    for (const json& v : ref["voxels"]) {
        const openvdb::Coord c(v["ijk"][0].get<int>(), v["ijk"][1].get<int>(), v["ijk"][2].get<int>());
        std::vector<float> coeffs(size_t(r.coeffs) * 3, 0.0f);
        for (int k = 0; k < r.coeffs && k < int(b.sh.size()); ++k) {
            const openvdb::Vec3f s = b.sh[size_t(k)]->getConstAccessor().getValue(c);
            for (int ch = 0; ch < 3; ++ch) coeffs[size_t(k) * 3 + ch] = s[ch];
        }
        for (size_t k = 0; k < terms.size(); ++k) {
            const float T = b.sunTransmittance[k]->getConstAccessor().getValue(c);
            addSunTermSh(terms[k], g, order, T, 1.0, coeffs.data());
        }
        r.sh.insert(r.sh.end(), coeffs.begin(), coeffs.end());
    }
    return r;
}

/// Relative L1 of `img` against the reference image, per pixel and over 4x4 blocks, with
/// the L1 the reference's noise alone would give (E|N(0, s)| = s sqrt(2 / pi)).
json imageErrors(const std::vector<float>& img, const json& ref, int w, int h) {
    const std::vector<double> mean = ref["mean"], se = ref["stderr"];
    double l1 = 0, sum = 0, noise = 0, bl1 = 0, bnoise = 0;
    const double k = std::sqrt(2.0 / kPi);
    for (int by = 0; by < h; by += 4)
        for (int bx = 0; bx < w; bx += 4)
            for (int ch = 0; ch < 3; ++ch) {
                double bi = 0, bm = 0, bv = 0;
                for (int y = by; y < std::min(h, by + 4); ++y)
                    for (int x = bx; x < std::min(w, bx + 4); ++x) {
                        const size_t p = (size_t(y) * w + x) * 3 + ch;
                        l1 += std::fabs(img[p] - mean[p]);
                        noise += k * se[p];
                        sum += mean[p];
                        bi += img[p], bm += mean[p], bv += se[p] * se[p];
                    }
                bl1 += std::fabs(bi - bm);
                bnoise += k * std::sqrt(bv);
            }
    return {{"image_l1", l1 / sum},
            {"image_l1_noise", noise / sum},
            {"block_l1", bl1 / sum},
            {"block_l1_noise", bnoise / sum},
            {"image_ratio", [&] {
                 double s = 0;
                 for (const float v : img) s += v;
                 return s / sum;
             }()}};
}

/// `lpmbake render` at 4x4 rays per pixel, box-filtered: the reference jitters its rays over
/// each pixel, so one ray through the centre would differ wherever the picture has detail.
std::vector<float> renderSupersampled(const BakeFile& b, const PinholeCamera& cam) {
    constexpr int kS = 4;
    PinholeCamera fine = cam;
    fine.width *= kS;
    fine.height *= kS;
    const std::vector<float> big = renderBake(b, fine, nullptr, 0.5);
    std::vector<float> out(size_t(cam.width) * cam.height * 3, 0.0f);
    for (int y = 0; y < fine.height; ++y)
        for (int x = 0; x < fine.width; ++x)
            for (int ch = 0; ch < 3; ++ch)
                out[(size_t(y / kS) * cam.width + x / kS) * 3 + ch] +=
                    big[(size_t(y) * fine.width + x) * 3 + ch] / float(kS * kS);
    return out;
}

int writeSky(const std::string& path) {
    const int w = 256, h = 128;
    std::vector<float> px(size_t(w) * h * 3);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            const double lat = kPi / 2 - (y + 0.5) / h * kPi;
            const RGB c = lat > 0 ? RGB(0.3f, 0.45f, 0.8f) * float(0.5 + 0.5 * std::sin(lat)) : RGB(0.1f, 0.09f, 0.07f);
            for (int ch = 0; ch < 3; ++ch) px[(size_t(y) * w + x) * 3 + ch] = c[ch];
        }
    const int sy = int((kPi / 2 - 35.0 * kPi / 180.0) / kPi * h), sx = w / 3;
    const float sun[3] = {12000.f, 11000.f, 9500.f};  // about 5 W/m^2 over the pixel's 4.9e-4 sr
    for (int ch = 0; ch < 3; ++ch) px[(size_t(sy) * w + sx) * 3 + ch] = sun[ch];
    auto out = OIIO::ImageOutput::create(path);
    OIIO::ImageSpec spec(w, h, 3, OIIO::TypeDesc::FLOAT);
    if (!out || !out->open(path, spec) || !out->write_image(OIIO::TypeDesc::FLOAT, px.data()) || !out->close())
        throw Error("study", "cannot write " + path);
    return 0;
}

int compareBake(char** argv) {
    json ref;
    std::ifstream(argv[2]) >> ref;
    const BakeFile b = readBakeFile(argv[3]);
    const int order = ref["sh_order"];
    const LpmResult r = bakeAtVoxels(b, ref, order);
    std::vector<McVoxelEstimate> mc;
    for (size_t i = 0; i < ref["voxels"].size(); ++i) {
        McVoxelEstimate e;
        e.voxel = i;
        e.mean = ref["voxels"][i]["mean"].get<std::vector<double>>();
        e.stdErr = ref["voxels"][i]["stderr"].get<std::vector<double>>();
        mc.push_back(e);
    }
    const test::Comparison c = test::compare(r, mc);
    const json& jc = ref["camera"];
    PinholeCamera cam;
    cam.eye = {jc["eye"][0], jc["eye"][1], jc["eye"][2]};
    cam.target = {jc["target"][0], jc["target"][1], jc["target"][2]};
    cam.up = {jc["up"][0], jc["up"][1], jc["up"][2]};
    cam.fovYDeg = jc["fov"];
    cam.width = jc["size"][0];
    cam.height = jc["size"][1];
    json out = imageErrors(renderSupersampled(b, cam), ref["image"], cam.width, cam.height);
    out["band0_rms"] = c.band0Rms;
    out["band0_noise"] = c.band0Noise;
    out["band0_bias"] = c.band0Bias;
    out["band0_corrected"] = c.band0Corrected();
    if (order > 0) out["band12_rms"] = c.band12Rms, out["band12_noise"] = c.band12Noise;
    std::printf("%s\n", out.dump().c_str());
    return 0;
}

}  // namespace

int main(int argc, char** argv) {
    try {
        initOpenVdb();
        if (argc >= 3 && std::string(argv[1]) == "reference") return reference(argc, argv);
        if (argc == 4 && std::string(argv[1]) == "compare") return compareBake(argv);
        if (argc == 3 && std::string(argv[1]) == "sky") return writeSky(argv[2]);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "lpm_study: %s\n", e.what());
        return 1;
    }
    std::fprintf(stderr, "usage: lpm_study reference IN.vdb --bake FRAMING.vdb [...] -o REF.json\n"
                         "       lpm_study compare REF.json BAKE.vdb\n");
    return 2;
}

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
//   lpm_study compare REF.json BAKE.vdb [SIDE_BY_SIDE.png]
//     One JSON line: the bake's band-0 and band-1..2 errors at the reference voxels (the
//     exact sun terms added back; RMS relative to the reference's band-0 RMS), and `lpmbake render`'s image (black
//     background, 4x4 rays a pixel) against the reference image, relative L1 per pixel and over 4x4 blocks, with the
//     reference's own noise beside each figure; optionally the images: reference | bake | |difference| x 4.
#include <OpenImageIO/imageio.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <string>

#include "core/lpm_solver.h"
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

/// The bake's SH against the reference at its voxels: RMS over voxels and channels of
/// Band 0's error relative to each voxel's own reference value, RMS over the voxels and
/// channels the reference resolves (its value at least twice its standard error and 1e-3
/// of `scale`, the RMS of its band 0): deep, dim voxels weigh as much as lit ones
/// (lpm_bench_volume's measure), with the same measure of the reference's noise.
json voxelRelativeErrors(const LpmResult& r, const json& voxels, double scale) {
    double err = 0, noise = 0, count = 0;
    for (size_t i = 0; i < voxels.size(); ++i) {
        const std::vector<double> mean = voxels[i]["mean"], se = voxels[i]["stderr"];
        for (size_t ch = 0; ch < 3; ++ch) {
            if (!(se[ch] > 0 && mean[ch] > 2.0 * se[ch] && mean[ch] > 1e-3 * scale)) continue;
            const double d = (r.sh[i * size_t(r.coeffs) * 3 + ch] - mean[ch]) / mean[ch];
            err += d * d;
            noise += (se[ch] / mean[ch]) * (se[ch] / mean[ch]);
            count += 1;
        }
    }
    return {{"band0_voxel_rms", count > 0 ? std::sqrt(err / count) : 0.0},
            {"band0_voxel_noise", count > 0 ? std::sqrt(noise / count) : 0.0},
            {"band0_voxel_count", count}};
}

/// (bake - MC), relative to the RMS of the reference's band 0 (so voxels the reference sees
/// as nearly dark cannot blow a ratio up), for band 0 and for bands 1..2, each with the
/// same measure of the reference's standard errors and, for band 0, the error with that
/// noise removed in quadrature and the mean bias.
json voxelErrors(const LpmResult& r, const json& voxels) {
    double d0 = 0, n0 = 0, ref0 = 0, bias = 0, d12 = 0, n12 = 0;
    for (size_t i = 0; i < voxels.size(); ++i) {
        const std::vector<double> mean = voxels[i]["mean"], se = voxels[i]["stderr"];
        for (int k = 0; k < r.coeffs; ++k)
            for (int ch = 0; ch < 3; ++ch) {
                const size_t j = size_t(k) * 3 + ch;
                const double d = r.sh[i * size_t(r.coeffs) * 3 + j] - mean[j];
                (k == 0 ? d0 : d12) += d * d;
                (k == 0 ? n0 : n12) += se[j] * se[j];
                if (k == 0) ref0 += mean[j] * mean[j], bias += d;
            }
    }
    const double count = 3.0 * double(voxels.size()), scale = std::sqrt(ref0 / count);
    json out = {{"band0_rms", std::sqrt(d0 / count) / scale},
                {"band0_noise", std::sqrt(n0 / count) / scale},
                {"band0_corrected", std::sqrt(std::max(0.0, d0 - n0) / count) / scale},
                {"band0_bias", bias / count / scale}};
    out.update(voxelRelativeErrors(r, voxels, scale));
    if (r.coeffs > 1) {
        out["band12_rms"] = std::sqrt(d12 / count) / scale;
        out["band12_noise"] = std::sqrt(n12 / count) / scale;
    }
    return out;
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

/// reference | bake | |difference| x 4, side by side, as an sRGB PNG (exposure: the
/// reference's 99th percentile at 0.9).
void writeSideBySide(const std::string& path, const std::vector<float>& img, const json& ref, int w, int h) {
    const std::vector<double> mean = ref["mean"];
    std::vector<double> sorted(mean.begin(), mean.end());
    std::sort(sorted.begin(), sorted.end());
    const double white = std::max(1e-12, sorted[size_t(0.99 * double(sorted.size() - 1))] / 0.9);
    const auto encode = [&](double v) {
        const double x = std::clamp(v / white, 0.0, 1.0);
        return std::uint8_t(std::lround(255.0 * (x <= 0.0031308 ? 12.92 * x : 1.055 * std::pow(x, 1 / 2.4) - 0.055)));
    };
    std::vector<std::uint8_t> px(size_t(3 * w) * h * 3);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
            for (int ch = 0; ch < 3; ++ch) {
                const size_t p = (size_t(y) * w + x) * 3 + ch, row = size_t(y) * 3 * w;
                px[(row + x) * 3 + ch] = encode(mean[p]);
                px[(row + w + x) * 3 + ch] = encode(img[p]);
                px[(row + 2 * w + x) * 3 + ch] = encode(4.0 * std::fabs(img[p] - mean[p]));
            }
    auto out = OIIO::ImageOutput::create(path);
    OIIO::ImageSpec spec(3 * w, h, 3, OIIO::TypeDesc::UINT8);
    if (!out || !out->open(path, spec) || !out->write_image(OIIO::TypeDesc::UINT8, px.data()) || !out->close())
        throw Error("study", "cannot write " + path);
}

int compareBake(int argc, char** argv) {
    json ref;
    std::ifstream(argv[2]) >> ref;
    const BakeFile b = readBakeFile(argv[3]);
    const int order = ref["sh_order"];
    const LpmResult r = bakeAtVoxels(b, ref, order);
    const json& jc = ref["camera"];
    PinholeCamera cam;
    cam.eye = {jc["eye"][0], jc["eye"][1], jc["eye"][2]};
    cam.target = {jc["target"][0], jc["target"][1], jc["target"][2]};
    cam.up = {jc["up"][0], jc["up"][1], jc["up"][2]};
    cam.fovYDeg = jc["fov"];
    cam.width = jc["size"][0];
    cam.height = jc["size"][1];
    const std::vector<float> img = renderSupersampled(b, cam);
    json out = imageErrors(img, ref["image"], cam.width, cam.height);
    if (argc == 5) writeSideBySide(argv[4], img, ref["image"], cam.width, cam.height);
    out.update(voxelErrors(r, ref["voxels"]));
    std::printf("%s\n", out.dump().c_str());
    return 0;
}

}  // namespace

int main(int argc, char** argv) {
    try {
        initOpenVdb();
        if (argc >= 3 && std::string(argv[1]) == "reference") return reference(argc, argv);
        if ((argc == 4 || argc == 5) && std::string(argv[1]) == "compare") return compareBake(argc, argv);
        if (argc == 3 && std::string(argv[1]) == "sky") return writeSky(argv[2]);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "lpm_study: %s\n", e.what());
        return 1;
    }
    std::fprintf(stderr,
                 "usage: lpm_study reference IN.vdb --bake FRAMING.vdb [...] -o REF.json\n"
                 "       lpm_study compare REF.json BAKE.vdb [SIDE_BY_SIDE.png]\n"
                 "       lpm_study sky OUT.exr\n");
    return 2;
}

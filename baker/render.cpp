// `lpmbake render`: a pinhole ray march of a bake, to check it by eye. Single scattering
// from the baked S only: along a camera ray with direction v it accumulates
//   L += T * albedo * S(x, -v) * (1 - exp(-sigma_t dt))        (in-scattering)
//      + T * (1 - albedo) * L_e * (1 - exp(-sigma_t dt))        (emission, if baked)
// with density and S trilinearly interpolated (S from the SH grids, clamped at zero, plus
// the exact sun terms E T p_HG of format 2, core/sun_term.h), and
// adds T * environment(v) behind the volume. Settings come from the bake's metadata.
// The march samples only where the interpolated density is non-zero, i.e. within one voxel
// of an active density voxel; the lighting grids hold solved S on that whole footprint
// (vdb_io/lighting_topology.h), so no lookup there reads the zero background. A bake
// without that shell (older lpmbake) is rendered as it is, with a warning: its edge is dark.
#include <algorithm>
#include <cmath>
#include <filesystem>

#include <OpenImageIO/imageio.h>
#include <openvdb/tools/Interpolation.h>

#include "baker/options.h"
#include "core/mc_reference.h"
#include "core/parallel.h"
#include "core/sh.h"
#include "core/sun_term.h"
#include "vdb_io/atomic_file.h"
#include "vdb_io/bake_file.h"
#include "vdb_io/color.h"
#include "vdb_io/env_reader.h"
#include "vdb_io/io_error.h"
#include "vdb_io/lighting_topology.h"

namespace lpm {

namespace {

std::string lower(std::string s) {
    std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    return s;
}

/// Ray/box intersection in index space; returns false when the ray misses.
bool clipRay(const openvdb::Vec3d& o, const openvdb::Vec3d& d, const openvdb::BBoxd& box, double& t0, double& t1) {
    t0 = 0;
    t1 = 1e300;
    for (int a = 0; a < 3; ++a) {
        if (std::fabs(d[a]) < 1e-300) {
            if (o[a] < box.min()[a] || o[a] > box.max()[a]) return false;
            continue;
        }
        double ta = (box.min()[a] - o[a]) / d[a], tb = (box.max()[a] - o[a]) / d[a];
        if (ta > tb) std::swap(ta, tb);
        t0 = std::max(t0, ta);
        t1 = std::min(t1, tb);
    }
    return t0 < t1;
}

/// EXR chromaticities for the colour spaces of the shipped config (so other tools know
/// the primaries; OIIO 2.4 does not write oiio:ColorSpace into EXR headers).
bool chromaticities(const std::string& space, float c[8]) {
    static const float ap1[8] = {0.713f, 0.293f, 0.165f, 0.830f, 0.128f, 0.044f, 0.32168f, 0.33767f};
    static const float ap0[8] = {0.7347f, 0.2653f, 0.0f, 1.0f, 0.0001f, -0.077f, 0.32168f, 0.33767f};
    static const float r709[8] = {0.64f, 0.33f, 0.30f, 0.60f, 0.15f, 0.06f, 0.3127f, 0.3290f};
    const float* p = space == "ACEScg" ? ap1 : space == "ACES2065-1" ? ap0 : space == "lin_rec709" ? r709 : nullptr;
    if (!p) return false;
    std::copy(p, p + 8, c);
    return true;
}

}  // namespace

void runRender(const RenderOptions& o, const Log& log) {
    if (o.bake.empty()) throw UsageError("render: no bake given");
    if (o.output.empty()) throw UsageError("render: no output image given (-o IMAGE.exr|.png)");
    if (o.width <= 0 || o.height <= 0 || o.width > 16384 || o.height > 16384)
        throw UsageError("render: --size must be WxH with 1..16384 pixels per side");
    if (!(o.fovYDeg > 0 && o.fovYDeg < 180)) throw UsageError("render: --fov-y must be in (0, 180) degrees");
    if (!(o.stepVoxels > 0)) throw UsageError("render: --step must be positive");
    if (o.threads < 0) throw UsageError("render: --threads must be 0 (all cores) or positive");
    const std::string ext = lower(std::filesystem::path(o.output).extension().string());
    if (ext != ".exr" && ext != ".png")
        throw UsageError("render: output '" + o.output + "' must end in .exr (scene-linear) or .png (sRGB view)");
    ThreadLimit limit(o.threads);
    AtomicOutput out(o.output, {o.bake, o.env});

    BakeFile bake = readBakeFile(o.bake);
    const auto problems = validateBake(bake);
    if (!problems.empty()) throw InputError("render", "'" + o.bake + "' is not an lpmbake bake: " + problems.front());
    if (!bake.density)
        throw InputError("render", "'" + o.bake + "' has no density grid (baked with --no-density?); cannot render");
    if (const std::uint64_t missing = missingShellVoxels(*bake.density, *bake.sh.front()))
        log.warn("render: '" + o.bake + "' has no S at " + std::to_string(missing) +
                 " voxel(s) within one voxel of the density (written by an lpmbake before the lighting shell); "
                 "the volume's edge will render dark: bake it again");
    const openvdb::MetaMap& meta = *bake.meta;
    const double densityScale = metaDouble(meta, "lpm:density_scale", 1.0);
    const RGB albedo = metaRgb(meta, "lpm:albedo", RGB(0.9f));
    const std::string working = metaString(meta, "lpm:working_colorspace", "ACEScg");
    const int nc = shCount(bake.shOrder);
    const UpAxis sceneUp = metaString(meta, "lpm:up_axis", "y") == "z" ? UpAxis::Z : UpAxis::Y;

    // Exact sun terms (format 2, core/sun_term.h): S(x, w) += E_k T_k(x) p_HG(g, dot(-toward_k, w)).
    std::vector<SunTerm> suns(bake.sunTransmittance.size());
    const double sunG = metaDouble(meta, "lpm:sun_term_g", 0.0);
    for (size_t k = 0; k < suns.size(); ++k) {
        const std::string p = "lpm:sun_term_" + std::to_string(k) + "_";
        const auto toward = meta.getMetadata<openvdb::Vec3DMetadata>(p + "toward");
        if (toward) suns[k].toSun = normalize(Vec3{toward->value().x(), toward->value().y(), toward->value().z()});
        suns[k].irradiance = metaRgb(meta, p + "irradiance", RGB(0.f));
    }

    std::unique_ptr<EnvMap> env;
    if (!o.env.empty()) {
        EnvReadOptions eo;
        eo.path = o.env;
        eo.colorSpace = o.envColorSpace;
        eo.workingSpace = working;
        eo.rotateYDeg = metaDouble(meta, "lpm:env_rotate_y_deg", 0.0);
        eo.scale = float(metaDouble(meta, "lpm:env_scale", 1.0));
        eo.up = sceneUp;
        EnvInput e = readEnvironment(eo);
        for (const auto& w : e.warnings) log.warn(w);
        env = std::move(e.env);
    }

    const openvdb::math::Transform& xf = bake.density->transform();
    openvdb::BBoxd box;
    const bool hasVolume = bake.density->activeVoxelCount() > 0;
    PinholeCamera cam;
    cam.eye = o.eye;
    cam.target = o.target;
    if (hasVolume) {
        const openvdb::CoordBBox cb = bake.density->evalActiveVoxelBoundingBox();
        box = openvdb::BBoxd(cb.min().asVec3d() - openvdb::Vec3d(1), cb.max().asVec3d() + openvdb::Vec3d(1));
        // Default camera: look at the world-space box centre from +Z (-Y in a Z-up bake; a little above
        // and to the right), far enough for the bounding sphere to fit the field of view.
        const openvdb::BBoxd wb = xf.indexToWorld(box);
        const openvdb::Vec3d c = wb.getCenter();
        const double radius = 0.5 * (wb.max() - wb.min()).length();
        if (o.autoTarget) cam.target = {c.x(), c.y(), c.z()};
        if (o.autoEye)
            cam.eye = cam.target + normalize(upAxisToWorld(sceneUp, Vec3(0.3, 0.35, 1.0))) * (1.05 * radius / std::sin(0.5 * o.fovYDeg * kPi / 180));
    } else if (o.autoEye || o.autoTarget) {
        throw InputError("render", "'" + o.bake + "' is an empty bake: give --eye and --target");
    }
    if (!(length(cam.target - cam.eye) > 0)) throw UsageError("render: --eye and --target must differ");
    const Vec3 up = o.autoUp ? upAxisToWorld(sceneUp, Vec3(0, 1, 0)) : o.up;
    if (!(length(cross(normalize(cam.target - cam.eye), up)) > 1e-6))
        throw UsageError("render: --up must not be parallel to the view direction");
    cam.up = up;
    cam.fovYDeg = o.fovYDeg;
    cam.width = o.width;
    cam.height = o.height;

    std::vector<float> img(size_t(o.width) * o.height * 3, 0.f);
    using openvdb::tools::BoxSampler;
    parallelForChunks(size_t(o.height), 1, [&](size_t y0, size_t y1) {
        // Accessors are not thread-safe: one set per task.
        auto dacc = bake.density->getConstAccessor();
        std::vector<openvdb::Vec3SGrid::ConstAccessor> shAcc;
        for (int k = 0; k < nc; ++k) shAcc.push_back(bake.sh[k]->getConstAccessor());
        std::vector<openvdb::FloatGrid::ConstAccessor> sunAcc;
        for (const auto& g : bake.sunTransmittance) sunAcc.push_back(g->getConstAccessor());
        std::vector<double> sunPhase(suns.size());
        std::unique_ptr<openvdb::Vec3SGrid::ConstAccessor> eacc;
        if (bake.emission) eacc.reset(new openvdb::Vec3SGrid::ConstAccessor(bake.emission->getConstAccessor()));
        for (size_t py = y0; py < y1; ++py)
            for (int px = 0; px < o.width; ++px) {
                const Vec3 v = cam.rayDirection(px + 0.5, py + 0.5);
                double L[3] = {0, 0, 0}, T = 1;
                double t0, t1;
                const openvdb::Vec3d eo = xf.worldToIndex(openvdb::Vec3d(cam.eye.x, cam.eye.y, cam.eye.z));
                const openvdb::Vec3d di =
                    xf.worldToIndex(openvdb::Vec3d(cam.eye.x + v.x, cam.eye.y + v.y, cam.eye.z + v.z)) - eo;
                if (hasVolume && clipRay(eo, di, box, t0, t1)) {
                    double Y[16];
                    shEval(-v, Y);  // S(x, -v): light travelling toward the eye
                    for (size_t k = 0; k < suns.size(); ++k) sunPhase[k] = sunTermPhase(suns[k], sunG, -v);
                    const double dt = o.stepVoxels / di.length();  // world length of one step
                    for (double t = t0 + 0.5 * dt; t < t1 && T > 1e-4; t += dt) {
                        const openvdb::Vec3d p = eo + di * t;
                        float dens = 0;
                        BoxSampler::sample(dacc, p, dens);
                        if (!(dens > 0)) continue;
                        const double tau = double(dens) * densityScale * dt;
                        const double a = -std::expm1(-tau);  // 1 - exp(-tau), accurate for small tau
                        double S[3] = {0, 0, 0};
                        for (int k = 0; k < nc; ++k) {
                            openvdb::Vec3s c;
                            BoxSampler::sample(shAcc[k], p, c);
                            for (int ch = 0; ch < 3; ++ch) S[ch] += c[ch] * Y[k];
                        }
                        double Ssun[3] = {0, 0, 0};  // exact, non-negative: added after the SH clamp
                        for (size_t k = 0; k < suns.size(); ++k) {
                            float T = 0;
                            BoxSampler::sample(sunAcc[k], p, T);
                            for (int ch = 0; ch < 3; ++ch) Ssun[ch] += suns[k].irradiance[ch] * T * sunPhase[k];
                        }
                        openvdb::Vec3s le(0.f);
                        if (eacc) BoxSampler::sample(*eacc, p, le);
                        for (int ch = 0; ch < 3; ++ch)
                            L[ch] += T * a * (albedo[ch] * (std::max(0.0, S[ch]) + Ssun[ch]) + (1 - albedo[ch]) * le[ch]);
                        T *= std::exp(-tau);
                    }
                }
                if (env) {
                    const RGB b = env->lookupSmooth(v);
                    for (int ch = 0; ch < 3; ++ch) L[ch] += T * b[ch];
                }
                float* d = &img[(py * o.width + px) * 3];
                for (int ch = 0; ch < 3; ++ch) d[ch] = std::isfinite(L[ch]) ? float(L[ch]) : 0.f;
            }
    });

    OIIO::ImageSpec spec(o.width, o.height, 3, ext == ".png" ? OIIO::TypeDesc::UINT8 : OIIO::TypeDesc::HALF);
    spec.attribute("Software", std::string("lpmbake ") + LPM_VERSION_STRING);
    if (ext == ".png") {
        convertToDisplay(img, working);  // config's default display and view (sRGB / Standard)
        for (float& c : img) c = std::clamp(c, 0.f, 1.f);
        spec.attribute("oiio:ColorSpace", "sRGB");
    } else {
        spec.attribute("oiio:ColorSpace", working);
        spec.attribute("lpm:colorspace", working);
        float ch[8];
        if (chromaticities(canonicalColorSpace(working), ch))
            spec.attribute("chromaticities", OIIO::TypeDesc(OIIO::TypeDesc::FLOAT, 8), ch);
        spec.attribute("compression", "zip");
    }
    auto writer = OIIO::ImageOutput::create(out.tempPath());
    if (!writer) throw OutputError("render", "cannot create an image writer for '" + o.output + "': " + OIIO::geterror());
    if (!writer->open(out.tempPath(), spec) || !writer->write_image(OIIO::TypeDesc::FLOAT, img.data()) ||
        !writer->close())
    {
        const std::string why = out.failureReason();
        throw OutputError("render", "cannot write '" + out.finalPath() + "': " + (why.empty() ? writer->geterror() : why));
    }
    out.commit();
    log.note("wrote " + o.output + " (" + std::to_string(o.width) + "x" + std::to_string(o.height) + ", " +
             (ext == ".png" ? std::string("sRGB view") : working) + ")");
}

}  // namespace lpm

// `lpmbake render`: a pinhole ray march of a bake (vdb_io/bake_render.h), to check it by
// eye. Settings come from the bake's metadata; the camera from the options or, by default,
// framing the volume (framingCamera). A bake without the lighting shell (older lpmbake) is
// rendered as it is, with a warning: its edge is dark.
#include <memory>
#include <optional>

#include "baker/options.h"
#include "core/parallel.h"
#include "vdb_io/atomic_file.h"
#include "vdb_io/bake_file.h"
#include "vdb_io/bake_render.h"
#include "vdb_io/bake_schema.h"
#include "vdb_io/env_reader.h"
#include "vdb_io/io_error.h"
#include "vdb_io/lighting_topology.h"
#include "vdb_io/preview_image.h"

namespace lpm {

namespace {

void checkRenderOptions(const RenderOptions& o) {
    if (o.bake.empty()) throw UsageError("render: no bake given");
    if (o.output.empty()) throw UsageError("render: no output image given (-o IMAGE.exr|.png)");
    if (o.width <= 0 || o.height <= 0 || o.width > 16384 || o.height > 16384)
        throw UsageError("render: --size must be WxH with 1..16384 pixels per side");
    if (!(o.fovYDeg > 0 && o.fovYDeg < 180)) throw UsageError("render: --fov-y must be in (0, 180) degrees");
    if (!(o.stepVoxels > 0)) throw UsageError("render: --step must be positive");
    if (o.threads < 0) throw UsageError("render: --threads must be 0 (all cores) or positive");
    if (!isPreviewImagePath(o.output))
        throw UsageError("render: output '" + o.output + "' must end in .exr (scene-linear) or .png (sRGB view)");
}

/// The options' camera, with framingCamera's eye, target and up where they were not given.
PinholeCamera renderCamera(const RenderOptions& o, const BakeFile& bake) {
    PinholeCamera cam;
    if (o.autoEye || o.autoTarget || o.autoUp) {
        if (bake.density->activeVoxelCount() > 0) {
            cam = framingCamera(bake, o.fovYDeg, o.width, o.height);
        } else if (o.autoEye || o.autoTarget) {
            throw InputError("render", "'" + o.bake + "' is an empty bake: give --eye and --target");
        } else {
            cam.up = upAxisToWorld(readShaderParams(*bake.meta).up, Vec3(0, 1, 0));
        }
    }
    if (!o.autoEye) cam.eye = o.eye;
    if (!o.autoTarget) cam.target = o.target;
    if (!o.autoUp) cam.up = o.up;
    if (!(length(cam.target - cam.eye) > 0)) throw UsageError("render: --eye and --target must differ");
    if (!(length(cross(normalize(cam.target - cam.eye), cam.up)) > 1e-6))
        throw UsageError("render: --up must not be parallel to the view direction");
    cam.fovYDeg = o.fovYDeg;
    cam.width = o.width;
    cam.height = o.height;
    return cam;
}

std::unique_ptr<EnvMap> renderEnvironment(const RenderOptions& o, const ShaderParams& shader, ImageDecode* decode,
                                          const Log& log) {
    if (o.env.empty() || !decode) return nullptr;
    EnvReadOptions eo;
    eo.path = o.env;
    eo.colorSpace = o.envColorSpace;
    eo.workingSpace = shader.workingColorspace;
    eo.rotateYDeg = shader.envRotateYDeg;
    eo.scale = float(shader.envScale);
    eo.up = shader.up;
    EnvInput e = readEnvironment(eo, *decode);
    for (const auto& w : e.warnings) log.warn(w);
    return std::move(e.env);
}

}  // namespace

void runRender(const RenderOptions& o, const Log& log) {
    checkRenderOptions(o);
    ThreadLimit limit(o.threads);
    AtomicOutput out(o.output, {o.bake, o.env});
    // The image helpers load OpenImageIO (about 0.45 s each) while this process reads the
    // bake and renders.
    std::optional<ImageDecode> envDecode;
    if (!o.env.empty()) envDecode.emplace(o.env);
    ImageEncode encode(out.tempPath(), out.finalPath());
    BakeFile bake = readBakeFile(o.bake);
    const auto problems = validateBake(bake);
    if (!problems.empty()) throw InputError("render", "'" + o.bake + "' is not an lpmbake bake: " + problems.front());
    if (!bake.density)
        throw InputError("render", "'" + o.bake + "' has no density grid (baked with --no-density?); cannot render");
    if (const std::uint64_t missing = missingShellVoxels(*bake.density, *bake.sh.front()))
        log.warn("render: '" + o.bake + "' has no S at " + std::to_string(missing) +
                 " voxel(s) within one voxel of the density (written by an lpmbake before the lighting shell); "
                 "the volume's edge will render dark: bake it again");
    const ShaderParams shader = readShaderParams(*bake.meta);
    const std::unique_ptr<EnvMap> env = renderEnvironment(o, shader, envDecode ? &*envDecode : nullptr, log);
    const PinholeCamera cam = renderCamera(o, bake);
    writePreviewImage(out, encode, renderBake(bake, cam, env.get(), o.stepVoxels), o.width, o.height,
                      shader.workingColorspace);
    log.note("wrote " + o.output + " (" + std::to_string(o.width) + "x" + std::to_string(o.height) + ", " +
             previewImageEncoding(o.output, shader.workingColorspace) + ")");
}

}  // namespace lpm

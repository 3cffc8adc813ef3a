"""Blender side of scripts/bench/cycles_side_by_side.sh (docs/cycles_comparison.md).

Run with Blender 3.4's own Python (bpy, numpy):

  blender -b --factory-startup --python cycles_side_by_side.py -- camera
      --bake BAKE.vdb --sidecar BAKE.json --index-bbox X0,Y0,Z0,X1,Y1,Z1 --size WxH --fov-y DEG
      [--eye X,Y,Z --target X,Y,Z] [--up X,Y,Z] --out CAMERA.json [--white WHITE.exr]
      `lpmbake render`'s camera (vdb_io/bake_render.cpp framingCamera: the density's
      active index box grown by one voxel, through the grid's index-to-world matrix, seen
      from its centre + normalize(upTurn(0.3, 0.35, 1)) * 1.05 r / sin(fov / 2)), with any
      of eye, target, up given replacing its value; writes it as JSON; with --white also a
      constant lat-long environment of radiance 1 (for `lpmbake render`'s coverage).

  blender -b --factory-startup --python cycles_side_by_side.py -- render
      --vdb IN.vdb [--grid density] --sidecar BAKE.json --env SKY --camera CAMERA.json
      --spp 16,64,256,1024 --ref-spp 4096 [--seed-base 100] [--ref-seed 0]
      [--extra-spp N --extra-seed S] [--step-rate 0.5] [--bounces 256] [--threads N]
      [--t-launch EPOCH_S] --out DIR --timings TIMINGS.json
      Cycles path tracing of the PHYSICAL volume (not the bake): sigma_t = grid *
      lpm:density_scale, sigma_s = lpm:albedo * sigma_t, Henyey-Greenstein g = lpm:g, all
      from the bake's sidecar so that both renderers use the same numbers; the world is the
      environment in lpmbake's orientation (lpm_import.setup_world); the object is moved
      by -0.5 voxel along each index axis (Blender 3.4 puts voxel i at i + 0.5, OpenVDB at
      i); the camera is lpm_import's pinhole (lpmbake render's conventions) with a
      transparent film, a 0.01-pixel filter (one ray through each pixel centre, as lpmbake
      render), no denoising, no clamping, no adaptive sampling. Renders a 1-sample
      warm-up (the per-render overhead: scene sync, VDB load, world importance map), the
      ladder, optionally an extra independent render, then the reference; each timed
      with time.perf_counter around bpy.ops.render.render. Writes DIR/cycles_*.exr (RGBA,
      scene linear = Linear Rec.709, 32-bit) and TIMINGS.json after every render.

  blender -b --factory-startup --python cycles_side_by_side.py -- compare
      --manifest RUNS.json --timings TIMINGS.json --out DIR [--block 4]
      [--min-coverage 0.1] [--white-lpm WHITE_RENDER.exr --black-lpm BLACK_RENDER.exr]
      [--hd 1920x1080] [--md TABLE.md] [--side-by-side PNG] [--diff-scale 0.05]
      Relative L1 of every image against the reference over the pixels the volume covers
      (reference alpha >= min coverage), per pixel and on BxB block means; the reference's
      own noise; a fit err^2 = a (1/spp + 1/N) + beta of the Cycles ladder (N: the
      reference's spp) and t = t0 + c spp of its times; the Cycles time needed to reach
      each lpmbake setting's error; the same extrapolated to HD; Cycles' alpha against
      lpmbake render's coverage 1 - T (from renders with a white and no environment).
      Prints a markdown report (also to --md), writes DIR/report.json and PNG previews.
      RUNS.json: {"lpmbake": [{"setting", "options", "bake_s", "render_s", "render_hd_s",
      "image"}, ...]}.

Errors: one line `cycles_side_by_side: error: ...`, exit 1 (usage) or 2 (input/failure).
"""

import argparse
import json
import math
import os
import sys
import time

T_SCRIPT = time.time()            # Blender start-up ends here (the driver passes the launch time)
T_SCRIPT_PERF = time.perf_counter()

import bpy                         # noqa: E402
import numpy as np                 # noqa: E402
from mathutils import Matrix, Vector   # noqa: E402

PROG = "cycles_side_by_side"
HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.normpath(os.path.join(HERE, "..", "blender")))
import lpm_import                  # noqa: E402  (scripts/blender/lpm_import.py, unchanged)


Fail = lpm_import.LpmError  # an error with its exit code (1 usage, 2 input, ...), as the import script's


def log(msg):
    print(PROG + ": " + msg, flush=True)


vec3 = lpm_import._vec3  # "X,Y,Z" -> [x, y, z] (argparse type), as the import script parses it


def size(text):
    w, h = lpm_import._size(text)
    if not (1 <= w <= 16384 and 1 <= h <= 16384):
        raise argparse.ArgumentTypeError("'%s': 1..16384 pixels per side" % text)
    return w, h


def int_list(text):
    try:
        v = [int(t) for t in text.split(",") if t.strip()]
    except ValueError:
        v = []
    if not v or any(x < 1 for x in v):
        raise argparse.ArgumentTypeError("'%s' is not a list of positive integers" % text)
    return v


class Parser(argparse.ArgumentParser):
    def error(self, message):
        raise Fail(1, message)


glue = lpm_import.glue_values  # "-30,-50,-300" values glued to their option for argparse


# ---------------------------------------------------------------------------------------
# camera
# ---------------------------------------------------------------------------------------

def load_volume(path, grid=None):
    if not os.path.isfile(path):
        raise Fail(2, "'%s' not found" % path)
    vol = bpy.data.volumes.new(os.path.splitext(os.path.basename(path))[0])
    vol.filepath = os.path.abspath(path)
    if not vol.grids.load():
        raise Fail(2, "Blender cannot read '%s': %s" % (path, vol.grids.error_message or "unreadable"))
    have = {g.name: g for g in vol.grids}
    if grid is not None and grid not in have:
        raise Fail(2, "'%s' has no grid '%s' (grids: %s)" % (path, grid, ", ".join(sorted(have))))
    return vol, have


def up_turn(up_axis, v):
    """core/envmap.cpp upAxisToWorld: identity for y, +90 degrees about +X for z."""
    v = Vector(v)
    return Matrix.Rotation(math.pi / 2, 3, "X") @ v if up_axis == "z" else v


def cmd_camera(argv):
    p = Parser(prog=PROG + " camera")
    p.add_argument("cmd")
    p.add_argument("--bake", required=True, help="the bake (for the density's transform and lpm:up_axis via --sidecar)")
    p.add_argument("--sidecar", required=True)
    p.add_argument("--index-bbox", required=True, help="active index box of the density: X0,Y0,Z0,X1,Y1,Z1")
    p.add_argument("--size", type=size, required=True)
    p.add_argument("--fov-y", type=float, default=40.0)
    p.add_argument("--eye", type=vec3)
    p.add_argument("--target", type=vec3)
    p.add_argument("--up", type=vec3)
    p.add_argument("--out", required=True)
    p.add_argument("--white")
    a = p.parse_args(glue(argv, {"--eye", "--target", "--up", "--fov-y", "--index-bbox"}))
    try:
        bb = [int(t) for t in a.index_bbox.split(",")]
        assert len(bb) == 6
    except (ValueError, AssertionError):
        raise Fail(1, "--index-bbox '%s' is not X0,Y0,Z0,X1,Y1,Z1" % a.index_bbox)
    params = lpm_import.BakeParams(lpm_import.read_sidecar(a.sidecar)["metadata"], a.sidecar)
    _, grids = load_volume(a.bake, params.density_grid)
    m = grids[params.density_grid].matrix_object      # OpenVDB index -> world
    lo = [bb[0] - 1, bb[1] - 1, bb[2] - 1]             # marchBox: one voxel around the active box
    hi = [bb[3] + 1, bb[4] + 1, bb[5] + 1]
    corners = [m @ Vector((x, y, z)) for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
    wmin = Vector([min(c[i] for c in corners) for i in range(3)])
    wmax = Vector([max(c[i] for c in corners) for i in range(3)])
    centre = 0.5 * (wmin + wmax)
    radius = 0.5 * (wmax - wmin).length
    fov = a.fov_y
    if not 0 < fov < 180:
        raise Fail(1, "--fov-y must be in (0, 180)")
    target = Vector(a.target) if a.target else centre
    eye = Vector(a.eye) if a.eye else target + up_turn(params.up_axis, (0.3, 0.35, 1.0)).normalized() * (
        1.05 * radius / math.sin(0.5 * math.radians(fov)))
    up = Vector(a.up) if a.up else up_turn(params.up_axis, (0.0, 1.0, 0.0))
    cam = {"eye": list(eye), "target": list(target), "up": list(up), "fov_y": fov,
           "width": a.size[0], "height": a.size[1], "up_axis": params.up_axis,
           "world_box": [list(wmin), list(wmax)]}
    with open(a.out, "w") as f:
        json.dump(cam, f, indent=1)
    log("camera eye %s target %s up %s fov %g, %dx%d" % (
        ",".join("%.6g" % c for c in eye), ",".join("%.6g" % c for c in target),
        ",".join("%.6g" % c for c in up), fov, a.size[0], a.size[1]))
    if a.white:
        img = bpy.data.images.new("white", 16, 8, float_buffer=True, alpha=False)
        img.pixels = [1.0] * (16 * 8 * 4)
        img.filepath_raw = os.path.abspath(a.white)
        img.file_format = "OPEN_EXR"
        img.save()
    return 0


# ---------------------------------------------------------------------------------------
# render
# ---------------------------------------------------------------------------------------

def physical_material(params, grid):
    """sigma_t = grid * density_scale (per object unit), Volume Scatter (colour albedo: sigma_s
    = albedo sigma_t, anisotropy g) + Volume Absorption (colour albedo: sigma_a = (1 -
    albedo) sigma_t), trilinear lookup."""
    mat = bpy.data.materials.new("physical_volume")
    mat.use_nodes = True
    tree = mat.node_tree
    tree.nodes.clear()
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    attr = tree.nodes.new("ShaderNodeAttribute")
    attr.attribute_type = "GEOMETRY"
    attr.attribute_name = grid
    mul = tree.nodes.new("ShaderNodeMath")
    mul.operation = "MULTIPLY"
    tree.links.new(attr.outputs["Fac"], mul.inputs[0])
    mul.inputs[1].default_value = params.density_scale
    albedo = tuple(params.albedo) + (1.0,)
    scat = tree.nodes.new("ShaderNodeVolumeScatter")
    scat.inputs["Color"].default_value = albedo
    scat.inputs["Anisotropy"].default_value = params.g
    tree.links.new(mul.outputs[0], scat.inputs["Density"])
    absorb = tree.nodes.new("ShaderNodeVolumeAbsorption")
    absorb.inputs["Color"].default_value = albedo
    tree.links.new(mul.outputs[0], absorb.inputs["Density"])
    add = tree.nodes.new("ShaderNodeAddShader")
    tree.links.new(scat.outputs[0], add.inputs[0])
    tree.links.new(absorb.outputs[0], add.inputs[1])
    tree.links.new(add.outputs[0], out.inputs["Volume"])
    mat.cycles.volume_interpolation = "LINEAR"
    mat.cycles.homogeneous_volume = False
    return mat


def build_scene(a, cam):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    params = lpm_import.BakeParams(lpm_import.read_sidecar(a.sidecar)["metadata"], a.sidecar)
    if lpm_import.working_to_rec709(params.working_colorspace) is not None:
        raise Fail(1, "the bake's working space is %s: bake with --working-space lin_rec709 so that "
                      "both renderers work in Linear Rec.709" % params.working_colorspace)
    grid = a.grid or params.density_grid
    vol, grids = load_volume(a.vdb, grid)
    if grids[grid].data_type != "FLOAT":
        raise Fail(2, "grid '%s' of '%s' is %s, not float" % (grid, a.vdb, grids[grid].data_type))
    vol.render.precision = "FULL"
    vol.render.clipping = 0.0
    vol.render.space = "OBJECT"
    vol.render.step_size = 0.0          # automatic: the voxel size (times the scene's step rate)
    vol.materials.append(physical_material(params, grid))
    obj = bpy.data.objects.new("physical_volume", vol)
    scene.collection.objects.link(obj)
    # The half-voxel shift, as lpm_import.import_bake: Blender 3.4 places voxel i at index
    # i + 0.5, OpenVDB (and lpmbake) at i.
    m3 = grids[grid].matrix_object.to_3x3()
    obj.matrix_world = Matrix.Translation(-0.5 * (m3.col[0] + m3.col[1] + m3.col[2]))
    lpm_import.setup_world(scene, params, a.env, env_colorspace=params.env_colorspace)
    lpm_import.setup_render(scene, cam["eye"], cam["target"], cam["up"], cam["fov_y"], cam["width"],
                            cam["height"], samples=1, seed=0, pixel_filter=0.01,
                            step_rate=a.step_rate, transparent=True)
    # setup_render is for emission-only bakes: turn on the light transport of a physical medium.
    c = scene.cycles
    c.max_bounces = a.bounces
    c.volume_bounces = a.bounces
    c.diffuse_bounces = c.glossy_bounces = c.transmission_bounces = 0    # no surfaces in the scene
    c.transparent_max_bounces = 1024    # the volume's bounding mesh is crossed as transparent surfaces
    c.volume_max_steps = 8192
    c.sample_clamp_direct = c.sample_clamp_indirect = 0.0
    c.use_denoising = False
    c.use_adaptive_sampling = False
    scene.world.cycles.sampling_method = "AUTOMATIC"      # importance-sample the environment (MIS)
    if a.threads:
        scene.render.threads_mode = "FIXED"
        scene.render.threads = a.threads
    s = scene.render.image_settings
    s.file_format = "OPEN_EXR"
    s.color_depth = "32"
    s.exr_codec = "ZIP"
    s.color_mode = "RGBA"
    return scene, params


def render_one(scene, spp, seed, path):
    scene.cycles.samples = spp
    scene.cycles.seed = seed
    t0 = time.perf_counter()
    bpy.ops.render.render(write_still=False, scene=scene.name)
    dt = time.perf_counter() - t0
    tmp = os.path.join(os.path.dirname(path), ".%s.tmp-%d.exr" % (os.path.basename(path), os.getpid()))
    bpy.data.images["Render Result"].save_render(tmp, scene=scene)
    if not os.path.isfile(tmp):
        raise Fail(2, "Blender wrote no image to '%s'" % tmp)
    os.replace(tmp, path)
    return dt


def cmd_render(argv):
    p = Parser(prog=PROG + " render")
    p.add_argument("cmd")
    p.add_argument("--vdb", required=True)
    p.add_argument("--grid")
    p.add_argument("--sidecar", required=True)
    p.add_argument("--env", required=True)
    p.add_argument("--camera", required=True)
    p.add_argument("--spp", type=int_list, required=True)
    p.add_argument("--ref-spp", type=int, required=True)
    p.add_argument("--seed-base", type=int, default=100)
    p.add_argument("--ref-seed", type=int, default=0)
    p.add_argument("--extra-spp", type=int, default=0, help="an extra independent render (noise check)")
    p.add_argument("--extra-seed", type=int, default=1)
    p.add_argument("--step-rate", type=float, default=0.5)
    p.add_argument("--bounces", type=int, default=256)
    p.add_argument("--threads", type=int, default=0)
    p.add_argument("--t-launch", type=float)
    p.add_argument("--out", required=True)
    p.add_argument("--timings", required=True)
    a = p.parse_args(argv)
    if a.ref_spp < 1 or not a.step_rate > 0 or a.bounces < 1:
        raise Fail(1, "--ref-spp, --step-rate and --bounces must be positive")
    with open(a.camera) as f:
        cam = json.load(f)
    os.makedirs(a.out, exist_ok=True)
    t_build = time.perf_counter()
    scene, params = build_scene(a, cam)
    t_built = time.perf_counter()
    timings = {
        "blender_version": bpy.app.version_string,
        "startup_s": (T_SCRIPT - a.t_launch) if a.t_launch else None,
        "script_import_s": t_build - T_SCRIPT_PERF,
        "scene_build_s": t_built - t_build,
        "threads": scene.render.threads,
        "step_rate": a.step_rate, "bounces": a.bounces,
        "density_scale": params.density_scale, "albedo": params.albedo, "g": params.g,
        "width": cam["width"], "height": cam["height"],
        "renders": [],
    }

    def save():
        tmp = a.timings + ".tmp"
        with open(tmp, "w") as f:
            json.dump(timings, f, indent=1)
        os.replace(tmp, a.timings)

    jobs = [("warmup", 1, a.seed_base - 1)]
    jobs += [("ladder", n, a.seed_base + i) for i, n in enumerate(a.spp)]
    if a.extra_spp > 0:
        jobs.append(("extra", a.extra_spp, a.extra_seed))
    jobs.append(("reference", a.ref_spp, a.ref_seed))
    for kind, spp, seed in jobs:
        name = {"warmup": "cycles_warmup_spp%d.exr",
                "ladder": "cycles_spp%d.exr",
                "extra": "cycles_extra_spp%d.exr",
                "reference": "cycles_ref_spp%d.exr"}[kind] % spp
        path = os.path.join(a.out, name)
        log("rendering %s: %d spp, seed %d ..." % (kind, spp, seed))
        dt = render_one(scene, spp, seed, path)
        timings["renders"].append({"kind": kind, "spp": spp, "seed": seed, "seconds": dt, "image": path,
                                   "loadavg_after": os.getloadavg()[0]})
        save()
        log("%s %d spp: %.2f s -> %s" % (kind, spp, dt, path))
    return 0


# ---------------------------------------------------------------------------------------
# compare
# ---------------------------------------------------------------------------------------

def read_exr(path):
    """(H, W, 4) float array, top row first, the file's numbers (no colour conversion)."""
    if not os.path.isfile(path):
        raise Fail(2, "'%s' not found" % path)
    img = bpy.data.images.load(os.path.abspath(path))
    img.colorspace_settings.name = "Non-Color"
    w, h = img.size
    if w == 0 or h == 0:
        raise Fail(2, "cannot read '%s'" % path)
    buf = np.empty(w * h * 4, dtype=np.float32)
    img.pixels.foreach_get(buf)
    bpy.data.images.remove(img)
    return buf.reshape(h, w, 4)[::-1].astype(np.float64)


def write_png(path, rgb):
    """rgb: (H, W, 3) display values in [0, 1] (already encoded), top row first."""
    h, w, _ = rgb.shape
    img = bpy.data.images.new(os.path.basename(path), w, h, alpha=False, float_buffer=False)
    img.colorspace_settings.name = "Non-Color"    # the numbers are written as they are
    rgba = np.ones((h, w, 4), dtype=np.float32)
    rgba[..., :3] = np.clip(rgb, 0.0, 1.0)
    img.pixels.foreach_set(rgba[::-1].ravel())
    img.filepath_raw = os.path.abspath(path)
    img.file_format = "PNG"
    img.save()
    bpy.data.images.remove(img)


def srgb(x):
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def block_mean(a, b):
    h, w = a.shape[0] // b * b, a.shape[1] // b * b
    a = a[:h, :w]
    return a.reshape(h // b, b, w // b, b, *a.shape[2:]).mean(axis=(1, 3))


def rel_l1(img, ref, mask):
    num = np.abs(img[mask] - ref[mask]).sum()
    den = np.abs(ref[mask]).sum()
    return num / den if den > 0 else float("inf")


def fit_error(spps, errs, ref_spp):
    """Weighted least squares (relative residuals) of err^2 = a (1/spp + 1/N) + beta, N the
    reference's spp, beta >= 0: independent noise of the image (a/spp) and of the reference
    (a/N) plus anything that does not fall with the samples (beta, ideally 0). Returns a, beta."""
    x = 1.0 / np.asarray(spps, dtype=np.float64) + 1.0 / ref_spp
    y = np.asarray(errs, dtype=np.float64) ** 2
    w = 1.0 / y
    A = np.stack([x * w, w], axis=1)
    (a, beta), *_ = np.linalg.lstsq(A, y * w, rcond=None)
    if beta < 0:                    # refit with beta = 0
        a, beta = float((x * w * y * w).sum() / ((x * w) ** 2).sum()), 0.0
    return float(a), float(beta)


def timing_model(path):
    """Cycles' time model t = t0 + c spp from the renders of a `render` run's TIMINGS.json (its
    warm-up as t0, its ladder for c), and a line saying what was rendered."""
    with open(path) as f:
        t = json.load(f)
    runs = [r for r in t["renders"] if r["kind"] == "ladder"]
    warm = [r["seconds"] for r in t["renders"] if r["kind"] == "warmup"]
    if len(runs) < 2:
        raise Fail(2, "%s: a time model needs at least two ladder renders" % path)
    t0, c = fit_time([r["spp"] for r in runs], [r["seconds"] for r in runs], warm[0] if warm else None)
    what = "%dx%d, %s spp: %s s" % (t["width"], t["height"], ", ".join(str(r["spp"]) for r in runs),
                                   ", ".join("%.2f" % r["seconds"] for r in runs))
    return t0, c, what


def fit_time(spps, secs, t0=None):
    """t = t0 + c spp: t0 the per-render overhead (the 1-sample warm-up's time when given,
    else the least-squares intercept, at least 0), c >= 0 by least squares through t0."""
    x = np.asarray(spps, dtype=np.float64)
    y = np.asarray(secs, dtype=np.float64)
    if t0 is None:
        A = np.stack([np.ones_like(x), x], axis=1)
        (t0, c), *_ = np.linalg.lstsq(A, y, rcond=None)
        t0 = max(0.0, float(t0))
    c = float((x * (y - t0)).sum() / (x * x).sum())
    return float(t0), max(c, 0.0)


def fmt_s(s):
    if s is None or not math.isfinite(s):
        return "n/a"
    if s >= 3600:
        return "%.1f h" % (s / 3600)
    if s >= 100:
        return "%.0f" % s
    if s >= 10:
        return "%.1f" % s
    return "%.2f" % s


def fmt_ratio(x):
    return "%.0f" % x if x >= 100 else "%.1f" % x if x >= 1 else "%.2g" % x


def cmd_compare(argv):
    p = Parser(prog=PROG + " compare")
    p.add_argument("cmd")
    p.add_argument("--manifest", required=True)
    p.add_argument("--timings", required=True)
    p.add_argument("--out", required=True)
    p.add_argument("--block", type=int, default=4)
    p.add_argument("--min-coverage", type=float, default=0.1)
    p.add_argument("--white-lpm")
    p.add_argument("--black-lpm")
    p.add_argument("--hd", type=size, default=(1920, 1080))
    p.add_argument("--time-runs", help="timing renders at the comparison's size (TIMINGS.json of a `render` run): "
                   "Cycles' time model from them instead of the ladder's own times")
    p.add_argument("--hd-time-runs", help="timing renders at the HD size: Cycles' HD time model from them "
                   "instead of the sample time scaled by the pixel count")
    p.add_argument("--md")
    p.add_argument("--side-by-side")
    p.add_argument("--diff-scale", type=float, default=0.05,
                   help="difference images: full red/blue at this share of the reference's 99.5th percentile")
    a = p.parse_args(argv)
    with open(a.manifest) as f:
        man = json.load(f)
    with open(a.timings) as f:
        tim = json.load(f)
    ref_run = [r for r in tim["renders"] if r["kind"] == "reference"]
    if not ref_run:
        raise Fail(2, "%s holds no reference render" % a.timings)
    ref_run = ref_run[0]
    ref4 = read_exr(ref_run["image"])
    ref, alpha = ref4[..., :3], ref4[..., 3]
    H, W = alpha.shape
    mask = alpha >= a.min_coverage
    B = a.block
    refb = block_mean(ref, B)
    maskb = block_mean(alpha, B) >= a.min_coverage
    if mask.sum() == 0 or maskb.sum() == 0:
        raise Fail(2, "the reference's alpha is below %g everywhere: the volume is not in view" % a.min_coverage)
    pixels = W * H
    lines = []

    def out(s=""):
        lines.append(s)

    rows = []   # dicts: renderer, setting, spp, seconds, err_px, err_blk, image, brightness
    for r in tim["renders"]:
        if r["kind"] in ("ladder", "extra", "reference", "warmup"):
            img = read_exr(r["image"])[..., :3]
            rows.append({"renderer": "Cycles", "kind": r["kind"], "setting": {
                "ladder": "path tracing", "extra": "path tracing (extra seed %d)" % r["seed"],
                "reference": "path tracing (reference)", "warmup": "path tracing (warm-up)"}[r["kind"]],
                "spp": r["spp"], "seconds": r["seconds"], "img": img, "seed": r["seed"]})
    for m in man["lpmbake"]:
        img = read_exr(m["image"])[..., :3]
        rows.append({"renderer": "lpmbake", "kind": "lpmbake", "setting": m["setting"], "spp": None,
                     "seconds": m["bake_s"] + m["render_s"], "bake_s": m["bake_s"], "render_s": m["render_s"],
                     "render_hd_s": m.get("render_hd_s"), "options": m.get("options", ""), "img": img})
    for r in rows:
        if r["img"].shape != ref.shape:
            raise Fail(2, "image of %s %s is %dx%d, the reference %dx%d" % (
                r["renderer"], r["setting"], r["img"].shape[1], r["img"].shape[0], W, H))
        if r["kind"] == "reference":
            r["err_px"] = r["err_blk"] = 0.0
        else:
            r["err_px"] = rel_l1(r["img"], ref, mask)
            r["err_blk"] = rel_l1(block_mean(r["img"], B), refb, maskb)
        r["brightness"] = r["img"][mask].sum() / ref[mask].sum()

    ladder = sorted([r for r in rows if r["kind"] == "ladder"], key=lambda r: r["spp"])
    lpms = [r for r in rows if r["kind"] == "lpmbake"]
    warm = [r for r in rows if r["kind"] == "warmup"]
    extra = [r for r in rows if r["kind"] == "extra"]
    ref_spp = ref_run["spp"]

    out("## Cycles %s vs lpmbake: %dx%d, reference %d spp" % (tim.get("blender_version", "?"), W, H, ref_spp))
    out()
    out("Relative L1 against the Cycles reference over the %d pixels (%d blocks of %dx%d) whose "
        "reference alpha is at least %g; 'blocks' compares %dx%d block means. Seconds: Cycles = "
        "bpy.ops.render.render wall time (scene sync included); lpmbake = bake + render, each its "
        "process's wall time. Brightness = sum(image) / sum(reference) over those pixels." % (
            mask.sum(), maskb.sum(), B, B, a.min_coverage, B, B))
    out()
    out("| renderer | setting | spp | seconds | rel. L1 (pixel) | rel. L1 (%dx%d blocks) | brightness |" % (B, B))
    out("|---|---|---:|---:|---:|---:|---:|")
    order = lpms + warm + ladder + extra + [r for r in rows if r["kind"] == "reference"]
    for r in order:
        if r["kind"] == "lpmbake":
            secs = "%s (bake %s + render %s)" % (fmt_s(r["seconds"]), fmt_s(r["bake_s"]), fmt_s(r["render_s"]))
            setting = r["setting"] + (" (`%s`)" % r["options"] if r["options"] else "")
        else:
            secs = fmt_s(r["seconds"])
            setting = r["setting"]
        err = ("%.4f" % r["err_px"], "%.4f" % r["err_blk"]) if r["kind"] != "reference" else ("0 (ref)", "0 (ref)")
        out("| %s | %s | %s | %s | %s | %s | %.4f |" % (r["renderer"], setting, r["spp"] if r["spp"] else "-",
                                                       secs, err[0], err[1], r["brightness"]))
    out()
    st = tim.get("startup_s")
    loads = [r["loadavg_after"] for r in tim["renders"] if "loadavg_after" in r]
    out("Blender start-up (launch to script start) %s s, scene build %s s (not in the seconds above); "
        "Cycles threads %s, volume step rate %g, max bounces %d; 1-minute load average after each Cycles "
        "render %s (above the thread count: another process shared the cores)." % (
            fmt_s(st) if st is not None else "n/a", fmt_s(tim["scene_build_s"]), tim.get("threads"),
            tim["step_rate"], tim["bounces"], ", ".join("%.1f" % x for x in loads) if loads else "n/a"))
    out()

    report = {"pixels": int(mask.sum()), "blocks": int(maskb.sum()), "rows": [
        {k: v for k, v in r.items() if k != "img"} for r in rows]}

    # The reference's own noise. Independent renders A (n spp) and R (N spp) of an unbiased
    # renderer differ by noise of variance s^2 (1/n + 1/N) per pixel; the expected L1 of
    # Gaussian noise is proportional to its standard deviation, so the reference's own
    # error is relL1(A, R) * sqrt((1/N) / (1/n + 1/N)).
    out("### The reference's own noise")
    out()
    noise_est = []
    for r in ladder[-1:] + extra:
        n = r["spp"]
        k = math.sqrt((1.0 / ref_spp) / (1.0 / n + 1.0 / ref_spp))
        noise_est.append((r, r["err_px"] * k, r["err_blk"] * k))
        out("- from the independent %d-spp render (seed %d): relative L1 %.4f (pixel), %.4f (blocks) "
            "x sqrt((1/%d) / (1/%d + 1/%d)) = %.4f (pixel), %.4f (blocks)" % (
                n, r["seed"], r["err_px"], r["err_blk"], ref_spp, n, ref_spp, noise_est[-1][1], noise_est[-1][2]))
    fits = {}
    if len(ladder) >= 2:
        spps = [r["spp"] for r in ladder]
        for key, label in (("err_px", "pixel"), ("err_blk", "blocks")):
            fits[key] = fit_error(spps, [r[key] for r in ladder], ref_spp)
            ca, cb = fits[key]
            out("- from the fit err^2 = a (1/spp + 1/%d) + beta of the ladder (%s; relative residuals): "
                "a = %.4g, beta = %.3g: the reference's noise sqrt(a/%d) = %.4f; Cycles' own error "
                "sqrt(a/spp); sqrt(beta) = %.4f is what does not fall with the samples (0 for "
                "independent unbiased renders)" % (ref_spp, label, ca, cb, ref_spp, math.sqrt(ca / ref_spp),
                                                    math.sqrt(cb)))
    out()
    report["noise"] = [{"from_spp": r["spp"], "pixel": e1, "blocks": e2} for r, e1, e2 in noise_est]
    report["fits"] = {k: {"a": v[0], "beta": v[1], "ref_noise": math.sqrt(v[0] / ref_spp)}
                      for k, v in fits.items()}

    # Time to reach lpmbake's error.
    if len(ladder) >= 2 and lpms:
        t0, c = fit_time([r["spp"] for r in ladder], [r["seconds"] for r in ladder],
                         warm[0]["seconds"] if warm else None)
        out("Cycles time model: t = t0 + c x spp = %.2f s + %.4g s x spp (t0: %s; c: least squares over the "
            "ladder; the reference's %d spp took %s s, the model says %s s)." % (
                t0, c, "the 1-sample warm-up" if warm else "the ladder's intercept", ref_spp,
                fmt_s(ref_run["seconds"]), fmt_s(t0 + c * ref_spp)))
        if a.time_runs:
            t0, c, runs = timing_model(a.time_runs)
            out("Timed again in this run (%s; the ladder's images keep their errors, these renders only give "
                "the times): t = %.2f s + %.4g s x spp; this model is the one used below." % (runs, t0, c))
        hd_model = timing_model(a.hd_time_runs) if a.hd_time_runs else None
        if hd_model:
            out("Cycles rendered at %dx%d in this run (%s): t = %.2f s + %.4g s x spp, %.1fx the sample time "
                "at %dx%d; the HD columns below use this model, with Cycles' error at a given spp taken "
                "from the %dx%d ladder." % (a.hd[0], a.hd[1], hd_model[2], hd_model[0], hd_model[1],
                                            hd_model[1] / c, W, H, W, H))
        out()
        hd_ratio = (a.hd[0] * a.hd[1]) / float(pixels)
        hd_cov = (a.hd[1] / float(H)) ** 2
        out("### Cycles time to match lpmbake's error")
        out()
        if hd_model:
            hd_how = ("Cycles' HD time from the HD renders' model above (in brackets, for comparison: the "
                      "sample time at %dx%d scaled by (%d/%d)^2 = %.2f)" % (W, H, a.hd[1], H, hd_cov))
        else:
            hd_how = ("Cycles' sample time scaled by the pixel count (x%.2f; an upper bound: the extra pixels "
                      "of a wider frame are mostly background; scaling by (%d/%d)^2 = %.2f gives the value in "
                      "brackets), its per-render overhead t0 kept; the HD Cycles times are EXTRAPOLATED, not "
                      "rendered" % (hd_ratio, a.hd[1], H, hd_cov))
        out("Both errors against the truth: lpmbake's measured error minus the reference's noise in "
            "quadrature, e^2 = err^2 - a/%d, and Cycles' sqrt(a/spp), so spp = a / e^2 (a from the fit "
            "above). Where lpmbake's error is not clearly above the reference's noise (err^2 < 2 a/%d) "
            "it is not resolved by this reference: the table gives the lower bound spp >= a / err^2 "
            "(all of the measured error counted as lpmbake's) and marks it >=. HD: %dx%d, same vertical "
            "field of view; %s; lpmbake's bake as measured, its render %s." % (
                ref_spp, ref_spp, a.hd[0], a.hd[1], hd_how,
                "measured at HD" if any(r.get("render_hd_s") for r in lpms) else
                "scaled by the pixel count (extrapolated)"))
        out()
        out("| lpmbake setting | metric | lpmbake error: measured / less the reference's noise | Cycles spp "
            "needed | Cycles s | lpmbake s | ratio | HD Cycles s | HD lpmbake s | HD ratio |")
        out("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|")
        report["match"] = []
        for r in lpms:
            for key, label in (("err_px", "pixel"), ("err_blk", "blocks")):
                ca, _ = fits[key]
                noise2 = ca / ref_spp
                resolved = r[key] ** 2 >= 2 * noise2
                e2 = r[key] ** 2 - noise2 if resolved else r[key] ** 2
                spp = ca / e2
                ge = "" if resolved else ">= "
                tc = t0 + c * spp
                tl = r["seconds"]
                hd_render = r.get("render_hd_s") or r["render_s"] * hd_ratio
                tl_hd = r["bake_s"] + hd_render
                tc_hd = hd_model[0] + hd_model[1] * spp if hd_model else t0 + c * spp * hd_ratio
                tc_hd_lo = t0 + c * spp * hd_cov
                err_s = "%.4f / %s" % (r[key], ("%.4f" % math.sqrt(e2)) if resolved else "unresolved")
                out("| %s | %s | %s | %s%.0f | %s%s | %s | %s%s | %s%s [%s] | %s | %s%s |" % (
                    r["setting"], label, err_s, ge, spp, ge, fmt_s(tc), fmt_s(tl), ge, fmt_ratio(tc / tl),
                    ge, fmt_s(tc_hd), fmt_s(tc_hd_lo), fmt_s(tl_hd), ge, fmt_ratio(tc_hd / tl_hd)))
                report["match"].append({"setting": r["setting"], "metric": label, "err": r[key],
                                        "err_less_ref_noise": math.sqrt(e2) if resolved else None,
                                        "resolved": resolved, "spp": spp, "cycles_s": tc, "lpmbake_s": tl,
                                        "cycles_hd_s": tc_hd, "cycles_hd_s_coverage_scaled": tc_hd_lo,
                                        "lpmbake_hd_s": tl_hd})
        out()

    # Coverage: lpmbake render's 1 - T (with a white environment) against Cycles' alpha.
    if a.white_lpm and a.black_lpm:
        wl = read_exr(a.white_lpm)[..., :3]
        bl = read_exr(a.black_lpm)[..., :3]
        cov = 1.0 - (wl - bl).mean(axis=2)
        d = np.abs(cov - alpha)
        out("Geometry check: |Cycles reference alpha - lpmbake render coverage (1 - T)|: mean %.4f over "
            "the image, %.4f over the volume's pixels, max %.4f (a missing half-voxel shift or a wrong "
            "camera shows here, independent of the lighting)." % (d.mean(), d[mask].mean(), d.max()))
        out()
        report["coverage_diff"] = {"mean": float(d.mean()), "mean_volume": float(d[mask].mean()),
                                   "max": float(d.max())}

    # Previews: one exposure for all (the reference's 99.5th percentile of the volume's
    # pixels maps to 0.9), sRGB; differences (image - reference) in luminance, red = brighter,
    # blue = darker, full scale = --diff-scale of that percentile (per pixel in *_diff.png,
    # on block means in the side by side).
    lum = lambda x: x @ np.array([0.2126, 0.7152, 0.0722])   # noqa: E731
    peak = float(np.percentile(lum(ref)[mask], 99.5)) or 1.0
    expo = 0.9 / peak

    def disp(x):
        return srgb(x * expo)

    def diff(x, block=1):
        d = (lum(x) - lum(ref)) / (a.diff_scale * peak)
        if block > 1:
            d = np.kron(block_mean(d, block), np.ones((block, block)))
            d = np.pad(d, ((0, H - d.shape[0]), (0, W - d.shape[1])))
        rgb = np.zeros(d.shape + (3,))
        rgb[..., 0] = np.clip(d, 0, 1)
        rgb[..., 2] = np.clip(-d, 0, 1)
        rgb[..., 1] = 0.0
        return srgb(rgb)

    def slug(s):
        return "".join(ch if ch.isalnum() else "_" for ch in s).strip("_")

    write_png(os.path.join(a.out, "reference.png"), disp(ref))
    for r in rows:
        if r["kind"] == "lpmbake":
            base = "lpmbake_" + slug(r["setting"])
        elif r["kind"] in ("ladder", "extra"):
            base = "cycles_%s_spp%d" % (r["kind"], r["spp"])
        else:
            continue
        write_png(os.path.join(a.out, base + ".png"), disp(r["img"]))
        write_png(os.path.join(a.out, base + "_diff.png"), diff(r["img"]))
    if a.side_by_side and lpms:
        # reference | lpmbake (first of the "default" settings, else the first) | Cycles at the
        # ladder rung closest to lpmbake's error | lpmbake - reference
        lp = next((r for r in lpms if r["setting"] == "default"), lpms[0])
        cy = min(ladder, key=lambda r: abs(math.log(max(r["err_px"], 1e-9) / max(lp["err_px"], 1e-9)))) \
            if ladder else None
        panels = [disp(ref), disp(lp["img"])] + ([disp(cy["img"])] if cy else []) + [diff(lp["img"], B)] + \
            ([diff(cy["img"], B)] if cy else [])
        gap = np.ones((H, 2, 3))
        strip = [panels[0]]
        for pnl in panels[1:]:
            strip += [gap, pnl]
        write_png(a.side_by_side, np.concatenate(strip, axis=1))
        out("Side by side (%s): Cycles reference %d spp | lpmbake %s | Cycles %s spp (the rung closest in "
            "per-pixel error) | lpmbake - reference | Cycles - reference; differences of luminance on %dx%d "
            "block means, red brighter, blue darker, full scale %g%% of the reference's 99.5th percentile; "
            "one exposure for all (that percentile at 0.9), sRGB." % (
                os.path.basename(a.side_by_side), ref_spp, lp["setting"], cy["spp"] if cy else "-", B, B,
                100 * a.diff_scale))
        out()
    text = "\n".join(lines)
    print(text, flush=True)
    if a.md:
        with open(a.md, "w") as f:
            f.write(text + "\n")
    with open(os.path.join(a.out, "report.json"), "w") as f:
        json.dump(report, f, indent=1, default=float)
    return 0


def main(argv):
    if not argv:
        raise Fail(1, "usage: camera|render|compare ... (see the header of %s)" % os.path.basename(__file__))
    cmds = {"camera": cmd_camera, "render": cmd_render, "compare": cmd_compare}
    if argv[0] not in cmds:
        raise Fail(1, "unknown command '%s' (camera, render, compare)" % argv[0])
    return cmds[argv[0]](argv)


if __name__ == "__main__":
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    try:
        rc = main(argv)
    except Fail as e:  # also lpm_import's own errors, with their exit codes
        sys.stderr.write("%s: error: %s\n" % (PROG, str(e).replace("\n", " ")))
        rc = e.code
    except Exception as e:          # noqa: BLE001  one line, exit 2
        import traceback
        traceback.print_exc()
        sys.stderr.write("%s: error: internal: %s: %s\n" % (PROG, type(e).__name__, str(e).replace("\n", " ")))
        rc = 2
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(rc)

"""Import an lpmbake bake into Blender (tested with Blender 3.4.1, Cycles).

Command line (an empty scene is built; nothing is saved unless --save-blend is given):

    blender -b --factory-startup --python scripts/blender/lpm_import.py -- BAKE.vdb
        [--sidecar BAKE.json] [--env SKY.exr]
        [--render OUT.exr|OUT.png --camera-eye X,Y,Z --camera-target X,Y,Z
         [--camera-up X,Y,Z] [--fov-y DEG] [--size WxH] [--samples N] [--seed N]
         [--pixel-filter WIDTH] [--step-rate R] [--transparent]]
        [--material auto|constant-free] [--no-half-voxel-shift] [--save-blend FILE.blend]

From Blender's Python console or another script:

    import sys; sys.path.append("/path/to/lpmbake/scripts/blender")
    import lpm_import
    obj = lpm_import.import_bake("/path/bake.vdb", env="/path/sky.exr")

What it builds (docs/renderers.md):

* a Volume object reading BAKE.vdb, moved by -0.5 voxel along each index axis: Blender
  3.4 places a VDB voxel i at index i + 0.5, OpenVDB (and lpmbake) at i;
* a material of stock nodes: Volume Absorption with sigma_t = density * lpm:density_scale,
  plus an Emission of sigma_s(x) * S(x, -view) per unit length, sigma_s = albedo * sigma_t.
  S is the `scatter` grid for an isotropic bake (SH order 0 without anisotropic sun
  terms); otherwise the real SH sum_k sh_k Y_k(w) at w = -view (Geometry > Incoming,
  turned into the grid frame by the object's world-to-object transform), clamped at zero,
  plus each exact sun term E_K T_K(x) p_HG(g, dot(-toward_K, w)) (docs/sun_term.md);
  plus sigma_a * L_e from the bake's `emission` grid when it has one (as `lpmbake render`);
  the result is converted from the bake's working colour space to Blender's scene linear
  (Linear Rec.709);
* or, with --material constant-free (import_bake(..., material="constant-free")), for a
  bake made with `lpmbake --renderer-grids`: Attribute `extinction` into the Volume
  Absorption's density and Attribute `source` (sigma_s * scatter + sigma_a * L_e) into the
  Emission, through the same colour conversion, and no number from the sidecar in the
  node tree (for g = 0 bakes: it interpolates sigma_s * S as one grid, so it is close to,
  not equal to, the material above; for g != 0 `source` is the direction average of S);
* with an environment: a world with the environment in lpmbake's orientation (lat-long,
  OpenEXR ImfEnvmap convention, +Y up, or +Z up for lpm:up_axis z, turned by
  lpm:env_rotate_y_deg, scaled by lpm:env_scale); without one a black world;
* with --render: a pinhole camera with `lpmbake render`'s conventions (vertical field of
  view, pixel (0,0) at the top left), Cycles on the CPU with a fixed seed, written as a
  scene-linear EXR (Linear Rec.709) or an sRGB PNG (view transform Standard).

The bake's parameters come from the sidecar JSON that `lpmbake ... --sidecar BAKE.json`
writes (Blender's Python cannot read VDB file metadata).  The VDB's world coordinates are
used as they are and the camera and environment follow the bake's frame (lpm:up_axis):
Blender's world is Z-up, so a Y-up bake (lpmbake's default) renders correctly but lies on
its side in Blender's viewport. import_bake(..., matrix=M) places the object; the baked
directions and the world's environment turn with M's rotation.

Errors print one line `lpm_import: error: ...` and exit with lpmbake's codes: 1 usage,
2 input, 3 output, 4 internal.
"""

import argparse
import json
import math
import os
import sys

import bpy
from mathutils import Matrix, Vector

PROG = "lpm_import"

# Real SH constants, ACN order (core/sh.cpp, docs/conventions.md).
_C0 = 0.28209479177387814
_C1 = 0.48860251190291992
_C2A = 1.0925484305920792     # Y4, Y5, Y7
_C2B = 0.31539156525252005    # Y6
_C2C = 0.54627421529603959    # Y8
_C3A = 0.59004358992664352    # Y9, Y15
_C3B = 2.8906114426405538     # Y10
_C3C = 0.45704579946446572    # Y11, Y13
_C3D = 0.37317633259011546    # Y12
_C3E = 1.4453057213202769     # Y14


class LpmError(Exception):
    """An error with lpmbake's exit code (1 usage, 2 input, 3 output, 4 internal)."""

    def __init__(self, code, message):
        super().__init__(message)
        self.code = code


def _log(msg):
    print(PROG + ": " + msg, flush=True)


# ---------------------------------------------------------------------------------------
# Sidecar
# ---------------------------------------------------------------------------------------

def default_sidecar_path(bake_path):
    root, ext = os.path.splitext(bake_path)
    return (root if ext.lower() == ".vdb" else bake_path) + ".json"


def read_sidecar(path):
    """The sidecar as a dict with "bake", "grids" and "metadata" (lpm:* keys)."""
    try:
        with open(path, "r", encoding="utf-8") as f:
            data = json.load(f)
    except FileNotFoundError:
        raise LpmError(2, "sidecar '%s' not found (bake with `lpmbake ... --sidecar %s`)" % (path, path))
    except (OSError, ValueError) as e:
        raise LpmError(2, "cannot read sidecar '%s': %s" % (path, e))
    if not isinstance(data, dict) or not isinstance(data.get("metadata"), dict):
        raise LpmError(2, "sidecar '%s' has no \"metadata\" object (not written by lpmbake --sidecar)" % path)
    if "lpm:format_version" not in data["metadata"]:
        raise LpmError(2, "sidecar '%s' has no lpm:format_version (not an lpmbake bake)" % path)
    return data


class BakeParams:
    """The parameters a renderer needs, from the sidecar's "metadata" object."""

    def __init__(self, meta, where):
        def num(key, default=None):
            v = meta.get(key, default)
            if v is None or isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise LpmError(2, "%s: %s is missing or not a finite number" % (where, key))
            return float(v)

        def vec3(key, default=None):
            v = meta.get(key, default)
            if isinstance(v, (int, float)) and not isinstance(v, bool):
                v = [v, v, v]
            if (not isinstance(v, list) or len(v) != 3 or
                    not all(isinstance(c, (int, float)) and math.isfinite(c) for c in v)):
                raise LpmError(2, "%s: %s is missing or not three finite numbers" % (where, key))
            return [float(c) for c in v]

        self.format_version = int(num("lpm:format_version"))
        if self.format_version > 2:
            _log("warning: %s: lpm:format_version %d is newer than this script knows (2)" %
                 (where, self.format_version))
        self.where = where
        self.density_grid = meta.get("lpm:density_grid", "density")
        self.renderer_grids = meta.get("lpm:renderer_grids") is True
        self.density_scale = num("lpm:density_scale", 1.0)
        self.albedo = vec3("lpm:albedo", [0.9, 0.9, 0.9])
        self.g = num("lpm:g", 0.0)
        self.sh_order = int(num("lpm:sh_order"))
        if not 0 <= self.sh_order <= 3:
            raise LpmError(2, "%s: lpm:sh_order %d is outside 0..3" % (where, self.sh_order))
        self.sh_count = int(num("lpm:sh_count", (self.sh_order + 1) ** 2))
        if self.sh_count != (self.sh_order + 1) ** 2:
            raise LpmError(2, "%s: lpm:sh_count %d does not match lpm:sh_order %d" %
                           (where, self.sh_count, self.sh_order))
        self.up_axis = str(meta.get("lpm:up_axis", "y")).lower()
        if self.up_axis not in ("y", "z"):
            raise LpmError(2, "%s: lpm:up_axis '%s' is neither y nor z" % (where, self.up_axis))
        self.env_rotate_y_deg = num("lpm:env_rotate_y_deg", 0.0)
        self.env_scale = num("lpm:env_scale", 1.0)
        self.env_colorspace = str(meta.get("lpm:env_colorspace", "lin_rec709"))
        self.env_file = str(meta.get("lpm:env_file", ""))
        self.working_colorspace = str(meta.get("lpm:working_colorspace", "ACEScg"))
        self.sun_term_g = num("lpm:sun_term_g", self.g)
        self.suns = []
        for k in range(int(num("lpm:sun_term_count", 0))):
            p = "lpm:sun_term_%d_" % k
            toward = Vector(vec3(p + "toward"))
            if toward.length == 0:
                raise LpmError(2, "%s: %stoward is the zero vector" % (where, p))
            self.suns.append({
                "toward": toward.normalized(),
                "irradiance": vec3(p + "irradiance"),
                "grid": str(meta.get(p + "grid", "sun_transmittance_%d" % k)),
            })
        self.has_emission = bool(meta.get("lpm:emission_grid") or meta.get("lpm:temperature_grid"))
        if not -1 < self.sun_term_g < 1 and self.suns:
            raise LpmError(2, "%s: lpm:sun_term_g %g is outside (-1, 1)" % (where, self.sun_term_g))

    def sh_grids(self):
        return ["sh_%d" % k for k in range(self.sh_count)]

    def uses_scatter_grid(self):
        """Isotropic S: the `scatter` grid holds it whole (sun terms included)."""
        return self.sh_order == 0 and (not self.suns or self.sun_term_g == 0)

    def needed_grids(self, material="auto"):
        if material == "constant-free":
            if not self.renderer_grids:
                raise LpmError(2, "%s has no \"lpm:renderer_grids\": true: --material constant-free "
                                  "needs a bake made with `lpmbake ... --renderer-grids`" % self.where)
            return ["extinction", "source"]
        if not self.density_grid:
            raise LpmError(2, "%s: the bake has no density grid (baked with --no-density); "
                              "nothing to render%s" % (self.where, " (it has renderer grids: use --material "
                                                       "constant-free)" if self.renderer_grids else ""))
        grids = [self.density_grid] + (["emission"] if self.has_emission else [])
        if self.uses_scatter_grid():
            grids.append("scatter")
        else:
            grids += self.sh_grids() + [s["grid"] for s in self.suns]
        return grids


# ---------------------------------------------------------------------------------------
# Colour: the bake's working space -> Blender's scene linear (Linear Rec.709 in 3.4)
# ---------------------------------------------------------------------------------------

def _xyz_matrix(prim, white):
    """RGB -> XYZ for chromaticities prim = ((xr, yr), (xg, yg), (xb, yb)) and white (x, y)."""
    def xyz(c):
        return Vector((c[0] / c[1], 1.0, (1 - c[0] - c[1]) / c[1]))
    m = Matrix((xyz(prim[0]), xyz(prim[1]), xyz(prim[2]))).transposed()
    s = m.inverted() @ xyz(white)
    return m @ Matrix(((s[0], 0, 0), (0, s[1], 0), (0, 0, s[2])))


def _bradford(src_white, dst_white):
    b = Matrix(((0.8951, 0.2664, -0.1614), (-0.7502, 1.7135, 0.0367), (0.0389, -0.0685, 1.0296)))

    def xyz(c):
        return Vector((c[0] / c[1], 1.0, (1 - c[0] - c[1]) / c[1]))
    s, d = b @ xyz(src_white), b @ xyz(dst_white)
    return b.inverted() @ Matrix(((d[0] / s[0], 0, 0), (0, d[1] / s[1], 0), (0, 0, d[2] / s[2]))) @ b


_D65 = (0.3127, 0.3290)
_ACES_WHITE = (0.32168, 0.33767)
_REC709 = ((0.64, 0.33), (0.30, 0.60), (0.15, 0.06))
_AP1 = ((0.713, 0.293), (0.165, 0.830), (0.128, 0.044))
_AP0 = ((0.7347, 0.2653), (0.0, 1.0), (0.0001, -0.077))


def working_to_rec709(space):
    """3x3 matrix from the bake's working space (data/config.ocio names and aliases) to
    linear Rec.709 (Bradford adaptation, as OCIO's *_BFD built-ins), or None for identity."""
    s = space.strip().lower()
    to709 = _xyz_matrix(_REC709, _D65).inverted()
    if s in ("lin_rec709", "linear", "lin_srgb", "linear rec.709 (srgb)", "scene-linear rec.709-srgb",
             "raw", "utility - raw"):
        return None
    if s in ("acescg", "aces - acescg", "lin_ap1"):
        return to709 @ _bradford(_ACES_WHITE, _D65) @ _xyz_matrix(_AP1, _ACES_WHITE)
    if s in ("aces2065-1", "aces", "aces2065_1", "aces - aces2065-1", "lin_ap0"):
        return to709 @ _bradford(_ACES_WHITE, _D65) @ _xyz_matrix(_AP0, _ACES_WHITE)
    if s in ("cie-xyz-d65", "cie_xyz_d65"):
        return to709
    _log("warning: working colour space '%s' unknown to this script: its values are used as "
         "Linear Rec.709" % space)
    return None


def _blender_colorspace(space):
    s = space.strip().lower()
    table = {"lin_rec709": "Linear", "linear": "Linear", "lin_srgb": "Linear",
             "acescg": "Linear ACEScg", "lin_ap1": "Linear ACEScg",
             "aces2065-1": "Linear ACES", "lin_ap0": "Linear ACES",
             "cie-xyz-d65": "XYZ", "srgb": "sRGB", "raw": "Non-Color"}
    return table.get(s)


# ---------------------------------------------------------------------------------------
# Node building
# ---------------------------------------------------------------------------------------

class _Nodes:
    """Small helpers that add stock nodes to a tree and return output sockets; any
    input may be a socket or a constant."""

    def __init__(self, tree):
        self.tree = tree
        self.x = 0

    def node(self, kind, **props):
        n = self.tree.nodes.new(kind)
        for k, v in props.items():
            setattr(n, k, v)
        n.location = (self.x, 0)
        self.x += 20
        return n

    def _set(self, sock, v):
        if isinstance(v, bpy.types.NodeSocket):
            self.tree.links.new(v, sock)
        else:
            sock.default_value = v

    def math(self, op, a, b=0.0, c=0.0):
        n = self.node("ShaderNodeMath", operation=op)
        for i, v in enumerate((a, b, c)):
            self._set(n.inputs[i], v)
        return n.outputs[0]

    def mul(self, *xs):
        out = xs[0]
        for x in xs[1:]:
            out = self.math("MULTIPLY", out, x)
        return out

    def vmath(self, op, a, b=(0.0, 0.0, 0.0), scale=None):
        n = self.node("ShaderNodeVectorMath", operation=op)
        self._set(n.inputs[0], a)
        self._set(n.inputs[1], b)
        if scale is not None:
            self._set(n.inputs[3], scale)
        return n.outputs["Value"] if op in ("DOT_PRODUCT", "LENGTH", "DISTANCE") else n.outputs["Vector"]

    def vscale(self, v, s):
        return self.vmath("SCALE", v, scale=s)

    def vadd(self, a, b):
        return self.vmath("ADD", a, b)

    def attribute(self, name, output):
        n = self.node("ShaderNodeAttribute", attribute_type="GEOMETRY", attribute_name=name)
        return n.outputs[output]

    def combine(self, x, y, z):
        n = self.node("ShaderNodeCombineXYZ")
        for i, v in enumerate((x, y, z)):
            self._set(n.inputs[i], v)
        return n.outputs[0]

    def matrix3(self, m, v):
        """m @ v for a constant 3x3 matrix and a vector socket."""
        rows = [self.vmath("DOT_PRODUCT", v, tuple(m[i])) for i in range(3)]
        return self.combine(*rows)


def _sh_basis(nb, w, order):
    """Sockets (or constants) of Y_0 .. Y_{(order+1)^2-1} at the unit vector socket w."""
    ys = [_C0]
    if order == 0:
        return ys
    sep = nb.node("ShaderNodeSeparateXYZ")
    nb.tree.links.new(w, sep.inputs[0])
    x, y, z = sep.outputs[0], sep.outputs[1], sep.outputs[2]
    ys += [nb.mul(y, _C1), nb.mul(z, _C1), nb.mul(x, _C1)]
    if order == 1:
        return ys
    xx, yy, zz = nb.mul(x, x), nb.mul(y, y), nb.mul(z, z)
    xy, yz, xz = nb.mul(x, y), nb.mul(y, z), nb.mul(x, z)
    x2_y2 = nb.math("SUBTRACT", xx, yy)
    ys += [nb.mul(xy, _C2A), nb.mul(yz, _C2A),
           nb.math("MULTIPLY_ADD", zz, 3 * _C2B, -_C2B),          # C (3 z^2 - 1)
           nb.mul(xz, _C2A), nb.mul(x2_y2, _C2C)]
    if order == 2:
        return ys
    five_z2_1 = nb.math("MULTIPLY_ADD", zz, 5.0, -1.0)
    ys += [nb.mul(y, nb.math("MULTIPLY_ADD", xx, 3.0, nb.math("MULTIPLY", yy, -1.0)), _C3A),
           nb.mul(xy, z, _C3B),
           nb.mul(y, five_z2_1, _C3C),
           nb.mul(z, nb.math("MULTIPLY_ADD", zz, 5.0, -3.0), _C3D),
           nb.mul(x, five_z2_1, _C3C),
           nb.mul(z, x2_y2, _C3E),
           nb.mul(x, nb.math("MULTIPLY_ADD", yy, -3.0, xx), _C3A)]
    return ys


def _volume_shader(nb, out, sigma_t, emit, working_colorspace):
    """Volume Absorption (density sigma_t) + Emission (colour emit, converted from the
    working space to Linear Rec.709, strength 1) into the material output's Volume."""
    tree = nb.tree
    m = working_to_rec709(working_colorspace)
    if m is not None:
        emit = nb.matrix3(m, emit)
    emission = nb.node("ShaderNodeEmission")
    tree.links.new(emit, emission.inputs["Color"])
    emission.inputs["Strength"].default_value = 1.0

    absorb = nb.node("ShaderNodeVolumeAbsorption")
    absorb.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)   # sigma_a = (1 - colour) * density
    tree.links.new(sigma_t, absorb.inputs["Density"])
    add = nb.node("ShaderNodeAddShader")
    tree.links.new(absorb.outputs[0], add.inputs[0])
    tree.links.new(emission.outputs[0], add.inputs[1])
    tree.links.new(add.outputs[0], out.inputs["Volume"])


def _new_material(name):
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    tree = mat.node_tree
    tree.nodes.clear()
    nb = _Nodes(tree)
    out = nb.node("ShaderNodeOutputMaterial", target="ALL")
    mat.cycles.volume_interpolation = "LINEAR"    # trilinear: the lighting shell covers it
    mat.cycles.homogeneous_volume = False
    return mat, nb, out


def build_constant_free_material(params, name="lpm_bake"):
    """The minimal material for a bake with renderer grids (--renderer-grids): Attribute
    `extinction` (sigma_t) into Volume Absorption, Attribute `source` (sigma_s * scatter +
    sigma_a * L_e) into an Emission of strength 1. Only the working colour space's name
    is used (for the conversion to Linear Rec.709): no number from the sidecar."""
    mat, nb, out = _new_material(name)
    _volume_shader(nb, out, nb.attribute("extinction", "Fac"), nb.attribute("source", "Vector"),
                   params.working_colorspace)
    return mat


def build_material(params, name="lpm_bake"):
    """A material of stock nodes rendering the bake (see the module docstring)."""
    mat, nb, out = _new_material(name)
    tree = nb.tree

    density = nb.attribute(params.density_grid, "Fac")
    sigma_t = nb.mul(density, params.density_scale)

    if params.uses_scatter_grid():
        s_total = nb.attribute("scatter", "Vector")
    else:
        # w = -view = Geometry > Incoming (toward the viewer, world space) in the grid frame.
        geom = nb.node("ShaderNodeNewGeometry")
        vt = nb.node("ShaderNodeVectorTransform", vector_type="VECTOR",
                     convert_from="WORLD", convert_to="OBJECT")
        tree.links.new(geom.outputs["Incoming"], vt.inputs[0])
        w = nb.vmath("NORMALIZE", vt.outputs[0])
        ys = _sh_basis(nb, w, params.sh_order)
        s_sh = None
        for k, yk in enumerate(ys):
            term = nb.vscale(nb.attribute("sh_%d" % k, "Vector"), yk)
            s_sh = term if s_sh is None else nb.vadd(s_sh, term)
        s_total = nb.vmath("MAXIMUM", s_sh, (0.0, 0.0, 0.0))     # clamp the SH part at zero
        g = params.sun_term_g
        for sun in params.suns:
            # E T p_HG(g, c), c = dot(-toward, w); p_HG = (1-g^2) / (4 pi (1 + g^2 - 2 g c)^1.5)
            c = nb.vmath("DOT_PRODUCT", w, tuple(-sun["toward"]))
            denom = nb.math("MULTIPLY_ADD", c, -2.0 * g, 1.0 + g * g)
            phase = nb.mul(nb.math("POWER", denom, -1.5), (1.0 - g * g) / (4.0 * math.pi))
            weight = nb.mul(nb.attribute(sun["grid"], "Fac"), phase)
            s_total = nb.vadd(s_total, nb.vscale(tuple(sun["irradiance"]), weight))

    # Emission per unit length: sigma_s * S = albedo * sigma_t * S.
    emit = nb.vscale(nb.vmath("MULTIPLY", s_total, tuple(params.albedo)), sigma_t)
    if params.has_emission:
        # The bake's own emission: sigma_a * L_e = (1 - albedo) * sigma_t * L_e (lpmbake render).
        le = nb.attribute("emission", "Vector")
        absorbed = tuple(1.0 - a for a in params.albedo)
        emit = nb.vadd(emit, nb.vscale(nb.vmath("MULTIPLY", le, absorbed), sigma_t))
    _volume_shader(nb, out, sigma_t, emit, params.working_colorspace)
    return mat


# ---------------------------------------------------------------------------------------
# Environment
# ---------------------------------------------------------------------------------------

def env_mapping_matrix(params):
    """Rotation taking a Blender world direction to the direction whose Blender
    equirectangular lookup (u = 0.5 - atan2(y, x) / 2pi, v = 0.5 + asin(z) / pi, v up)
    gives lpmbake's pixel (core/envmap.cpp: image frame +Y up, longitude 0 at +Z, +90 deg
    at +X; world = upTurn * rotateY * image, upTurn = +90 deg about +X for up axis z)."""
    spin = Matrix.Rotation(math.radians(params.env_rotate_y_deg), 3, "Y")
    up_turn = Matrix.Rotation(math.pi / 2, 3, "X") if params.up_axis == "z" else Matrix.Identity(3)
    # Image-frame direction d -> Blender lookup direction b = (d.z, d.x, d.y).
    perm = Matrix(((0, 0, 1), (1, 0, 0), (0, 1, 0)))
    return perm @ spin.transposed() @ up_turn.transposed()


def setup_world(scene, params, env_path=None, env_colorspace=None, rotation=None):
    """The scene's world: the environment in lpmbake's orientation, or black.

    rotation: the bake object's rotation (3x3, bake frame -> Blender world; default
    identity), so that the background stays where the baked lighting came from.

    env_colorspace: the image's colour space (an lpmbake/OCIO name such as lin_rec709 or
    a Blender one); default: lpm:env_colorspace when env_path is the bake's own
    environment (lpm:env_file), else Blender's guess (Linear for EXR/HDR, sRGB for 8-bit
    images: lpmbake's defaults too)."""
    world = bpy.data.worlds.new("lpm_world")
    scene.world = world
    world.use_nodes = True
    tree = world.node_tree
    tree.nodes.clear()
    nb = _Nodes(tree)
    out = nb.node("ShaderNodeOutputWorld")
    bg = nb.node("ShaderNodeBackground")
    tree.links.new(bg.outputs[0], out.inputs["Surface"])
    if not env_path:
        bg.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
        bg.inputs["Strength"].default_value = 0.0
        return world
    if not os.path.isfile(env_path):
        raise LpmError(2, "environment '%s' not found" % env_path)
    try:
        img = bpy.data.images.load(os.path.abspath(env_path), check_existing=True)
    except RuntimeError as e:
        raise LpmError(2, "cannot read environment '%s': %s" % (env_path, str(e).strip()))
    if img.size[0] <= 0 or img.size[1] <= 0:
        raise LpmError(2, "cannot read environment '%s'" % env_path)
    if img.size[0] != 2 * img.size[1]:
        raise LpmError(2, "environment '%s' is %dx%d, not a 2:1 lat-long image" %
                       (env_path, img.size[0], img.size[1]))
    space = env_colorspace
    if space is None and params.env_file and os.path.isfile(params.env_file) and \
            os.path.samefile(params.env_file, env_path):
        space = params.env_colorspace
    if space is not None:
        cs = _blender_colorspace(space) or space
        try:
            img.colorspace_settings.name = cs
        except TypeError:
            raise LpmError(1, "colour space '%s' is unknown to Blender's colour config" % space)
    coord = nb.node("ShaderNodeTexCoord")
    mapping = nb.node("ShaderNodeMapping", vector_type="VECTOR")
    m = env_mapping_matrix(params)
    if rotation is not None:
        m = m @ Matrix(rotation).to_3x3().transposed()
    mapping.inputs["Rotation"].default_value = m.to_euler("XYZ")
    tree.links.new(coord.outputs["Generated"], mapping.inputs["Vector"])
    tex = nb.node("ShaderNodeTexEnvironment", projection="EQUIRECTANGULAR", interpolation="Linear")
    tex.image = img
    tree.links.new(mapping.outputs[0], tex.inputs["Vector"])
    tree.links.new(tex.outputs["Color"], bg.inputs["Color"])
    bg.inputs["Strength"].default_value = params.env_scale
    return world


# ---------------------------------------------------------------------------------------
# Import
# ---------------------------------------------------------------------------------------

MATERIALS = ("auto", "constant-free")


def import_bake(path, sidecar=None, env=None, scene=None, world=True, name=None,
                half_voxel_shift=True, matrix=None, env_colorspace=None, material="auto"):
    """Import bake `path` into `scene` (default: the current one) and return the object.

    sidecar: the bake's JSON sidecar (default: path with .json).  env: environment image
    for the world (with world=True; None gives a black world, world=False leaves the
    world alone; env_colorspace: see setup_world).  matrix: the object's placement
    (default identity: the VDB's world coordinates as they are); the world's environment
    turns with its rotation.  half_voxel_shift: move by -0.5 voxel to undo Blender 3.4's
    half-voxel placement.  material: "auto" (density x lpm:density_scale, albedo, the
    `scatter` grid or the SH and sun terms from the sidecar) or "constant-free" (the
    renderer grids `extinction` and `source` of a bake made with --renderer-grids, no
    number from the sidecar; for g = 0 bakes, close to "auto": docs/renderers.md).
    """
    if material not in MATERIALS:
        raise LpmError(1, "material '%s' is not one of %s" % (material, ", ".join(MATERIALS)))
    scene = scene or bpy.context.scene
    path = os.path.abspath(bpy.path.abspath(path))
    if not os.path.isfile(path):
        raise LpmError(2, "bake '%s' not found" % path)
    sidecar = os.path.abspath(sidecar) if sidecar else default_sidecar_path(path)
    data = read_sidecar(sidecar)
    params = BakeParams(data["metadata"], "sidecar '%s'" % sidecar)
    if data.get("bake") and data["bake"] != os.path.basename(path):
        _log("warning: sidecar '%s' describes '%s', not '%s'" % (sidecar, data["bake"], os.path.basename(path)))
    needed = params.needed_grids(material)
    constant_free = material == "constant-free"
    if constant_free and (params.g != 0 or (params.suns and params.sun_term_g != 0)):
        _log("warning: '%s' has g = %g: `source` is the direction average of S, exact only for "
             "g = 0 (--material auto evaluates the SH and sun terms at -view)" % (path, params.g))

    name = name or os.path.splitext(os.path.basename(path))[0]
    vol = bpy.data.volumes.new(name)
    vol.filepath = path
    if not vol.grids.load():
        msg = vol.grids.error_message or "unreadable"
        bpy.data.volumes.remove(vol)
        raise LpmError(2, "Blender cannot read '%s': %s" % (path, msg))
    have = {g.name: g for g in vol.grids}
    if isinstance(data.get("grids"), list) and set(data["grids"]) != set(have):
        bpy.data.volumes.remove(vol)
        raise LpmError(2, "sidecar '%s' lists grids %s but '%s' holds %s (sidecar of another bake?)" %
                       (sidecar, sorted(data["grids"]), path, sorted(have)))
    for g in needed:
        if g not in have:
            bpy.data.volumes.remove(vol)
            raise LpmError(2, "'%s' has no grid '%s' (grids: %s)" % (path, g, ", ".join(sorted(have))))
    dens_name = "extinction" if constant_free else params.density_grid
    dens = have[dens_name]
    if dens.data_type != "FLOAT":
        bpy.data.volumes.remove(vol)
        raise LpmError(2, "grid '%s' of '%s' is %s, not a float grid" % (dens_name, path, dens.data_type))
    if constant_free and have["source"].data_type != "VECTOR_FLOAT":
        bpy.data.volumes.remove(vol)
        raise LpmError(2, "grid 'source' of '%s' is %s, not a Vec3f grid" % (path, have["source"].data_type))
    index_to_object = dens.matrix_object.copy()

    vol.render.precision = "FULL"        # Cycles stores grids as half floats by default
    vol.render.clipping = 0.0            # no voxel of the footprint is dropped
    vol.render.space = "OBJECT"
    vol.render.step_size = 0.0           # automatic: the voxel size
    vol.materials.append((build_constant_free_material if constant_free else build_material)(params, name + "_lpm"))

    obj = bpy.data.objects.new(name, vol)
    scene.collection.objects.link(obj)
    place = Matrix.Identity(4) if matrix is None else Matrix(matrix)
    if half_voxel_shift:
        # Blender 3.4 puts voxel i at index i + 0.5: move by -0.5 index units along each
        # index axis, in object units (the columns of the index-to-object matrix).
        m3 = index_to_object.to_3x3()
        shift = -0.5 * (m3.col[0] + m3.col[1] + m3.col[2])
        place = place @ Matrix.Translation(shift)
    obj.matrix_world = place
    obj["lpm_sidecar"] = sidecar
    obj["lpm_half_voxel_shift"] = bool(half_voxel_shift)
    obj["lpm_up_axis"] = params.up_axis
    obj["lpm_material"] = material
    if world:
        setup_world(scene, params, env, env_colorspace, rotation=place.to_quaternion().to_matrix())
    if constant_free:
        _log("imported '%s': renderer grids extinction and source (constant-free), up axis %s, "
             "working space %s" % (path, params.up_axis, params.working_colorspace))
    else:
        _log("imported '%s': %s, SH order %d, %d exact sun term(s), up axis %s, working space %s" %
             (path, "scatter grid" if params.uses_scatter_grid() else "SH at -view",
              params.sh_order, len(params.suns), params.up_axis, params.working_colorspace))
    return obj


# ---------------------------------------------------------------------------------------
# Camera and render
# ---------------------------------------------------------------------------------------

def camera_matrix(eye, target, up):
    """lpmbake's pinhole frame (core/camera.cpp): f = target - eye, r = f x up,
    u = r x f; Blender's camera looks along its -Z with +Y up."""
    eye, target, up = Vector(eye), Vector(target), Vector(up)
    f = target - eye
    if f.length == 0:
        raise LpmError(1, "--camera-eye and --camera-target must differ")
    f.normalize()
    r = f.cross(up)
    if r.length <= 1e-6 * max(up.length, 1e-300):
        raise LpmError(1, "--camera-up must not be parallel to the view direction")
    r.normalize()
    u = r.cross(f)
    return Matrix(((r.x, u.x, -f.x, eye.x), (r.y, u.y, -f.y, eye.y),
                   (r.z, u.z, -f.z, eye.z), (0, 0, 0, 1)))


def setup_render(scene, eye, target, up, fov_y, width, height, samples=64, seed=0,
                 pixel_filter=1.5, step_rate=0.5, transparent=False):
    if not 0 < fov_y < 180:
        raise LpmError(1, "--fov-y must be in (0, 180) degrees")
    if not (1 <= width <= 16384 and 1 <= height <= 16384):
        raise LpmError(1, "--size must be WxH with 1..16384 pixels per side")
    if samples < 1:
        raise LpmError(1, "--samples must be at least 1")
    cam_data = bpy.data.cameras.new("lpm_camera")
    cam_data.sensor_fit = "VERTICAL"
    cam_data.angle_y = math.radians(fov_y)
    dist = (Vector(target) - Vector(eye)).length
    cam_data.clip_start = 1e-4 * dist
    cam_data.clip_end = 1e6 * dist
    cam = bpy.data.objects.new("lpm_camera", cam_data)
    scene.collection.objects.link(cam)
    cam.matrix_world = camera_matrix(eye, target, up)
    scene.camera = cam

    r = scene.render
    r.engine = "CYCLES"
    r.resolution_x, r.resolution_y, r.resolution_percentage = width, height, 100
    r.pixel_aspect_x = r.pixel_aspect_y = 1.0
    r.film_transparent = transparent
    r.use_motion_blur = False
    c = scene.cycles
    c.device = "CPU"
    c.samples = samples
    c.use_adaptive_sampling = False
    c.use_denoising = False               # Debian's Blender has no OpenImageDenoise
    c.seed = seed
    c.use_animated_seed = False
    c.pixel_filter_type = "BLACKMAN_HARRIS"
    c.filter_width = max(0.01, pixel_filter)
    # Camera rays only: the bake holds the scattering; the volume's bounding mesh is
    # crossed as transparent surfaces.
    c.max_bounces = 0
    c.diffuse_bounces = c.glossy_bounces = c.transmission_bounces = c.volume_bounces = 0
    c.transparent_max_bounces = 1024
    c.volume_step_rate = step_rate        # in voxels (lpmbake render's --step 0.5)
    c.volume_max_steps = 8192
    c.sample_clamp_direct = c.sample_clamp_indirect = 0.0
    if scene.world is not None:
        # Nothing in this scene scatters light: the world is background only, and its
        # importance map (seconds, hundreds of MiB for a large HDRI) would be unused.
        scene.world.cycles.sampling_method = "NONE"
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    scene.display_settings.display_device = "sRGB"
    return cam


def check_output(out_path):
    """The image format from the extension; the directory must exist and be writable."""
    ext = os.path.splitext(out_path)[1].lower()
    if ext not in (".exr", ".png"):
        raise LpmError(1, "--render '%s' must end in .exr (scene-linear) or .png (sRGB view)" % out_path)
    out_dir = os.path.dirname(os.path.abspath(out_path))
    if not os.path.isdir(out_dir) or not os.access(out_dir, os.W_OK):
        raise LpmError(3, "cannot write '%s': directory missing or not writable" % out_path)
    return ext, out_dir


def render_to(scene, out_path):
    """Render the scene's camera with Cycles and write out_path (.exr: scene linear,
    32-bit float, zip; .png: 8-bit sRGB, view transform Standard) atomically."""
    ext, out_dir = check_output(out_path)
    s = scene.render.image_settings
    if ext == ".exr":
        s.file_format = "OPEN_EXR"
        s.color_depth = "32"
        s.exr_codec = "ZIP"
    else:
        s.file_format = "PNG"
        s.color_depth = "8"
    s.color_mode = "RGBA" if scene.render.film_transparent else "RGB"
    scene.render.use_file_extension = False
    tmp = os.path.join(out_dir, ".%s.lpmtmp-%d%s" % (os.path.basename(out_path), os.getpid(), ext))
    scene.render.filepath = tmp
    bpy.ops.render.render(write_still=True, scene=scene.name)
    if not os.path.isfile(tmp):
        raise LpmError(3, "Blender wrote no image to '%s'" % tmp)
    os.replace(tmp, out_path)
    _log("wrote %s (%dx%d, %s)" % (out_path, scene.render.resolution_x, scene.render.resolution_y,
                                   "Linear Rec.709" if ext == ".exr" else "sRGB view"))


# ---------------------------------------------------------------------------------------
# Command line
# ---------------------------------------------------------------------------------------

class _Parser(argparse.ArgumentParser):
    def error(self, message):
        raise LpmError(1, message)


def _vec3(text):
    try:
        v = [float(t) for t in text.split(",")]
    except ValueError:
        v = []
    if len(v) != 3 or not all(math.isfinite(c) for c in v):
        raise argparse.ArgumentTypeError("'%s' is not X,Y,Z" % text)
    return v


def _size(text):
    try:
        w, h = (int(t) for t in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError("'%s' is not WxH" % text)
    return w, h


def glue_values(argv, valued):
    """Values such as -30,-50,-300 look like options to argparse: glue them to their option
    (for the options in `valued`), as --camera-eye=-30,-50,-300."""
    out, i = [], 0
    while i < len(argv):
        if argv[i] in valued and i + 1 < len(argv):
            out.append(argv[i] + "=" + argv[i + 1])
            i += 2
        else:
            out.append(argv[i])
            i += 1
    return out


def parse_args(argv):
    p = _Parser(prog=PROG, description="Import an lpmbake bake into Blender (docs/renderers.md).")
    p.add_argument("bake")
    p.add_argument("--sidecar")
    p.add_argument("--env")
    p.add_argument("--env-colorspace", help="colour space of --env (default: see setup_world)")
    p.add_argument("--render", metavar="OUT")
    p.add_argument("--camera-eye", type=_vec3)
    p.add_argument("--camera-target", type=_vec3)
    p.add_argument("--camera-up", type=_vec3, help="default: the bake's up axis")
    p.add_argument("--fov-y", type=float, default=40.0)
    p.add_argument("--size", type=_size, default=(640, 360))
    p.add_argument("--samples", type=int, default=64)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--pixel-filter", type=float, default=1.5,
                   help="Blackman-Harris width in pixels (0.01: one ray through the pixel centre, as lpmbake render)")
    p.add_argument("--step-rate", type=float, default=0.5, help="volume step in voxels")
    p.add_argument("--transparent", action="store_true", help="transparent film: alpha = 1 - transmittance")
    p.add_argument("--material", choices=MATERIALS, default="auto",
                   help="auto: density, albedo, scatter or SH and sun terms with the sidecar's numbers; "
                        "constant-free: the renderer grids extinction and source (bake with --renderer-grids)")
    p.add_argument("--no-half-voxel-shift", action="store_true")
    p.add_argument("--save-blend")
    valued = {"--camera-eye", "--camera-target", "--camera-up", "--fov-y", "--step-rate", "--pixel-filter"}
    a = p.parse_args(glue_values(argv, valued))
    if a.render and (a.camera_eye is None or a.camera_target is None):
        raise LpmError(1, "--render needs --camera-eye and --camera-target")
    if not (a.step_rate > 0):
        raise LpmError(1, "--step-rate must be positive")
    return a


def main(argv):
    a = parse_args(argv)
    if a.render:
        check_output(a.render)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    obj = import_bake(a.bake, sidecar=a.sidecar, env=a.env, scene=scene,
                      half_voxel_shift=not a.no_half_voxel_shift, env_colorspace=a.env_colorspace,
                      material=a.material)
    if a.render:
        up = a.camera_up
        if up is None:
            up = (0, 0, 1) if obj["lpm_up_axis"] == "z" else (0, 1, 0)
        setup_render(scene, a.camera_eye, a.camera_target, up, a.fov_y, a.size[0], a.size[1],
                     samples=a.samples, seed=a.seed, pixel_filter=a.pixel_filter,
                     step_rate=a.step_rate, transparent=a.transparent)
    if a.save_blend:
        bpy.ops.wm.save_as_mainfile(filepath=os.path.abspath(a.save_blend))
    if a.render:
        render_to(scene, a.render)


def _cli():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    try:
        main(argv)
    except LpmError as e:
        sys.stderr.write("%s: error: %s\n" % (PROG, str(e).replace("\n", " ")))
        sys.stderr.flush()
        sys.stdout.flush()
        os._exit(e.code)
    except Exception as e:   # anything unexpected: one line, exit 4
        sys.stderr.write("%s: error: internal: %s: %s\n" % (PROG, type(e).__name__, str(e).replace("\n", " ")))
        sys.stderr.flush()
        sys.stdout.flush()
        os._exit(4)


if __name__ == "__main__":
    _cli()

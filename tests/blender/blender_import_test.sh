#!/usr/bin/env bash
# Checks scripts/blender/lpm_import.py (docs/renderers.md): bakes data/vdb/densityAndHeat.vdb
# (23x23x42 non-cubic voxels, lit by data/env/rooftop_small.hdr and a sun) four ways, renders
# each bake with `lpmbake render` and with Blender 3.4 Cycles through the script (same camera,
# 96x96, one ray through each pixel centre, 16 samples), and compares them per 4x4 block
# where the volume covers at least 10% (tests/blender/exr_tool.py):
#
#   A  g = 0, --up-axis z, lin_rec709 working space: the `scatter` grid path
#   B  g = 0.6, SH order 2 + exact sun term, ACEScg working space (default), env rotated
#      and scaled: the SH-at--view path, the sun term, the colour conversion to Rec.709
#   C  g = 0.6, --sun-term off (SH order 2 carries everything), lin_rec709
#   D  g = 0, --renderer-grids, density scale 2.5, albedo 0.95,0.7,0.4, rendered with
#      --material constant-free (Attribute extinction and source only; the material is
#      checked to hold no Math node and no density scale or albedo value)
#
# plus: the environment's orientation (Blender's world against lpmbake render's
# background with data/env/OrientationLatLong.exr, for the z-up bake A and the y-up bake C
# rotated by -60 degrees); that the comparison fails without the half-voxel shift; and
# one-line errors with lpmbake's exit codes (also --material constant-free on a bake without
# renderer grids).
#
#   tests/blender/blender_import_test.sh LPMBAKE SOURCE_DIR [SCRATCH_DIR]
#
# Exit 77 (skipped) without `blender` on PATH. About 70 s on 2 cores.
set -euo pipefail
NAME=blender_import_test
[ $# -ge 2 ] || { echo "usage: $0 LPMBAKE SOURCE_DIR [SCRATCH_DIR]" >&2; exit 1; }
command -v blender >/dev/null 2>&1 || { echo "$NAME: SKIP: blender is not on PATH"; exit 77; }
abspath() { case $1 in /*) echo "$1" ;; *) echo "$PWD/$1" ;; esac; }
LPMBAKE=$(abspath "$1"); SRC=$(abspath "$2")
W=$(abspath "${3:-${TMPDIR:-/tmp}/$NAME.$$}")/$NAME
SCRIPT=$SRC/scripts/blender/lpm_import.py
TOOL=$SRC/tests/blender/exr_tool.py
VDB=$SRC/data/vdb/densityAndHeat.vdb
SKY=$SRC/data/env/rooftop_small.hdr
ORIENT=$SRC/data/env/OrientationLatLong.exr
rm -rf "$W"; mkdir -p "$W"; cd "$W"
fail() { echo "$NAME: FAIL: $*" >&2; exit 1; }
start=$SECONDS

# Bounds (docs/renderers.md): measured mean 0.0017, worst block 0.010, alpha 0.0023 per
# case; a missing half-voxel shift gives mean 0.24, no albedo 0.11, the SH axes y/z swapped
# 0.059, the view direction flipped 0.60, no sun term 0.23.
MAX_MEAN=0.01; MAX_BLOCK=0.03; MAX_ALPHA=0.01
MAX_ENV_MEAN=0.002; MAX_ENV_BLOCK=0.01
# Case D (constant-free, docs/renderers.md): Blender interpolates the product sigma_s S (the
# `source` grid) trilinearly, `lpmbake render` multiplies the trilinear sigma_t and S (along
# one axis they differ by t(1-t) d(sigma_s) dS per cell): measured mean 0.024, p95 0.107,
# worst block 0.19, alpha 0.0024 (with `source` on the density's voxels only, before it got
# the lighting shell, 0.034 / 0.106 / 0.86); the `auto` material on the same bake 0.0017 /
# 0.005 / 0.014. A source without sigma_s gives mean 44, without the density scale 0.60,
# without the albedo 0.40, sigma_s applied twice 0.79.
MAX_D_MEAN=0.04; MAX_D_P95=0.15; MAX_D_BLOCK=0.3

blend() { blender -b --factory-startup --python "$SCRIPT" -- "$@"; }
tool() { blender -b --factory-startup --python "$TOOL" -- "$@" 2>&1 | grep -E "^($NAME|exr_tool)" || true; }
EYE=28,-30,12; TARGET=0.3,0.3,8; UP=0,0,1; FOV=32; SIZE=96x96

# bake CASE [--density-scale S] OPTIONS...: bake (density scale 2 unless given first) and
# write the sidecar.
bake() {
  local c=$1 ds=2; shift
  if [ "${1:-}" = --density-scale ]; then ds=$2; shift 2; fi
  "$LPMBAKE" "$VDB" --env "$SKY" --sun 0.3,0.8,0.5 --density-scale "$ds" -q "$@" \
    -o "$c.vdb" --sidecar "$c.json" || fail "$c: bake failed"
}

# volume CASE ENV_SCALE [COLOR_FROM [MATERIAL [BOUNDS]]]: lpmbake renders without and with a
# constant environment (coverage), Blender with a transparent film and --material MATERIAL
# (auto); compare within BOUNDS (exr_tool options; default MAX_MEAN, MAX_BLOCK, MAX_ALPHA).
# COLOR_FROM: working space of the bake, converted to lin_rec709 with oiiotool and
# data/config.ocio.
volume() {
  local c=$1 scale=$2 from=${3:-} material=${4:-auto} ref=$1_lpm.exr white=$1_lpm_white.exr
  local bounds=${5:-"--max-mean $MAX_MEAN --max-block $MAX_BLOCK --max-alpha $MAX_ALPHA"}
  "$LPMBAKE" render "$c.vdb" --eye $EYE --target $TARGET --up $UP --fov-y $FOV --size $SIZE \
    -q -o "$ref" || fail "$c: lpmbake render failed"
  "$LPMBAKE" render "$c.vdb" --eye $EYE --target $TARGET --up $UP --fov-y $FOV --size $SIZE \
    --env white.exr -q -o "$white" || fail "$c: lpmbake render (white) failed"
  if [ -n "$from" ]; then
    for f in "$ref" "$white"; do
      oiiotool --colorconfig "$SRC/data/config.ocio" "$f" --colorconvert "$from" lin_rec709 \
        -o "709_$f" || fail "$c: oiiotool colour conversion failed"
    done
    ref=709_$ref; white=709_$white
  fi
  blend "$c.vdb" --render "$c.blender.exr" --camera-eye $EYE --camera-target $TARGET \
    --camera-up $UP --fov-y $FOV --size $SIZE --samples 16 --pixel-filter 0.01 --transparent \
    --material "$material" > "$c.blender.log" 2>&1 || { cat "$c.blender.log"; fail "$c: Blender render failed"; }
  out=$(tool compare --ref "$ref" --white "$white" --white-radiance "$scale" --test "$c.blender.exr" \
        $bounds --label "$NAME: $c")
  echo "$out"
  case $out in *"[ok]"*) ;; *) fail "$c: Blender and lpmbake render disagree" ;; esac
}

# environment CASE EYE TARGET UP: the world's background against lpmbake render's.
environment() {
  local c=$1 eye=$2 target=$3 up=$4
  "$LPMBAKE" render "$c.vdb" --eye "$eye" --target "$target" --up "$up" --fov-y 100 --size 128x96 \
    --env "$ORIENT" -q -o "$c.env_lpm.exr" || fail "$c: lpmbake render (environment) failed"
  blend "$c.vdb" --env "$ORIENT" --render "$c.env_blender.exr" --camera-eye "$eye" \
    --camera-target "$target" --camera-up "$up" --fov-y 100 --size 128x96 --samples 1 \
    --pixel-filter 0.01 > "$c.env.log" 2>&1 || { cat "$c.env.log"; fail "$c: Blender render (environment) failed"; }
  out=$(tool compare --ref "$c.env_lpm.exr" --test "$c.env_blender.exr" \
        --max-mean $MAX_ENV_MEAN --max-block $MAX_ENV_BLOCK --label "$NAME: $c environment")
  echo "$out"
  case $out in *"[ok]"*) ;; *) fail "$c: the environment's orientation differs" ;; esac
}

blender -b --factory-startup --python "$TOOL" -- white white.exr > /dev/null 2>&1
[ -f white.exr ] || fail "could not write white.exr with Blender"

bake A --g 0 --up-axis z --working-space lin_rec709 --albedo 0.9
grep -q '"lpm:up_axis": "z"' A.json || fail "A: sidecar without lpm:up_axis z"
volume A 1
environment A 200,0,0 300,20,30 0,0,1

# The comparison must see a half-voxel error.
blend A.vdb --render A.noshift.exr --camera-eye $EYE --camera-target $TARGET --camera-up $UP \
  --fov-y $FOV --size $SIZE --samples 16 --pixel-filter 0.01 --transparent --no-half-voxel-shift \
  > A.noshift.log 2>&1 || fail "A: Blender render without the shift failed"
out=$(tool compare --ref A_lpm.exr --white A_lpm_white.exr --test A.noshift.exr \
      --max-mean $MAX_MEAN --max-block $MAX_BLOCK --label "$NAME: A without the half-voxel shift (must fail)")
echo "$out"
case $out in *"[FAIL"*) ;; *) fail "A: the comparison does not see a missing half-voxel shift" ;; esac

if command -v oiiotool > /dev/null 2>&1; then
  bake B --g 0.6 --albedo 0.9,0.8,0.7 --sun-irradiance 3,2.5,2 --env-rotate 30 --env-scale 0.8
  grep -q '"lpm:sun_term_count": 1' B.json || fail "B: no exact sun term in the bake"
  volume B 0.8 ACEScg
else
  echo "$NAME: case B skipped: oiiotool (openimageio-tools) not on PATH"
fi

bake C --g 0.6 --sun-term off --working-space lin_rec709 --albedo 0.85 --env-rotate -60
grep -q '"lpm:sh_order": 2' C.json || fail "C: not an SH order 2 bake"
volume C 1
environment C 0,0,-200 -30,-50,-300 0,1,0

bake D --density-scale 2.5 --g 0 --working-space lin_rec709 --albedo 0.95,0.7,0.4 --renderer-grids
grep -q '"lpm:renderer_grids": true' D.json || fail "D: sidecar without lpm:renderer_grids true"
volume D 1 "" constant-free "--max-mean $MAX_D_MEAN --max-p95 $MAX_D_P95 --max-block $MAX_D_BLOCK --max-alpha $MAX_ALPHA"
# The constant-free material: stock nodes reading extinction and source, no number from
# the sidecar (no Math or Value node, no input holding the density scale or an albedo).
cat > check_material.py <<'PY'
import json, sys
sys.path.insert(0, sys.argv[sys.argv.index("--") + 1])
import bpy, lpm_import
bpy.ops.wm.read_factory_settings(use_empty=True)
obj = lpm_import.import_bake("D.vdb", material="constant-free", world=False)
tree = obj.data.materials[0].node_tree
shader = json.load(open("D.json"))["shader"]
consts = [shader["density_scale"]] + list(shader["albedo"])
kinds = sorted(n.bl_idname for n in tree.nodes)
bad = [k for k in kinds if k in ("ShaderNodeMath", "ShaderNodeValue", "ShaderNodeVectorMath")]
names = sorted(n.attribute_name for n in tree.nodes if n.bl_idname == "ShaderNodeAttribute")
for n in tree.nodes:
    for i in n.inputs:
        if i.is_linked or not hasattr(i, "default_value"):
            continue
        v = i.default_value
        for x in (v if hasattr(v, "__len__") else [v]):
            if isinstance(x, float) and any(abs(x - c) <= 1e-6 * abs(c) for c in consts):
                bad.append("%s.%s = %g" % (n.name, i.name, x))
ok = not bad and names == ["extinction", "source"]
print("blender_import_test: D material %s: nodes %s, attributes %s%s" %
      ("ok" if ok else "FAIL", ", ".join(kinds), ", ".join(names), "; " + "; ".join(bad) if bad else ""))
PY
out=$(blender -b --factory-startup --python check_material.py -- "$SRC/scripts/blender" 2>&1 |
      grep "^$NAME: D material" || true)
echo "$out"
case $out in *"material ok"*) ;; *) fail "D: the constant-free material holds more than Attribute extinction and source" ;; esac

# Errors: one line, lpmbake's exit codes.
set +e
msg=$(blend A.vdb --sidecar missing.json 2>&1 >/dev/null); rc=$?
set -e
[ $rc -eq 2 ] || fail "missing sidecar: exit $rc, expected 2"
[ "$(printf '%s\n' "$msg" | grep -c '^lpm_import: error: ')" -eq 1 ] || fail "missing sidecar: message '$msg'"
set +e
msg=$(blend A.vdb --render x.exr --camera-eye 0,0,0 --camera-target 0,0,1 --size 96 2>&1 >/dev/null); rc=$?
set -e
[ $rc -eq 1 ] || fail "bad --size: exit $rc, expected 1"
printf '%s\n' "$msg" | grep -q "^lpm_import: error: .*WxH" || fail "bad --size: message '$msg'"
set +e
msg=$(blend A.vdb --material constant-free 2>&1 >/dev/null); rc=$?
set -e
[ $rc -eq 2 ] || fail "constant-free without renderer grids: exit $rc, expected 2"
[ "$(printf '%s\n' "$msg" | grep -c '^lpm_import: error: .*A\.json.*renderer_grids')" -eq 1 ] ||
  fail "constant-free without renderer grids: message '$msg'"

echo "$NAME: ok ($((SECONDS - start)) s)"

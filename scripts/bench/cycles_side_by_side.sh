#!/usr/bin/env bash
# lpmbake against Blender Cycles path tracing of the same physical volume, side by side, in
# one run (docs/cycles_comparison.md):
#
#   1. a volume: the procedural ~1M-voxel plume (`lpm_make_volume plume --res 124`) or --vdb;
#   2. lpmbake: one bake per setting (below; --setting), timed, then
#      `lpmbake render` of each bake with the same camera, timed; all in Linear Rec.709
#      (--env-colorspace lin_rec709 --working-space lin_rec709: no colour conversion);
#   3. Cycles (Blender 3.4, CPU) path-traces the PHYSICAL volume (not the bake): sigma_t =
#      density x density scale, albedo, Henyey-Greenstein g, the same environment in
#      lpmbake's orientation and the same pinhole camera (scripts/blender/lpm_import.py's
#      world and camera code), the half-voxel shift, a transparent film, no denoiser, no
#      clamping, 256 bounces: a 1-sample warm-up, the spp ladder and a reference, each
#      timed around bpy.ops.render.render;
#   4. relative L1 of every image against the reference where the volume covers the pixel
#      (reference alpha >= 0.1), per pixel and on 4x4 block means; the reference's own
#      noise; a fit of Cycles' error (err^2 = a/spp + b) and time; the Cycles time that
#      reaches each lpmbake setting's error, also extrapolated to 1920x1080; a markdown
#      table (OUT/table.md) and PNG previews (OUT/*.png, OUT/side_by_side.png).
#
#   scripts/bench/cycles_side_by_side.sh [--quick] [--vdb IN.vdb [--grid NAME]]
#       [--res 124] [--width 192] [--height 192] [--spp-ladder 16,64,256,1024] [--ref-spp 4096]
#       [--extra-spp N] [--density-scale 0.25] [--albedo 0.9] [--g 0] [--env SKY]
#       [--fov-y 40] [--eye X,Y,Z --target X,Y,Z --up X,Y,Z] [--step-rate 0.5] [--bounces 256]
#       [--setting NAME='LPMBAKE OPTIONS' ...] [--no-hd] [--hd-cycles-spp 4,16]
#       [--time-spp 16,64,256] [--threads N]
#       [--max-brightness-diff 0.1] [--max-coverage-diff 0.02]
#       [--out DIR] [--lpmbake PATH] [--make-volume PATH] [--cycles-from DIR]
#
# Settings: `--quality preview`, `default`, `production` when `lpmbake --help` lists
# --quality, else the option sets preview (--solve-scale 0.5 --directions-per-face 2
# --rays-per-voxel 1), cheap (--directions-per-face 2 --rays-per-voxel 1), default, fine
# (--directions-per-face 8 --rays-per-voxel 3). --cycles-from DIR reuses the Cycles renders
# of an earlier run in DIR (same camera, ladder, reference spp, step rate, bounces, density
# scale, albedo, g: checked) to compare another lpmbake against them without re-rendering;
# Cycles is then timed again at --time-spp (default 16,64,256; `none` keeps DIR's times), so
# both renderers' seconds come from this run's machine state.
#
# HD: lpmbake render at 1920x1080 (timed), and Cycles rendered at 1920x1080 at
# --hd-cycles-spp (default 4,16; `none`: the HD Cycles times are then extrapolated from the
# sample time by the pixel count) for its HD time model; Cycles' error at a given spp comes
# from the WxH ladder.
#
# --quick: a small plume (--res 32, 16k voxels), 48x48 pixels, ladder 4,16, reference 64,
# no HD render: a smoke test of the whole pipeline (about 30 s on 2 cores). Exits non-zero
# on any failure, also when an lpmbake image's overall brightness differs from the
# reference's by more than --max-brightness-diff or lpmbake render's coverage (1 - T)
# differs from the reference's alpha by more than --max-coverage-diff on average (a wrong
# camera or half-voxel shift); the outputs are written first. Exit 77 with a SKIP line when
# `blender` is not on PATH. Full run at the defaults on 2 cores: about 50 minutes (the
# reference alone ~30; docs/cycles_comparison.md).
set -euo pipefail
NAME=cycles_side_by_side
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
PY=$ROOT/scripts/bench/cycles_side_by_side.py
abspath() { case $1 in /*) echo "$1" ;; *) echo "$PWD/$1" ;; esac; }
die() { echo "$NAME: error: $1" >&2; exit "${2:-1}"; }   # die MESSAGE [EXIT CODE]
usage() { sed -n '2,/^set -euo/p' "$0" | sed '$d' | sed 's/^# \{0,1\}//'; }

LPMBAKE=$ROOT/build/baker/lpmbake
MAKEVOL=$ROOT/build/scripts/bench/lpm_make_volume
OUT=$ROOT/out/bench/cycles
ENV=$ROOT/data/env/rooftop_small.hdr
VDB=""; GRID=""; RES=124; W=192; H=192; LADDER=16,64,256,1024; REF=4096; EXTRA=0
DS=0.25; ALBEDO=0.9; G=0; FOV=40; EYE=""; TARGET=""; UP=""; STEP=0.5; BOUNCES=256
THREADS=0; QUICK=0; HD=1; MAXB=0.1; MAXCOV=0.02; CYCLES_FROM=""; HD_SPP=4,16; TIME_SPP=""
SETTINGS=()
set_w=0; set_h=0; set_ladder=0; set_ref=0; set_res=0
while [ $# -gt 0 ]; do
  opt=$1
  case $opt in
    -h|--help) usage; exit 0 ;;
    --quick) QUICK=1; shift; continue ;;
    --no-hd) HD=0; shift; continue ;;
  esac
  [ $# -ge 2 ] || die "$opt needs a value (--help)"
  v=$2; shift 2
  case $opt in
    --vdb) VDB=$(abspath "$v") ;;
    --grid) GRID=$v ;;
    --res) RES=$v; set_res=1 ;;
    --width) W=$v; set_w=1 ;;
    --height) H=$v; set_h=1 ;;
    --spp-ladder) LADDER=$v; set_ladder=1 ;;
    --ref-spp) REF=$v; set_ref=1 ;;
    --extra-spp) EXTRA=$v ;;
    --hd-cycles-spp) HD_SPP=$v ;;
    --time-spp) TIME_SPP=$v ;;
    --density-scale) DS=$v ;;
    --albedo) ALBEDO=$v ;;
    --g) G=$v ;;
    --env) ENV=$(abspath "$v") ;;
    --fov-y) FOV=$v ;;
    --eye) EYE=$v ;;
    --target) TARGET=$v ;;
    --up) UP=$v ;;
    --step-rate) STEP=$v ;;
    --bounces) BOUNCES=$v ;;
    --setting) SETTINGS+=("$v") ;;
    --threads) THREADS=$v ;;
    --max-brightness-diff) MAXB=$v ;;
    --max-coverage-diff) MAXCOV=$v ;;
    --out) OUT=$(abspath "$v") ;;
    --cycles-from) CYCLES_FROM=$(abspath "$v") ;;
    --lpmbake) LPMBAKE=$(abspath "$v") ;;
    --make-volume) MAKEVOL=$(abspath "$v") ;;
    *) die "unknown option '$opt' (--help)" ;;
  esac
done
if [ "$QUICK" = 1 ]; then
  [ $set_res = 1 ] || RES=32
  [ $set_w = 1 ] || W=48
  [ $set_h = 1 ] || H=48
  [ $set_ladder = 1 ] || LADDER=4,16
  [ $set_ref = 1 ] || REF=64
  HD=0
fi
for n in "$W" "$H" "$REF" "$RES" "$BOUNCES" "$EXTRA" "$THREADS"; do
  [[ $n =~ ^[0-9]+$ ]] || die "'$n' is not a non-negative integer"
done
[[ $LADDER =~ ^[0-9]+(,[0-9]+)+$ ]] || die "--spp-ladder '$LADDER' must list at least two sample counts, as 16,64,256"
if [ -z "$TIME_SPP" ]; then
  if [ -n "$CYCLES_FROM" ]; then TIME_SPP=16,64,256; else TIME_SPP=none; fi
fi
for l in "$HD_SPP" "$TIME_SPP"; do
  [ "$l" = none ] || [[ $l =~ ^[0-9]+(,[0-9]+)+$ ]] || die "'$l' must be none or list at least two sample counts, as 4,16"
done
[ -z "$EYE$TARGET" ] || { [ -n "$EYE" ] && [ -n "$TARGET" ]; } || die "--eye and --target go together"

command -v blender > /dev/null 2>&1 || { echo "$NAME: SKIP: blender is not on PATH"; exit 77; }
[ -x "$LPMBAKE" ] || die "lpmbake '$LPMBAKE' not found or not executable (build it, or --lpmbake PATH)" 2
[ -f "$ENV" ] || die "environment '$ENV' not found" 2
if [ ${#SETTINGS[@]} -eq 0 ]; then
  help=$("$LPMBAKE" --help 2>&1 || true)
  if [[ $help == *--quality* ]]; then        # the presets, where this lpmbake has them
    SETTINGS=("preview=--quality preview" "default=--quality default" "production=--quality production")
    [ "$QUICK" = 0 ] || SETTINGS=("preview=--quality preview" "default=--quality default")
  else
    SETTINGS=("preview=--solve-scale 0.5 --directions-per-face 2 --rays-per-voxel 1"
              "cheap=--directions-per-face 2 --rays-per-voxel 1" "default="
              "fine=--directions-per-face 8 --rays-per-voxel 3")
    [ "$QUICK" = 0 ] || SETTINGS=("cheap=--directions-per-face 2 --rays-per-voxel 1" "default=")
  fi
fi
for s in "${SETTINGS[@]}"; do
  name=${s%%=*}
  if ! [[ $name =~ ^[A-Za-z0-9_-]+$ ]] || [ "$name" = "$s" ]; then die "--setting '$s' is not NAME=OPTIONS"; fi
done
[ -n "$VDB" ] || [ -x "$MAKEVOL" ] || die "lpm_make_volume '$MAKEVOL' not found (build it, --make-volume PATH, or --vdb)" 2
[ -z "$VDB" ] || [ -f "$VDB" ] || die "volume '$VDB' not found" 2

mkdir -p "$OUT/logs"
cd "$OUT"
start=$SECONDS
now() { echo "$EPOCHREALTIME"; }
elapsed() { python3 -c "import sys; print('%.3f' % (float(sys.argv[2]) - float(sys.argv[1])))" "$1" "$2"; }
blend() { blender -b --factory-startup --python "$PY" -- "$@"; }
# run LOG CMD...: CMD's output into logs/LOG; on failure show its tail and stop.
run() {
  local log=logs/$1; shift
  if ! "$@" > "$log" 2>&1; then
    tail -n 20 "$log" >&2
    die "failed: $* (log: $OUT/$log)" 2
  fi
}

echo "$NAME: $(date -u +%Y-%m-%dT%H:%MZ), $(nproc) cores ($(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //')), $(blender --version 2>/dev/null | sed -n 1p), load average $(cut -d' ' -f1-3 /proc/loadavg), out $OUT"

# 1. The volume.
if [ -z "$VDB" ]; then
  VDB=$OUT/plume_res$RES.vdb
  run make_volume.log "$MAKEVOL" plume "$VDB" --res "$RES"
  echo "$NAME: volume: $(cat logs/make_volume.log)"
fi
GRIDOPT=()
[ -z "$GRID" ] || GRIDOPT=(--grid "$GRID")
THREADOPT=()
[ "$THREADS" = 0 ] || THREADOPT=(--threads "$THREADS")

# 2. lpmbake bakes, one per setting.
names=(); bake_s=(); opts=()
for s in "${SETTINGS[@]}"; do
  name=${s%%=*}; o=${s#*=}
  # shellcheck disable=SC2206
  extra=($o)
  t0=$(now)
  run "bake_$name.log" "$LPMBAKE" "$VDB" "${GRIDOPT[@]}" --env "$ENV" --env-colorspace lin_rec709 \
    --working-space lin_rec709 --density-scale "$DS" --albedo "$ALBEDO" --g "$G" "${extra[@]}" \
    "${THREADOPT[@]}" --stats "bake_$name.stats.json" --sidecar "bake_$name.json" -o "bake_$name.vdb"
  t1=$(now)
  names+=("$name"); opts+=("$o"); bake_s+=("$(elapsed "$t0" "$t1")")
  echo "$NAME: bake $name (${o:-defaults}): ${bake_s[-1]} s (load average $(cut -d" " -f1 /proc/loadavg))"
done
first=${names[0]}
for n in "${names[@]}"; do [ "$n" != default ] || first=default; done

# 3. The camera: lpmbake render's framing (or --eye/--target/--up), computed from the
# density's active index box and its index-to-world matrix.
dgrid=$(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['metadata'].get('lpm:density_grid', 'density'))" "bake_$first.json")
bbox=$("$LPMBAKE" info "bake_$first.vdb" | python3 -c "
import re, sys
g = sys.argv[1]
found = []
for line in sys.stdin.read().splitlines():   # read everything: no SIGPIPE for lpmbake
    m = re.search(r'index bbox \[(-?\d+), (-?\d+), (-?\d+)\]\.\.\[(-?\d+), (-?\d+), (-?\d+)\]', line)
    if m and line.strip().startswith(g + ':'):
        found.append(','.join(m.groups()))
print(found[0] if found else '')
" "$dgrid")
[ -n "$bbox" ] || die "cannot read the density's index box from 'lpmbake info bake_$first.vdb'" 2
camopt=()
[ -z "$EYE" ] || camopt+=(--eye "$EYE" --target "$TARGET")
[ -z "$UP" ] || camopt+=(--up "$UP")
run camera.log blend camera --bake "bake_$first.vdb" --sidecar "bake_$first.json" --index-bbox "$bbox" \
  --size "${W}x$H" --fov-y "$FOV" "${camopt[@]}" --out camera.json --white white.exr
read -r CEYE CTARGET CUP < <(python3 -c "
import json; c = json.load(open('camera.json'))
print(' '.join(','.join('%.9g' % x for x in c[k]) for k in ('eye', 'target', 'up')))")
echo "$NAME: camera eye $CEYE target $CTARGET up $CUP fov-y $FOV, ${W}x$H (lpmbake render's conventions)"
CAM=(--eye "$CEYE" --target "$CTARGET" --up "$CUP" --fov-y "$FOV")

# 4. lpmbake render of every bake (no environment behind: black, as the transparent film),
# timed; the first bake also with a white environment (coverage 1 - T) and at 1920x1080.
render_s=(); render_hd_s=()
for i in "${!names[@]}"; do
  n=${names[$i]}
  t0=$(now)
  run "render_$n.log" "$LPMBAKE" render "bake_$n.vdb" "${CAM[@]}" --size "${W}x$H" --step "$STEP" \
    "${THREADOPT[@]}" -o "lpmbake_$n.exr"
  t1=$(now)
  render_s+=("$(elapsed "$t0" "$t1")")
  hd=""
  if [ "$HD" = 1 ]; then
    t0=$(now)
    run "render_${n}_hd.log" "$LPMBAKE" render "bake_$n.vdb" "${CAM[@]}" --size 1920x1080 --step "$STEP" \
      "${THREADOPT[@]}" -o "lpmbake_${n}_1920x1080.exr"
    t1=$(now)
    hd=$(elapsed "$t0" "$t1")
  fi
  render_hd_s+=("$hd")
  echo "$NAME: lpmbake render $n: ${render_s[-1]} s${hd:+ (1920x1080: $hd s)}"
done
run render_white.log "$LPMBAKE" render "bake_$first.vdb" "${CAM[@]}" --size "${W}x$H" --step "$STEP" \
  --env white.exr "${THREADOPT[@]}" -o "lpmbake_${first}_white.exr"

# 5. Cycles: warm-up, ladder, (extra,) reference; progress lines pass through. With
# --cycles-from DIR: DIR's renders, when they were made with the same camera and numbers.
if [ -n "$CYCLES_FROM" ]; then
  python3 - "$CYCLES_FROM" "$LADDER" "$REF" "$STEP" "$BOUNCES" "bake_$first.json" <<'PY' ||
import json, os, sys
d, ladder, ref, step, bounces, sidecar = sys.argv[1:]
t = json.load(open(os.path.join(d, "cycles_timings.json")))
old = json.load(open(os.path.join(d, "camera.json")))
new = json.load(open("camera.json"))
meta = json.load(open(sidecar))["metadata"]
bad = []
for k in ("eye", "target", "up"):
    if max(abs(a - b) for a, b in zip(old[k], new[k])) > 1e-4 * (1 + max(abs(x) for x in new[k])):
        bad.append("camera %s" % k)
for k in ("fov_y", "width", "height"):
    if old[k] != new[k]:
        bad.append("camera %s" % k)
runs = t["renders"]
if sorted(r["spp"] for r in runs if r["kind"] == "ladder") != sorted(int(x) for x in ladder.split(",")):
    bad.append("ladder")
if [r["spp"] for r in runs if r["kind"] == "reference"] != [int(ref)]:
    bad.append("reference spp")
if abs(t["step_rate"] - float(step)) > 1e-9 or t["bounces"] != int(bounces):
    bad.append("step rate or bounces")
if abs(t["density_scale"] - meta["lpm:density_scale"]) > 1e-6 or abs(t["g"] - meta["lpm:g"]) > 1e-6 or \
        max(abs(a - b) for a, b in zip(t["albedo"], meta["lpm:albedo"])) > 1e-6:
    bad.append("density scale, albedo or g")
if not all(os.path.isfile(r["image"]) for r in runs):
    bad.append("missing images")
if bad:
    print("cycles_side_by_side: error: --cycles-from %s: other %s" % (d, ", ".join(bad)), file=sys.stderr)
    sys.exit(1)
PY
    die "the renders in '$CYCLES_FROM' do not fit this run (or are missing)" 1
  [ "$CYCLES_FROM" -ef "$OUT" ] || cp "$CYCLES_FROM/cycles_timings.json" cycles_timings.json
  echo "$NAME: Cycles: reusing the renders of $CYCLES_FROM (same camera, ladder, reference, medium)"
else
extra_txt=""; [ "$EXTRA" = 0 ] || extra_txt=", extra $EXTRA spp"
echo "$NAME: Cycles: ladder $LADDER, reference $REF spp$extra_txt, ${W}x$H (log: $OUT/logs/cycles.log)"
t_launch=$(now)
set +e
blend render --vdb "$VDB" ${GRID:+--grid "$GRID"} --sidecar "bake_$first.json" --env "$ENV" \
  --camera camera.json --spp "$LADDER" --ref-spp "$REF" --extra-spp "$EXTRA" --step-rate "$STEP" \
  --bounces "$BOUNCES" --threads "$THREADS" --t-launch "$t_launch" --out "$OUT" --timings cycles_timings.json \
  > logs/cycles.log 2>&1 &
pid=$!
tail -n +1 -f logs/cycles.log --pid "$pid" | grep --line-buffered "^$NAME: .*s ->" || true
wait "$pid"; rc=$?
set -e
if [ $rc -ne 0 ]; then
  tail -n 20 logs/cycles.log >&2
  die "Cycles render failed (exit $rc; log: $OUT/logs/cycles.log)" 2
fi
fi

# 5b. Timing-only Cycles renders (images kept, errors not used): again at WxH when the
# ladder's renders were reused, and at 1920x1080 for the HD time model.
# cycles_timing DIR CAMERA.json SPP-LIST
cycles_timing() {
  mkdir -p "$1"
  echo "$NAME: Cycles timing renders $(python3 -c "import json,sys; c=json.load(open(sys.argv[1])); print('%dx%d' % (c['width'], c['height']))" "$2"), $3 spp (log: $OUT/logs/$1.log)"
  run "$1.log" blend render --vdb "$VDB" ${GRID:+--grid "$GRID"} --sidecar "bake_$first.json" --env "$ENV" \
    --camera "$2" --spp "$3" --ref-spp 1 --step-rate "$STEP" --bounces "$BOUNCES" --threads "$THREADS" \
    --out "$OUT/$1" --timings "$1/cycles_timings.json"
  grep "^$NAME: ladder" "logs/$1.log" || true
}
timeopt=()
if [ "$TIME_SPP" != none ]; then
  cycles_timing timing camera.json "$TIME_SPP"
  timeopt+=(--time-runs timing/cycles_timings.json)
fi
if [ "$HD" = 1 ] && [ "$HD_SPP" != none ]; then
  python3 -c "import json,sys; c=json.load(open(sys.argv[1])); c['width'], c['height'] = 1920, 1080; json.dump(c, open(sys.argv[2], 'w'), indent=1)" camera.json camera_hd.json
  cycles_timing hd camera_hd.json "$HD_SPP"
  timeopt+=(--hd-time-runs hd/cycles_timings.json)
fi

# 6. Compare, tables, previews.
python3 - "${#names[@]}" "${names[@]}" "${opts[@]}" "${bake_s[@]}" "${render_s[@]}" "${render_hd_s[@]}" <<'PY' > manifest.json
import json, sys
k = int(sys.argv[1]); a = sys.argv[2:]
names, opts, bake, rend, hd = (a[i * k:(i + 1) * k] for i in range(5))
print(json.dumps({"lpmbake": [
    {"setting": n, "options": o, "bake_s": float(b), "render_s": float(r),
     "render_hd_s": float(h) if h else None, "image": "lpmbake_%s.exr" % n}
    for n, o, b, r, h in zip(names, opts, bake, rend, hd)]}, indent=1))
PY
set +e
blend compare --manifest manifest.json --timings cycles_timings.json --out "$OUT" "${timeopt[@]}" \
  --white-lpm "lpmbake_${first}_white.exr" --black-lpm "lpmbake_$first.exr" \
  --md table.md --side-by-side side_by_side.png > logs/compare.log 2>&1
rc=$?
set -e
[ $rc -eq 0 ] || { tail -n 20 logs/compare.log >&2; die "compare failed (exit $rc; log: $OUT/logs/compare.log)" 2; }
cat table.md
echo "$NAME: volume $VDB; density scale $DS, albedo $ALBEDO, g $G; environment $ENV"

# 7. Sanity bounds (the outputs above are written first).
python3 - "$MAXB" "$MAXCOV" <<'PY' || die "sanity check failed (see above)" 1
import json, sys
maxb, maxcov = float(sys.argv[1]), float(sys.argv[2])
r = json.load(open("report.json"))
bad = []
for row in r["rows"]:
    if row["kind"] == "lpmbake" and abs(row["brightness"] - 1) > maxb:
        bad.append("lpmbake %s: brightness %.3f of the reference's (bound %g)" % (row["setting"], row["brightness"], maxb))
cov = r.get("coverage_diff")
if cov is None or not cov["mean_volume"] <= maxcov:
    bad.append("coverage: lpmbake render's 1 - T vs the Cycles alpha %s (bound %g)" %
               ("missing" if cov is None else "%.4f" % cov["mean_volume"], maxcov))
for b in bad:
    print("cycles_side_by_side: FAIL: " + b, file=sys.stderr)
sys.exit(1 if bad else 0)
PY
echo "$NAME: ok ($((SECONDS - start)) s, load average $(cut -d' ' -f1-3 /proc/loadavg); $OUT/table.md, $OUT/side_by_side.png)"

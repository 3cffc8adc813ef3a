#!/usr/bin/env bash
# The accuracy study (docs/accuracy.md, "The study"): what each knob and preset costs in
# time and error, against the Monte Carlo reference, on scenes generated here.
#   scripts/accuracy/run.sh [--quick] [--scenes a,b] [--out DIR] [--docs DIR]
# For each scene: the volume (lpm_make_volume, data/vdb, or Blender Mantaflow when `blender`
# is installed), a Monte Carlo reference (lpm_study reference: SH at 64 voxels and a
# 64x64 camera image), then one lpmbake bake per setting (separate processes: wall time and
# peak RSS are the bake's own), each compared with the reference (lpm_study compare) and
# checked by --verify 64; then, per scene, the default bake's --verify 64 estimate against
# the same error measured with 1024 probes of other voxels (--verify-seed 2). Writes
# DIR/results.jsonl and DIR/verify.jsonl, then scripts/accuracy/plot.py makes the plots
# (DOCS/accuracy/*.png) and the tables between the study markers of DOCS/accuracy.md
# (DOCS: docs). --quick: the presets only, smaller references, no 1024-probe check (the
# smoke test, tests/accuracy). LPM_BUILD_DIR: the build directory (default build).
set -euo pipefail
cd "$(dirname "$0")/../.."
quick=0; out=out/accuracy; only=""; docs=docs
while [ $# -gt 0 ]; do
  case "$1" in
    --quick) quick=1 ;;
    --out) out="$2"; shift ;;
    --scenes) only="$2"; shift ;;
    --docs) docs="$2"; shift ;;
    *) echo "usage: run.sh [--quick] [--scenes a,b] [--out DIR] [--docs DIR]" >&2; exit 2 ;;
  esac
  shift
done
B=${LPM_BUILD_DIR:-build}
for t in baker/lpmbake scripts/bench/lpm_study scripts/bench/lpm_make_volume; do
  [ -x "$B/$t" ] || { bash scripts/build.sh >/dev/null; break; }
done
python3 -c "import matplotlib" 2>/dev/null || /usr/bin/python3 -c "import matplotlib" 2>/dev/null || {
  SUDO=""; [ "$(id -u)" = 0 ] || SUDO=sudo
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends python3-matplotlib >/dev/null; }
LPMBAKE=$B/baker/lpmbake; STUDY=$B/scripts/bench/lpm_study; MAKE=$B/scripts/bench/lpm_make_volume
mkdir -p "$out"; results=$out/results.jsonl; : > "$results"; agreement=$out/verify.jsonl; : > "$agreement"
sky=data/env/rooftop_small.hdr
$STUDY sky "$out/sunsky.exr"

# name | volume | bake (and reference) arguments | reference voxels x paths, image spp
scenes=(
  "smoke|mantaflow|--density-scale 25 --albedo 0.9 --env $sky --up-axis z|4096 512"
  "fire|data/vdb/densityAndHeat.vdb|--density-scale 2 --albedo 0.8 --g 0.3 --env $sky --temperature-grid heat --temperature-scale 2000 --temperature-offset 1000|4096 512"
  "cumulus|cloud 48|--density-scale 2 --albedo 0.99 --env $sky|1024 128"
  "forward|cloud 48|--density-scale 0.5 --albedo 0.95 --g 0.85 --env $sky --sun 0.4,1,0.3 --sun-irradiance 5|4096 512"
  "wispy|plume 64|--density-scale 0.1 --albedo 0.9 --env $sky|4096 512"
  "sun-in-map|plume 64|--density-scale 0.5 --albedo 0.9 --g 0.6 --env $out/sunsky.exr|4096 512"
)
# name | knob | flags
settings=(
  "preview|preset|--quality preview" "default|preset|--quality default" "production|preset|--quality production"
  "n=1|directions|--directions-per-face 1" "n=2|directions|--directions-per-face 2"
  "n=3|directions|--directions-per-face 3" "n=6|directions|--directions-per-face 6"
  "r=1|rays|--rays-per-voxel 1" "r=3|rays|--rays-per-voxel 3"
  "bins 1|bins|--bins-per-face 1" "bins 4|bins|--bins-per-face 4"
  "sh 1|sh order|--sh-order 1" "sh 3|sh order|--sh-order 3"
  "tol 1e-2|tolerance|--tolerance 1e-2" "tol 1e-4|tolerance|--tolerance 1e-4"
  "max orders 3|max orders|--max-orders 3"
  "solve scale 0.5|solve scale|--solve-scale 0.5"
  "multires off|multires|--multires off"
  "no hot pixels|hot pixels|--env-hot-share 1"
  "no GMRES|acceleration|--no-krylov"
  "linear source|source|--source linear"
)
[ "$quick" = 1 ] && settings=("${settings[@]:0:3}")

volume() {  # volume SPEC NAME -> path
  case "$1" in
    mantaflow)
      if [ ! -f "$out/mantaflow/smoke.0040.vdb" ] && command -v blender >/dev/null; then
        bash scripts/volumes/make_blender_smoke.sh "$out/mantaflow" --res 96 --end 40 >&2
      fi
      [ -f "$out/mantaflow/smoke.0040.vdb" ] && echo "$out/mantaflow/smoke.0040.vdb" || echo "" ;;
    data/*) echo "$1" ;;
    *) read -r kind res <<< "$1"
       $MAKE "$kind" "$out/$2.vdb" --res "$res" >/dev/null
       echo "$out/$2.vdb" ;;
  esac
}

for scene in "${scenes[@]}"; do
  IFS='|' read -r name spec args ref <<< "$scene"
  [ -n "$only" ] && [[ ",$only," != *",$name,"* ]] && continue
  vdb=$(volume "$spec" "$name")
  [ -n "$vdb" ] || { echo "run.sh: $name: no volume (needs blender): skipped" >&2; continue; }
  read -r paths spp <<< "$ref"
  [ "$quick" = 1 ] && { paths=512; spp=64; }
  $LPMBAKE "$vdb" $args -q -o "$out/$name.framing.vdb"
  t0=$SECONDS
  # shellcheck disable=SC2086
  $STUDY reference "$vdb" --bake "$out/$name.framing.vdb" $args --voxels 64 --samples "$paths" --spp "$spp" \
    -o "$out/$name.ref.json"
  echo "run.sh: $name: reference $((SECONDS - t0)) s" >&2
  for s in "${settings[@]}"; do
    IFS='|' read -r label knob flags <<< "$s"
    bake="$out/$name.bake.vdb"; stats="$out/$name.stats.json"
    # shellcheck disable=SC2086
    if ! $LPMBAKE "$vdb" $args $flags --verify 64 --stats "$stats" -q -o "$bake"; then
      echo "run.sh: $name $label: bake failed" >&2; continue
    fi
    images=(); [ "$label" = default ] && images=("$out/$name.default.png")
    cmp=$($STUDY compare "$out/$name.ref.json" "$bake" "${images[@]}")
    /usr/bin/python3 - "$name" "$label" "$knob" "$stats" "$cmp" >> "$results" <<'PY'
import json, sys
name, label, knob, stats, cmp = sys.argv[1:]
s = json.load(open(stats)); c = json.loads(cmp)
row = {"scene": name, "setting": label, "knob": knob, "seconds": s["timings_s"]["total"],
       "solve_s": s["timings_s"]["solve"], "peak_rss_mib": s["peak_rss_mib"],
       "voxels": s["voxels"]["active"], "passes": s["passes"], "verify": s["verify"]}
row.update(c)
print(json.dumps(row))
PY
    echo "run.sh: $name $label: $(tail -1 "$results" | cut -c1-160)" >&2
  done
  [ "$quick" = 1 ] && continue
  # The default bake's 64-probe estimate against 1024 probes of other voxels and paths.
  # shellcheck disable=SC2086
  $LPMBAKE "$vdb" $args --verify 1024 --verify-seed 2 --stats "$out/$name.verify.json" -q -o "$out/$name.bake.vdb"
  /usr/bin/python3 - "$name" "$out/$name.verify.json" "$results" >> "$agreement" <<'PY'
import json, sys
name, stats, results = sys.argv[1:]
big = json.load(open(stats))["verify"]
small = [json.loads(l) for l in open(results) if json.loads(l)["scene"] == name and json.loads(l)["setting"] == "default"][0]
print(json.dumps({"scene": name, "probes64": small["verify"], "probes1024": big}))
PY
done
/usr/bin/python3 scripts/accuracy/plot.py "$results" "$docs"
# The default bake's side by side (reference | lpmbake render | difference x 4) per scene.
for f in "$out"/*.default.png; do [ -e "$f" ] && cp "$f" "$docs"/accuracy/"$(basename "$f" .default.png)"_images.png; done

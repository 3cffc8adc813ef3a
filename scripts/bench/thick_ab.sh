#!/usr/bin/env bash
# Two lpmbake binaries side by side on the thick 1M-voxel scenes (the linear source and the
# shaped two-grid tail; docs/performance.md, sessions 45-47): the Mantaflow smoke at
# density scale 150 (albedo 0.9 and 0.99), plume-1M at density scale 4 and the 1M cumulus
# at g = 0, albedo 0.99, density scale 0.6 (coarse voxels up to depth 1.2), baked by each
# binary in turn, repeated, so the ratios come from one run. --anisotropic bakes instead
# the separable-source scenes (g = 0.6): the smoke at density scale 150, albedo 0.9, and the
# cumulus at albedo 0.99. Prints per bake the total,
# solve and stage times (s) and peak RSS (MiB), and per scene whether the two binaries'
# grids are bit-identical (`lpmbake info --digest`).
#   scripts/bench/thick_ab.sh OLD-LPMBAKE [--reps N] [--threads N] [--anisotropic]
# The volumes come from scripts/bench/scale.sh (--mantaflow for the smoke).
set -euo pipefail
cd "$(dirname "$0")/../.."
[ $# -ge 1 ] || { echo "usage: thick_ab.sh OLD-LPMBAKE [--reps N] [--threads N] [--anisotropic]" >&2; exit 2; }
old="$1"; shift
reps=2; threads=2; anisotropic=0
while [ $# -gt 0 ]; do
  case "$1" in
    --reps) reps="$2"; shift ;;
    --threads) threads="$2"; shift ;;
    --anisotropic) anisotropic=1 ;;
    *) echo "usage: thick_ab.sh OLD-LPMBAKE [--reps N] [--threads N] [--anisotropic]" >&2; exit 2 ;;
  esac
  shift
done
new=build/baker/lpmbake
dir=out/bench/thick_ab; mkdir -p "$dir"
smoke=out/bench/scale/smoke-1M-mantaflow.vdb; plume=out/bench/scale/plume-1M.vdb
cumulus=out/bench/scale/cumulus-1M-g0.6-a0.99.vdb
for f in "$smoke" "$plume" "$cumulus"; do
  [ -f "$f" ] || { echo "thick_ab.sh: $f is missing: run scripts/bench/scale.sh --quick --mantaflow first" >&2; exit 1; }
done
scenes=("smoke-a0.9|$smoke|--albedo 0.9 --density-scale 150 --up-axis z"
        "smoke-a0.99|$smoke|--albedo 0.99 --density-scale 150 --up-axis z"
        "plume-ds4|$plume|--albedo 0.9 --density-scale 4"
        "cumulus-a0.99|$cumulus|--albedo 0.99 --density-scale 0.6")
[ "$anisotropic" = 1 ] &&
  scenes=("smoke-g0.6|$smoke|--albedo 0.9 --g 0.6 --density-scale 150 --up-axis z"
          "cumulus-g0.6-a0.99|$cumulus|--albedo 0.99 --g 0.6 --density-scale 0.6")
for rep in $(seq "$reps"); do
  for scene in "${scenes[@]}"; do
    IFS='|' read -r name vdb args <<<"$scene"
    for which in old new; do
      bin=$new; [ "$which" = old ] && bin=$old
      # shellcheck disable=SC2086
      "$bin" "$vdb" --env data/env/rooftop_small.hdr $args --threads "$threads" \
        --stats "$dir/$name.$which.json" -o "$dir/$name.$which.vdb" 2>/dev/null
      python3 - "$dir/$name.$which.json" "$name" "$which" "$rep" <<'PY'
import json, sys
d = json.load(open(sys.argv[1]))
t, s = d["timings_s"], d["stages_s"]
stages = " ".join(f"{k}={v:.2f}" for k, v in s.items() if "segments" not in k and v > 0)
print(f"{sys.argv[2]} {sys.argv[3]} rep {sys.argv[4]}: total {t['total']:.2f} solve {t['solve']:.2f} {stages} "
      f"peak {d['peak_rss_mib']:.0f}")
PY
    done
    if [ "$rep" = 1 ]; then
      a=$("$new" info --digest "$dir/$name.old.vdb" | tail -1); b=$("$new" info --digest "$dir/$name.new.vdb" | tail -1)
      echo "$name grids: $([ "$a" = "$b" ] && echo "bit-identical ($a)" || echo "differ ($a, $b)")"
    fi
  done
done

#!/usr/bin/env bash
# Time and memory against the active voxels (docs/performance.md): default bakes of
# procedural volumes generated here (no large files in the repo; three at g = 0.6, SH order 2,
# two of them a cumulus at albedo 0.99, where GMRES or the diffusion tail runs), each a separate process
# so peak RSS is its own.
#   scripts/bench/scale.sh [--quick] [--large] [--mantaflow] [--threads N] [--original PATH-TO-AN-OLDER-lpmbake]
# --large adds the 8M cloud (g = 0 and g = 0.6) and the 50M-active-voxel cloud in a
# 1024^3 box (about 12 minutes and 9 GB here). --mantaflow adds the ~1M-active-voxel Mantaflow smoke (Blender,
# headless, resolution 224, frame 60: about 12 minutes to simulate once, then kept), baked
# at density scales 25 and 150 (the second thick enough for the linear source), the thick one also at g = 0.6.
# --only NAME runs that scene alone (a scene that bakes another's volume needs that one's file).
# Prints a markdown table; volumes and bakes go to out/bench/scale/.
set -euo pipefail
cd "$(dirname "$0")/../.."
quick=0; large=0; mantaflow=0; threads=0; original=""; only=""
while [ $# -gt 0 ]; do
  case "$1" in
    --quick) quick=1 ;;
    --large) large=1 ;;
    --mantaflow) mantaflow=1 ;;
    --only) only="$2"; shift ;;
    --threads) threads="$2"; shift ;;
    --original) original="$2"; shift ;;
    *) echo "usage: scale.sh [--quick] [--large] [--mantaflow] [--only NAME] [--threads N] [--original LPMBAKE]" >&2; exit 2 ;;
  esac
  shift
done
[ -x build/baker/lpmbake ] || bash scripts/build.sh >/dev/null
dir=out/bench/scale; mkdir -p "$dir"
make_volume=build/scripts/bench/lpm_make_volume
env=data/env/rooftop_small.hdr

# name | generator arguments | bake arguments
scenes=(
  "plume-1M|plume --res 124|--albedo 0.9 --density-scale 0.25"
  "plume-1M-g0.6|plume --res 124|--albedo 0.9 --density-scale 0.25 --g 0.6"
  "cumulus-1M-g0.6-a0.99|cloud --res 160|--albedo 0.99 --density-scale 0.6 --g 0.6"
  # The same cloud at twice the density (116 optical depths across under delta-M): the
  # diffusion tail on separable sources (docs/multires.md, "On separable sources").
  "cumulus-1M-g0.6-a0.99-dense|same cumulus-1M-g0.6-a0.99|--albedo 0.99 --density-scale 1.2 --g 0.6"
  # The same cloud at g = 0 and 6.7x the density (voxels up to optical depth 4): the
  # planner takes the diffusion tail (docs/multires.md, "Diffusion tail").
  "cumulus-1M-a0.99-thick|same cumulus-1M-g0.6-a0.99|--albedo 0.99 --density-scale 4"
  "puff-1|puffs --res 512 --count 1|--albedo 0.9"
  "puffs-2-in-512^3|puffs --res 512 --count 2|--albedo 0.9"
)
if [ "$quick" = 0 ]; then
  scenes+=("cloud-4M|cloud --res 256|--albedo 0.9 --density-scale 0.05")
fi
if [ "$mantaflow" = 1 ]; then
  scenes+=("smoke-1M-mantaflow|mantaflow --res 224 --end 60|--albedo 0.9 --density-scale 25 --up-axis z")
  # The same smoke thick enough for the linear source (voxels up to optical depth 2.66).
  scenes+=("smoke-1M-mantaflow-thick|same smoke-1M-mantaflow|--albedo 0.9 --density-scale 150 --up-axis z")
  # And at albedo 0.99: the diffusion tail.
  scenes+=("smoke-1M-mantaflow-thick-a0.99|same smoke-1M-mantaflow|--albedo 0.99 --density-scale 150 --up-axis z")
  # And at g = 0.6: 24 unshot bins, where the auto plan keeps the constant source over the
  # memory line (docs/performance.md, "Session 44").
  scenes+=("smoke-1M-mantaflow-thick-g0.6|same smoke-1M-mantaflow|--albedo 0.9 --density-scale 150 --up-axis z --g 0.6")
fi
if [ "$large" = 1 ]; then
  scenes+=("cloud-8M|cloud --res 322|--albedo 0.9 --density-scale 0.04")
  # The same cloud at g = 0.6 (SH order 2): memory per active voxel of an anisotropic bake
  # at 8x plume-1M's size.
  scenes+=("cloud-8M-g0.6|cloud --res 322|--albedo 0.9 --density-scale 0.04 --g 0.6")
  scenes+=("cloud-50M-in-1024^3|cloud --res 585 --box 1024|--albedo 0.9 --density-scale 0.022")
fi

echo "| scene | active voxels | box voxels | bake | threads | passes (coarse) | solve s | total s | peak RSS MiB | bytes/active voxel above 200 MB |"
echo "|---|---|---|---|---|---|---|---|---|---|"
for line in "${scenes[@]}"; do
  IFS='|' read -r name gen bake <<<"$line"
  [ -n "$only" ] && [ "$name" != "$only" ] && continue
  vdb="$dir/$name.vdb"
  kind=${gen%% *}; opts=${gen#* }
  [ "$kind" = same ] && vdb="$dir/$opts.vdb"  # another scene's volume, baked with other settings
  if [ ! -f "$vdb" ] && [ "$kind" = mantaflow ]; then
    # shellcheck disable=SC2086
    bash scripts/volumes/make_blender_smoke.sh "$dir/$name.frames" $opts >&2
    last=$(ls "$dir/$name.frames"/smoke.*.vdb | sort | tail -1)
    mv "$last" "$vdb" && rm -rf "$dir/$name.frames"
  fi
  # shellcheck disable=SC2086
  [ -f "$vdb" ] || $make_volume "$kind" "$vdb" $opts >/dev/null
  for bin in build/baker/lpmbake $original; do
    label=$([ "$bin" = build/baker/lpmbake ] && echo "this" || echo "original")
    stats="$dir/$name.$label.json"
    # shellcheck disable=SC2086
    "$bin" "$vdb" --env "$env" $bake --threads "$threads" --stats "$stats" -o "$dir/$name.$label.out.vdb" 2>/dev/null
    python3 - "$stats" "$name" "$label" <<'EOF'
import json, sys
d = json.load(open(sys.argv[1]))
p = d["pass_stats"]
coarse = sum(1 for x in p if x.get("coarse"))
act = d["voxels"]["active"]
rss = d["peak_rss_mib"]
per = max(0.0, (rss - 200) * 2**20 / act)
print(f"| {sys.argv[2]} | {act} | {d['voxels']['bounding_box']} | {sys.argv[3]} | {d['threads']} | {len(p)} ({coarse}) | "
      f"{d['timings_s']['solve']:.2f} | {d['timings_s']['total']:.2f} | {rss:.0f} | {per:.0f} |")
EOF
  done
done

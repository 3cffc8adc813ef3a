#!/usr/bin/env bash
# One run, same volume: the old solver against this one per pass (2 passes, full
# resolution), and the default bake at 1 and 2 threads (docs/performance.md).
#   scripts/bench/threads_and_old.sh OLD_LPMBAKE VOLUME.vdb [bake args...]
set -euo pipefail
old=$1; vdb=$2; shift 2
new=build/baker/lpmbake
env=data/env/rooftop_small.hdr
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
row() {  # label binary args...
  local label=$1 bin=$2; shift 2
  "$bin" "$vdb" --env "$env" "$@" --stats "$out/s.json" -o "$out/o.vdb" 2>/dev/null
  python3 - "$out/s.json" "$label" <<'PY'
import json, sys
d = json.load(open(sys.argv[1])); p = d["pass_stats"]
per = [x["seconds"] for x in p if not x.get("coarse")]
print(f"| {sys.argv[2]} | {d['threads']} | {len(p)} | {d['timings_s']['solve']:.2f} | "
      f"{', '.join(f'{s:.2f}' for s in per[:3])} | {d['ray_segments_per_second']:.3g} | {d['peak_rss_mib']:.0f} |")
PY
}
echo "| run | threads | passes | solve s | first full-resolution passes s | segments/s | peak RSS MiB |"
echo "|---|---|---|---|---|---|---|"
row "old solver, 2 passes" "$old" "$@" --max-orders 2 --threads 2
row "this, full resolution, 2 passes" "$new" "$@" --multires off --max-orders 2 --threads 2
row "this, default bake" "$new" "$@" --threads 1
row "this, default bake" "$new" "$@" --threads 2

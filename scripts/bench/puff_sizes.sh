#!/usr/bin/env bash
# Issue 9's target 4 against the size of the puffs: one puff alone (its own tight box)
# against two such puffs at opposite corners of a 512^3 box, for several puff radii, the
# bakes interleaved (one puff, the other puff, two puffs, repeated) so each ratio is
# measured in one run. The ratio of the totals falls toward 1 as the puffs shrink (the
# bake's fixed part, which the box does not change, dominates) and rises toward the ratio
# of the active voxels as they grow (time follows the active voxels); the box itself should
# cost nothing. What the box costs is the pair against its two puffs baked apart, each in
# its own tight box (the near one is "one puff"; the far one is the pair's other puff, whose
# noise differs): two / (near + far), the same voxels with the empty box between them.
#   scripts/bench/puff_sizes.sh [--reps N] [--threads N] [--radii "8 16 32 64"]
# Prints a markdown table: per radius, the active voxels, passes, and the minimum and
# median over the repetitions of the solve, the bake's total and the whole process (start
# to exit), for the near puff, the far puff and the pair, with the ratios of the minima.
# The sky is read once before the runs so every timed bake takes it from the decoded-image
# cache (docs/image_cache.md).
set -euo pipefail
cd "$(dirname "$0")/../.."
reps=3; threads=0; radii="8 16 32 64"
while [ $# -gt 0 ]; do
  case "$1" in
    --reps) reps="$2"; shift ;;
    --threads) threads="$2"; shift ;;
    --radii) radii="$2"; shift ;;
    *) echo "usage: puff_sizes.sh [--reps N] [--threads N] [--radii \"R1 R2 ...\"]" >&2; exit 2 ;;
  esac
  shift
done
[ -x build/baker/lpmbake ] || bash scripts/build.sh >/dev/null
dir=out/bench/puffs; mkdir -p "$dir"
env=data/env/rooftop_small.hdr
bake_args=(--env "$env" --albedo 0.9 --threads "$threads")
results="$dir/results.txt"; : >"$results"

for r in $radii; do
  for count in 1 1f 2; do
    vdb="$dir/puffs-$count-r$r.vdb"
    corner=near; [ "$count" = 1f ] && corner=far
    [ -f "$vdb" ] || build/scripts/bench/lpm_make_volume puffs "$vdb" --res 512 --count "${count%f}" --radius "$r" \
      --corner "$corner" >/dev/null
  done
  build/baker/lpmbake "$dir/puffs-1-r$r.vdb" "${bake_args[@]}" -o "$dir/warm.vdb" 2>/dev/null
  for rep in $(seq "$reps"); do
    for count in 1 1f 2; do
      stats="$dir/puffs-$count-r$r.$rep.json"
      start=$(date +%s.%N)
      build/baker/lpmbake "$dir/puffs-$count-r$r.vdb" "${bake_args[@]}" --stats "$stats" \
        -o "$dir/puffs-$count-r$r.out.vdb" 2>/dev/null
      end=$(date +%s.%N)
      echo "$r $count $stats $start $end" >>"$results"
    done
  done
done
rm -f "$dir/warm.vdb"

python3 - "$results" <<'EOF'
import json, statistics, sys
rows = {}
for line in open(sys.argv[1]):
    r, count, stats, start, end = line.split()
    d = json.load(open(stats))
    t = d["timings_s"]
    rows.setdefault((int(r), count), []).append(
        dict(solve=t["solve"], total=t["total"], process=float(end) - float(start),
             active=d["voxels"]["active"], box=d["voxels"]["bounding_box"], passes=len(d["pass_stats"]),
             peak=d["peak_rss_mib"], source=d.get("environment_source", "?")))
print("| radius | puffs | active voxels | box voxels | passes | solve s (min / median) | total s | process s | peak RSS MiB |")
print("|---|---|---|---|---|---|---|---|---|")
def mm(v):
    return f"{min(v):.3f} / {statistics.median(v):.3f}"
ratios = []
for r in sorted({k[0] for k in rows}):
    for count in ("1", "1f", "2"):
        x = rows[(r, count)]
        label = {"1": "one (near)", "1f": "one (far)", "2": "two"}[count]
        print(f"| {r} | {label} | {x[0]['active']} | {x[0]['box']} | {x[0]['passes']} | "
              f"{mm([y['solve'] for y in x])} | {mm([y['total'] for y in x])} | {mm([y['process'] for y in x])} | "
              f"{max(y['peak'] for y in x):.0f} |")
    one, far, two = rows[(r, "1")], rows[(r, "1f")], rows[(r, "2")]
    low = lambda x, key: min(y[key] for y in x)
    q = lambda key: low(two, key) / low(one, key)
    apart = lambda key: low(two, key) / (low(one, key) + low(far, key))
    ratios.append((r, two[0]["active"] / one[0]["active"], q("solve"), q("total"), q("process"),
                   two[0]["active"] / (one[0]["active"] + far[0]["active"]), apart("solve"), apart("total")))
print()
print("| radius | active voxels, two / one | solve, two / one | total | process "
      "| active voxels, two / (near + far) | solve, two / (near + far) | total |")
print("|---|---|---|---|---|---|---|---|")
for r, v, s, t, p, va, sa, ta in ratios:
    print(f"| {r} | {v:.2f}x | {s:.2f}x | {t:.2f}x | {p:.2f}x | {va:.2f}x | {sa:.2f}x | {ta:.2f}x |")
sources = {y["source"] for x in rows.values() for y in x}
print(f"\nsky read from: {', '.join(sorted(sources))}")
EOF

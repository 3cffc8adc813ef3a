#!/usr/bin/env bash
# Issue 9's targets 2 and 3 by stage: interleaved 1- and 2-thread bakes of one volume, each
# split into pass 0 (single scattering), the fine passes after it, the coarse-grid passes,
# the rest of the solve, the read and the write, with each stage's 1 -> 2 thread speed-up
# and, at 2 threads, its ray-segment updates per second. One table per pair (the machine is
# shared: a pair's two bakes run back to back, so their ratio is the least disturbed).
#   scripts/bench/stage_split.sh [--pairs N] VOLUME.vdb [bake args...]
set -euo pipefail
cd "$(dirname "$0")/../.."
pairs=2
if [ "${1:-}" = --pairs ]; then pairs=$2; shift 2; fi
vdb=${1:?usage: stage_split.sh [--pairs N] VOLUME.vdb [bake args...]}; shift
[ -x build/baker/lpmbake ] || bash scripts/build.sh >/dev/null
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
for ((i = 1; i <= pairs; ++i)); do
  for t in 1 2; do
    build/baker/lpmbake "$vdb" "$@" --threads "$t" --stats "$out/$t.json" -o "$out/$t.vdb" 2>/dev/null
  done
  python3 - "$out" "$i" <<'PY'
import json, os, sys
out, pair = sys.argv[1], sys.argv[2]

def stages(d):
    ps, ts = d["pass_stats"], d["timings_s"]
    fine = [p for p in ps[1:] if not p.get("coarse")]
    coarse = [p for p in ps if p.get("coarse")]
    s = {
        "pass 0": (ps[0]["seconds"], ps[0]["segments"]),
        "fine passes 1..": (sum(p["seconds"] for p in fine), sum(p["segments"] for p in fine)),
        "coarse passes": (sum(p["seconds"] for p in coarse), sum(p["segments"] for p in coarse)),
    }
    s["rest of the solve"] = (ts["solve"] - sum(v[0] for v in s.values()), 0)
    s["solve"] = (ts["solve"], d["ray_segments"])
    s["read"] = (ts["read"], 0)
    s["write"] = (ts["write"], 0)
    s["total"] = (ts["total"], 0)
    return s

one = stages(json.load(open(os.path.join(out, "1.json"))))
two = stages(json.load(open(os.path.join(out, "2.json"))))
print(f"\npair {pair}\n")
print("| stage | 1 thread s | 2 threads s | speed-up | segments/s at 2 threads |")
print("|---|---|---|---|---|")
for k in one:
    a, b = one[k][0], two[k][0]
    rate = f"{two[k][1] / b:.3g}" if two[k][1] and b > 0 else "-"
    print(f"| {k} | {a:.3f} | {b:.3f} | {a / b if b > 0 else float('nan'):.2f}x | {rate} |")
PY
done

#!/usr/bin/env bash
# Issue 9's target 3: the 1 -> 2 thread speed-up of one bake, measured in one run with
# the 1- and 2-thread bakes interleaved (this machine is shared: the minimum over the
# repetitions is the least disturbed run; the median is given beside it). Checks that
# every bake has the same content digest.
#   scripts/bench/thread_scaling.sh [--reps N] [--lpmbake BIN] VOLUME.vdb [bake args...]
# (--lpmbake: another build's binary, e.g. an earlier commit's, to compare; its digests
# are taken with that binary too)
# Prints a markdown table of each run and the speed-ups of solve, total (the bake's own
# timer, from the stats JSON) and process (the whole lpmbake process, start-up included:
# since session 30 the environment image's decoder loads in a helper process during the
# bake, where before it loaded before main, outside `total`). The environment column says
# where the sky came from: `decoded` by the helper or the decoded-image cache (session 32,
# docs/image_cache.md: every run after the first reads it unless LPMBAKE_IMAGE_CACHE=off).
# Before each repetition, lpm_bench_host_scaling (when built) measures the host's own
# 1 -> 2 thread speed-up on kernels with no serial part: the ceiling of that moment.
set -euo pipefail
cd "$(dirname "$0")/../.."
reps=5
bin=build/baker/lpmbake
while [ "${1:-}" = --reps ] || [ "${1:-}" = --lpmbake ]; do
  if [ "$1" = --reps ]; then reps=$2; else bin=$2; fi
  shift 2
done
vdb=${1:?usage: thread_scaling.sh [--reps N] VOLUME.vdb [bake args...]}; shift
[ "$bin" != build/baker/lpmbake ] || [ -x "$bin" ] || bash scripts/build.sh >/dev/null
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
host=build/scripts/bench/lpm_bench_host_scaling
for ((i = 1; i <= reps; ++i)); do
  # The host's own ceiling, in the same run (scripts/bench/host_scaling.cpp).
  if [ -x "$host" ]; then "$host" 1 | tail -3 | sed "s/^| /| $i | /" >> "$out/host"; fi
  for t in 1 2; do
    t0=$(date +%s%N)
    "$bin" "$vdb" "$@" --threads "$t" --stats "$out/$t.$i.json" -o "$out/$t.$i.vdb" 2>/dev/null
    t1=$(date +%s%N)
    echo $((t1 - t0)) > "$out/$t.$i.process"  # ns
    "$bin" info --digest "$out/$t.$i.vdb" > "$out/$t.$i.digest"
    rm -f "$out/$t.$i.vdb"
  done
done
status=0
python3 - "$out" "$reps" <<'PY' || status=$?
import glob, json, os, statistics, sys
out, reps = sys.argv[1], int(sys.argv[2])
runs = {1: [], 2: []}
digests = set()
print("| run | threads | solve s | total s | process s | environment s (from) | write s | peak RSS MiB | digest |")
print("|---|---|---|---|---|---|---|---|---|")
for i in range(1, reps + 1):
    for t in (1, 2):
        d = json.load(open(os.path.join(out, f"{t}.{i}.json")))
        dig = open(os.path.join(out, f"{t}.{i}.digest")).read().strip()
        digests.add(dig)
        ts = d["timings_s"]
        process = int(open(os.path.join(out, f"{t}.{i}.process")).read()) / 1e9
        runs[t].append((ts["solve"], ts["total"], process))
        print(f"| {i} | {t} | {ts['solve']:.2f} | {ts['total']:.2f} | {process:.2f} | "
              f"{ts['environment']:.2f} ({d.get('environment_source', '?')}) | {ts['write']:.2f} | "
              f"{d['peak_rss_mib']:.0f} | {dig} |")
for k, name in ((0, "solve"), (1, "total"), (2, "process")):
    a = [r[k] for r in runs[1]]
    b = [r[k] for r in runs[2]]
    print(f"\n{name}: 1 thread min {min(a):.2f} s, median {statistics.median(a):.2f} s; "
          f"2 threads min {min(b):.2f} s, median {statistics.median(b):.2f} s; "
          f"speed-up of the minima {min(a) / min(b):.2f}x, of the medians {statistics.median(a) / statistics.median(b):.2f}x")
print(f"\ncontent digests: {'all equal' if len(digests) == 1 else 'DIFFER: ' + ', '.join(sorted(digests))}")
sys.exit(0 if len(digests) == 1 else 1)
PY
if [ -s "$out/host" ]; then
  echo
  echo "The host's ceiling (lpm_bench_host_scaling 1 before each repetition; perfect is 2.00x):"
  echo "| rep | kernel | 1 thread s | 2 threads s | speed-up | (same) |"
  echo "|---|---|---|---|---|---|"
  cat "$out/host"
fi
exit $status

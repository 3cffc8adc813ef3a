#!/usr/bin/env bash
# Issue 9's target 3 by cause: how long a 2-thread bake keeps one thread waiting. Samples
# the bake with perf (cpu-clock, frame-pointer call chains) and counts the main thread's
# samples in the 5 ms slices where the worker took none: the serial time, split into page
# faults and zeroing (first touches), the solver (lpm:: frames), OpenVDB and the rest.
# Needs perf (Debian: linux-perf) and a kernel that lets this user sample itself.
#   scripts/bench/serial_time.sh [--runs N] [--hz F] [--bin LPMBAKE] VOLUME.vdb [bake args...]
set -euo pipefail
cd "$(dirname "$0")/../.."
runs=3; hz=1000; bin=build/baker/lpmbake
while [ $# -gt 0 ]; do
  case "$1" in
    --runs) runs=$2; shift 2 ;;
    --hz) hz=$2; shift 2 ;;
    --bin) bin=$2; shift 2 ;;
    *) break ;;
  esac
done
vdb=${1:?usage: serial_time.sh [--runs N] [--hz F] [--bin LPMBAKE] VOLUME.vdb [bake args...]}; shift
command -v perf >/dev/null || { echo "serial_time.sh: perf not found (apt-get install linux-perf)" >&2; exit 2; }
[ -x "$bin" ] || bash scripts/build.sh >/dev/null
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
for ((i = 1; i <= runs; ++i)); do
  perf record -q -F "$hz" -g -o "$out/$i.data" "$bin" "$vdb" "$@" --threads 2 --stats "$out/$i.json" \
    -o "$out/$i.vdb" >/dev/null 2>&1
  perf script -i "$out/$i.data" -F tid,time,ip,sym 2>/dev/null >"$out/$i.txt"
done
python3 - "$out" "$runs" "$hz" <<'PY'
import collections, json, os, re, sys
out, runs, hz = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
SLICE = 0.005

def samples(path):
    got, cur = [], None
    for line in open(path):
        head = re.match(r"^\s*(\d+)\s+([\d.]+):", line)
        if head:
            if cur:
                got.append(cur)
            cur = (int(head.group(1)), float(head.group(2)), [])
        elif line.strip() and cur:
            parts = line.strip().split(None, 1)
            cur[2].append(parts[-1])
    if cur:
        got.append(cur)
    return got

def cause(stack):
    text = " ".join(stack)
    if "clear_page" in text or "exc_page_fault" in text or (stack and "memset" in stack[0]):
        return "page faults and zeroing"
    if "lpm::" in text:
        return "solver and I/O code (lpm::)"
    if "openvdb" in text:
        return "OpenVDB"
    return "other (kernel, libc, unresolved)"

print("| run | bake total s | serial s | " + " | ".join(["page faults and zeroing", "solver and I/O code (lpm::)",
      "OpenVDB", "other (kernel, libc, unresolved)"]) + " |")
print("|---|---|---|---|---|---|---|")
for i in range(1, runs + 1):
    s = samples(os.path.join(out, f"{i}.txt"))
    if not s:
        sys.exit("serial_time.sh: perf recorded no samples")
    t0, main = min(x[1] for x in s), s[0][0]
    # The bake starts at the first sample in our code (before it: the dynamic loader).
    start = min(t - t0 for _, t, st in s if any("lpm::" in f for f in st))
    busy = collections.defaultdict(lambda: [0, 0])
    for tid, t, _ in s:
        busy[int((t - t0) / SLICE)][tid != main] += 1
    split = collections.Counter()
    for tid, t, st in s:
        if tid == main and t - t0 >= start and busy[int((t - t0) / SLICE)][1] == 0:
            split[cause(st)] += 1
    total = json.load(open(os.path.join(out, f"{i}.json")))["timings_s"]["total"]
    keys = ["page faults and zeroing", "solver and I/O code (lpm::)", "OpenVDB", "other (kernel, libc, unresolved)"]
    print(f"| {i} | {total:.2f} | {sum(split.values()) / hz:.3f} | " +
          " | ".join(f"{split[k] / hz:.3f}" for k in keys) + " |")
print()
print("Serial: the main thread's samples while the worker took none in the same 5 ms slice (off-CPU waits,"
      " such as fsync, are not counted). perf adds its own overhead: compare runs of one script.")
PY

#!/usr/bin/env bash
# Checks scripts/farm/lpm_slurm_submit.sh without Slurm (--dry-run): frame specs, task ids,
# chunks, --max-parallel, the generated job script, argument checks, and --only-pending
# against the real lpmbake --list-pending.
#
#   tests/farm/submit_dry_test.sh LPMBAKE DATA_DIR SCRATCH_DIR
#
# Runs in about a second; needs neither Slurm nor root.
set -euo pipefail
NAME=submit_dry_test
[ $# -eq 3 ] || { echo "usage: $0 LPMBAKE DATA_DIR SCRATCH_DIR" >&2; exit 1; }
abspath() { case $1 in /*) echo "$1" ;; *) echo "$PWD/$1" ;; esac; }
LPMBAKE=$(abspath "$1"); DATA=$(abspath "$2"); SCRATCH=$(abspath "$3")
SUBMIT=$(cd "$(dirname "${BASH_SOURCE[0]}")/../../scripts/farm" && pwd)/lpm_slurm_submit.sh
W=$SCRATCH/submit_dry_test
rm -rf "$W"; mkdir -p "$W/out"
cd "$W"
fail() { echo "$NAME: FAIL: $*" >&2; exit 1; }
n=0

# dry FRAMES_OPTS... -- : run a dry run into a fresh log dir; sets tasks ("id frames;...")
# and array (the --array value) from the files it wrote.
dry() {
  local ld="$W/logs_$n" out
  n=$((n + 1))
  out=$("$SUBMIT" --dry-run --max-array-size 1001 --log-dir "$ld" --lpmbake "$LPMBAKE" "$@" 2>&1) || fail "dry run $* failed: $out"
  tasks=$(grep -hv '^#' "$ld"/*.frames | tr '\n' ';')
  array=$(printf '%s\n' "$out" | sed -n 's/.*--array=\([^ ]*\).*/\1/p' | head -n 1 | tr -d '\\')
  script=$(ls "$ld"/*.sbatch)
}
BAKE=(in.####.vdb --env sky.hdr -o "$W/out/lit.####.vdb")

# One task per frame: task id = frame.
dry --frames 1-3 -- "${BAKE[@]}"
[ "$tasks" = "1 1;2 2;3 3;" ] || fail "1-3: tasks '$tasks'"
[ "$array" = "1-3" ] || fail "1-3: array '$array'"
dry --frames 1-9x2,20,22 --max-parallel 4 -- "${BAKE[@]}"
[ "$array" = "1-9:2,20,22%4" ] || fail "steps: array '$array'"
# Frames beyond MaxArraySize (1001 by default): tasks 0..N-1.
dry --frames 1001-1004 -- "${BAKE[@]}"
[ "$tasks" = "0 1001;1 1002;2 1003;3 1004;" ] || fail "1001-1004: tasks '$tasks'"
[ "$array" = "0-3" ] || fail "1001-1004: array '$array'"
# Chunks keep the order given and compress each chunk for lpmbake.
dry --frames 1-10,20-30x5 --chunk 4 -- "${BAKE[@]}"
[ "$tasks" = "0 1-4;1 5-8;2 9-10,20,25;3 30;" ] || fail "chunks: tasks '$tasks'"
[ "$array" = "0-3" ] || fail "chunks: array '$array'"
# The job script: lpmbake, the task's frames, --skip-existing (once), a frame log; CPUs.
dry --frames 5 --cpus 3 -- "${BAKE[@]}" --skip-existing --g 0.5
grep -q -- "--cpus-per-task=3" <<< "$(cat "$script")" || fail "--cpus 3 not in the resubmit line of $script"
line=$(grep '^exec ' "$script")
[ "$line" = "exec $(printf '%q' "$LPMBAKE") in.####.vdb --env sky.hdr -o $(printf '%q' "$W/out/lit.####.vdb") --g 0.5 --frames \"\$frames\" --skip-existing \\" ] ||
  fail "exec line: $line"
grep -q -- '--frame-log ' "$script" || fail "no --frame-log in $script"
grep -q 'SLURM_CPUS_PER_TASK=${SLURM_CPUS_PER_TASK:-${SLURM_CPUS_ON_NODE:-1}}' "$script" || fail "thread fallback missing"
# A user --frame-log is kept and ours not added.
dry --frames 5 -- "${BAKE[@]}" --frame-log mine.jsonl
[ "$(grep -v '^#' "$script" | grep -c -- '--frame-log')" = 1 ] || fail "user --frame-log: $(grep -- '--frame-log' "$script")"

# Refused: bad specs, frames after --, no lpmbake arguments.
for bad in "--frames 3-1" "--frames 1,,x" "--frames 1-5x0" "--chunk 0 --frames 1"; do
  # shellcheck disable=SC2086
  if "$SUBMIT" --dry-run --log-dir "$W/bad" --lpmbake "$LPMBAKE" $bad -- "${BAKE[@]}" 2>/dev/null; then fail "accepted $bad"; fi
done
if "$SUBMIT" --dry-run --log-dir "$W/bad" --lpmbake "$LPMBAKE" --frames 1 -- "${BAKE[@]}" --frames 2 2>/dev/null; then fail "accepted --frames after --"; fi
if "$SUBMIT" --dry-run --log-dir "$W/bad" --lpmbake "$LPMBAKE" --frames 1 2>/dev/null; then fail "accepted no lpmbake arguments"; fi
"$SUBMIT" --help | grep -q -- "--only-pending" || fail "--help"

# --only-pending with the real lpmbake: bake frame 1 (the empty one, instant), then frames
# 1-3 pending are 2 and 3.
REAL=("$DATA/vdb/smoke_seq.####.vdb" --env "$DATA/env/rooftop_small.hdr" -o "$W/out/lit.####.vdb")
"$LPMBAKE" "${REAL[@]}" --frame 1 -q || fail "baking frame 1 exited $?"
dry --frames 1-3 --only-pending -- "${REAL[@]}"
[ "$tasks" = "2 2;3 3;" ] || fail "--only-pending: tasks '$tasks'"
# Nothing pending: no files, nothing on stdout, exit 0.
out=$("$SUBMIT" --dry-run --log-dir "$W/none" --lpmbake "$LPMBAKE" --frames 1 --only-pending -- "${REAL[@]}" 2>/dev/null) ||
  fail "--only-pending with nothing pending failed"
[ -z "$out" ] && [ ! -e "$W/none" ] || fail "--only-pending with nothing pending printed '$out' or wrote $W/none"
echo "$NAME: PASS"

#!/usr/bin/env bash
# Integration test of the Slurm farm scripts with a real one-node Slurm cluster.
#
#   tests/farm/slurm_test.sh LPMBAKE DATA_DIR SCRATCH_DIR
#
#   LPMBAKE      the lpmbake binary (build/baker/lpmbake)
#   DATA_DIR     the repository's data/ (data/vdb/smoke_seq.000{1,2,3}.vdb, data/env/rooftop_small.hdr)
#   SCRATCH_DIR  a directory it may empty and fill (outputs, logs); the cluster itself lives in a
#                short directory under /tmp (unix socket paths are limited to 107 bytes)
#
# Exit 0 pass, 1 fail, 77 skipped (Slurm or munge not installed, or not root): CTest's
# SKIP_RETURN_CODE. Needs root (the test cluster runs SlurmUser=root) and about 30-60 s.
#
# Phases (each one timed; the times are printed at the end):
#   start     scripts/farm/slurm_local.sh start: munged, slurmctld, slurmd, node idle
#   local     reference bake of frames 1-3 on this machine with --threads 2
#   array     lpm_slurm_submit.sh --frames 1-3 --cpus 1 --wait: each output's
#             `lpmbake info --digest` equals the local bake's (so also 1 thread == 2 threads);
#             frame 1 is an empty density grid (an empty bake, exit 0)
#   cancel    outputs removed, submitted again; the task of frame 3 is frozen (SIGSTOP) once its
#             lpmbake has run a while, then scancelled (Slurm sends SIGCONT, SIGTERM): no file
#             at its output path, no temporary file left; frames 1 and 2 complete
#   resubmit  lpmbake --list-pending says "3"; lpm_slurm_submit.sh --only-pending --wait bakes
#             frame 3 only (frames 1, 2 untouched: same inode and mtime); a second
#             --only-pending submits nothing
#   skip      lpm_slurm_submit.sh --chunk 2 --wait over 1-3 (tasks 0: 1-2, 1: 3): every frame
#             reports "skipped", no file changes
#   stop      slurm_local.sh stop (also run by the EXIT trap, whatever happens)
set -euo pipefail

NAME=slurm_test
say() { echo "$NAME: $*"; }
skip() { echo "$NAME: SKIP: $*"; exit 77; }

[ $# -eq 3 ] || { echo "usage: $0 LPMBAKE DATA_DIR SCRATCH_DIR" >&2; exit 1; }
abspath() { case $1 in /*) echo "$1" ;; *) echo "$PWD/$1" ;; esac; }
LPMBAKE=$(abspath "$1"); DATA=$(abspath "$2"); SCRATCH=$(abspath "$3")
HERE=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
FARM=$(cd "$HERE/../../scripts/farm" && pwd)
LOCAL=$FARM/slurm_local.sh
SUBMIT=$FARM/lpm_slurm_submit.sh

for b in munged mungekey slurmctld slurmd sbatch squeue scancel sinfo; do
  command -v "$b" >/dev/null 2>&1 || skip "$b not installed (apt-get install --no-install-recommends slurm-wlm munge, or scripts/install_deps.sh)"
done
[ "$(id -u)" = 0 ] || skip "needs root (the test cluster runs SlurmUser=root)"
[ -x "$LPMBAKE" ] || { echo "$NAME: FAIL: no lpmbake at $LPMBAKE" >&2; exit 1; }
IN="$DATA/vdb/smoke_seq.####.vdb"
ENV="$DATA/env/rooftop_small.hdr"
for f in 1 2 3; do [ -r "$DATA/vdb/smoke_seq.000$f.vdb" ] || { echo "$NAME: FAIL: missing $DATA/vdb/smoke_seq.000$f.vdb" >&2; exit 1; }; done
[ -r "$ENV" ] || { echo "$NAME: FAIL: missing $ENV" >&2; exit 1; }

W=$SCRATCH/slurm_test
rm -rf "$W"
mkdir -p "$W/out" "$W/ref"
OUT="$W/out/lit.####.vdb"
out_of() { printf '%s/out/lit.%04d.vdb' "$W" "$1"; }
BAKE=("$IN" --env "$ENV" -o "$OUT")    # the bake arguments every phase uses

CLUSTER=$(mktemp -d /tmp/lpmslurm.XXXXXX)
failed=1
cleanup() {
  "$LOCAL" stop "$CLUSTER" >/dev/null 2>&1 || say "warning: slurm_local.sh stop reported leftovers"
  if [ $failed = 1 ]; then
    mkdir -p "$W/cluster_logs"
    cp -r "$CLUSTER/log" "$CLUSTER/etc" "$W/cluster_logs/" 2>/dev/null || true
    say "cluster logs kept in $W/cluster_logs; task logs in $W/logs_*"
  fi
  rm -rf "$CLUSTER"
}
trap cleanup EXIT

fail() {
  echo "$NAME: FAIL: $*" >&2
  for f in "$W"/logs_*/*.log; do [ -f "$f" ] && { echo "--- $f" >&2; tail -n 15 "$f" >&2; }; done
  exit 1
}

# Phase timing.
declare -A took=()
phases=()
t_begin=0
begin() { t_begin=$(date +%s%N); phases+=("$1"); say "== $1"; }
end() { took[$1]=$(( ($(date +%s%N) - t_begin) / 1000000 )); }
secs() { awk -v ms="$1" 'BEGIN { printf "%.1f s", ms / 1000 }'; }
t_all=$(date +%s%N)

digest() {  # FILE -> 16 hex digits, or fail
  local d
  d=$("$LPMBAKE" info --digest "$1") || fail "lpmbake info --digest $1 exited $?"
  [[ $d =~ ^[0-9a-f]{16}$ ]] || fail "lpmbake info --digest $1 printed '$d', not 16 hex digits"
  echo "$d"
}
statline() { stat -c '%i %y' "$1"; }   # inode and mtime (ns): "re-baked or not"

# frame_status LOGDIR JOBID FRAME -> the status of FRAME in that job's frame logs
frame_status() {
  cat "$1"/lpmbake_"$2"_*.frames.jsonl 2>/dev/null |
    sed -n "s/.*\"frame\" *: *$3 *[,}].*\"status\" *: *\"\([a-z]*\)\".*/\1/p; s/.*\"status\" *: *\"\([a-z]*\)\".*\"frame\" *: *$3 *[,}].*/\1/p" |
    tr '\n' ' ' | sed 's/ $//'
}

# ---------------------------------------------------------------------------------------
begin start
"$LOCAL" start "$CLUSTER" || fail "slurm_local.sh start"
# shellcheck disable=SC1091
. "$CLUSTER/env"
cpus=$(sed -n 's/^NodeName=.* CPUs=\([0-9]*\).*/\1/p' "$CLUSTER/etc/slurm.conf")
end start

# ---------------------------------------------------------------------------------------
begin local
"$LPMBAKE" "$IN" --env "$ENV" -o "$W/ref/ref.####.vdb" --frames 1-3 --threads 2 -q ||
  fail "local reference bake exited $?"
declare -A ref=()
for f in 1 2 3; do ref[$f]=$(digest "$(printf '%s/ref/ref.%04d.vdb' "$W" "$f")"); done
say "reference digests: 1=${ref[1]} 2=${ref[2]} 3=${ref[3]}"
end local

# ---------------------------------------------------------------------------------------
begin array
L=$W/logs_array
set +e
j1=$("$SUBMIT" --frames 1-3 --cpus 1 --wait --log-dir "$L" --lpmbake "$LPMBAKE" -- "${BAKE[@]}")
rc=$?
set -e
[ $rc = 0 ] || fail "array job ${j1:-?} exited $rc"
[[ $j1 =~ ^[0-9]+$ ]] || fail "lpm_slurm_submit.sh printed '$j1', not a job id"
for f in 1 2 3; do
  [ -f "$(out_of $f)" ] || fail "frame $f: no output $(out_of $f)"
  d=$(digest "$(out_of $f)")
  [ "$d" = "${ref[$f]}" ] || fail "frame $f: farm digest $d != local digest ${ref[$f]} (threads 1 vs 2)"
  [ "$(frame_status "$L" "$j1" $f)" = baked ] || fail "frame $f: frame log says '$(frame_status "$L" "$j1" $f)', not baked"
  grep -q "frames $f, 1 CPUs" "$L/lpmbake_${j1}_$f.log" || fail "task $f: log does not say it ran with 1 CPU"
done
say "array job $j1: 3 frames baked on the farm, digests equal to the local bake"
end array

# ---------------------------------------------------------------------------------------
begin cancel
victim=3
rm -f "$W"/out/lit.*.vdb
L=$W/logs_cancel
j2=$("$SUBMIT" --frames 1-3 --cpus 1 --log-dir "$L" --lpmbake "$LPMBAKE" -- "${BAKE[@]}") || fail "submit for the cancel phase"

# Find the lpmbake of task $victim: argv[0] (or argv[1] for an interpreted stand-in) is
# $LPMBAKE and Slurm set SLURM_ARRAY_JOB_ID / SLURM_ARRAY_TASK_ID in its environment.
find_bake() {
  local p argv
  for p in /proc/[0-9]*; do
    mapfile -d '' -t argv 2>/dev/null < "$p/cmdline" || continue
    [ "${argv[0]:-}" = "$LPMBAKE" ] || [ "${argv[1]:-}" = "$LPMBAKE" ] || continue
    grep -qxz "SLURM_ARRAY_JOB_ID=$j2" "$p/environ" 2>/dev/null || continue
    grep -qxz "SLURM_ARRAY_TASK_ID=$victim" "$p/environ" 2>/dev/null || continue
    echo "${p#/proc/}"; return 0
  done
  return 1
}
cpu_ticks() { local s; s=$(cat "/proc/$1/stat" 2>/dev/null) || { echo -1; return; }; s=${s##*) }; set -- $s; echo $(( ${12} + ${13} )); }

pid=""
for ((t = 0; t < 600; t++)); do   # 60 s for the task to start
  pid=$(find_bake || true)
  [ -n "$pid" ] && break
  [ -f "$(out_of $victim)" ] && fail "frame $victim was baked before its lpmbake process was seen"
  sleep 0.1
done
[ -n "$pid" ] || fail "the lpmbake of task ${j2}_$victim never appeared (squeue: $(squeue -h -j "$j2" 2>&1 | tr '\n' ';'))"
# Let it get into the bake (0.3 s of CPU or 1 s), then freeze it so that the bake cannot
# finish between our check and scancel.
hz=$(getconf CLK_TCK)
for ((t = 0; t < 10; t++)); do
  c=$(cpu_ticks "$pid")
  [ "$c" -lt 0 ] && break
  [ "$c" -ge $((hz * 3 / 10)) ] && break
  sleep 0.1
done
kill -STOP "$pid" 2>/dev/null || fail "lpmbake of frame $victim (pid $pid) ended before it could be frozen: bake too short"
[ -f "$(out_of $victim)" ] && fail "frame $victim finished before it was frozen (pid $pid, $(cpu_ticks "$pid") ticks)"
say "task ${j2}_$victim: lpmbake pid $pid frozen after $(cpu_ticks "$pid") CPU ticks; scancel"
scancel "${j2}_$victim" || fail "scancel ${j2}_$victim"
for ((t = 0; t < 400; t++)); do   # Slurm: SIGCONT, SIGTERM, SIGKILL after KillWait (10 s)
  [ -z "$(squeue -h -j "${j2}_$victim" 2>/dev/null)" ] && [ ! -d "/proc/$pid" ] && break
  sleep 0.1
done
[ -d "/proc/$pid" ] && [ "$(awk '{ print $3 }' "/proc/$pid/stat" 2>/dev/null)" != Z ] && fail "lpmbake pid $pid still alive 40 s after scancel"
[ -e "$(out_of $victim)" ] && fail "cancelled frame $victim left a file at its output path $(out_of $victim)"
tmp=$(find "$W/out" -name ".lit.*lpmtmp*" 2>/dev/null | tr '\n' ' ')
[ -z "$tmp" ] || fail "cancelled bake left temporary files after SIGTERM: $tmp"
# Slurm's record of the task (JobCompType=jobcomp/filetxt, written when the task ends).
for ((t = 0; t < 50; t++)); do
  state=$(grep "ArrayJobId=$j2 ArrayTaskId=$victim " "$CLUSTER/log/jobcomp.log" 2>/dev/null | sed -n 's/.*JobState=\([A-Z]*\).*/\1/p' | tail -n 1)
  [ -n "$state" ] && break
  sleep 0.1
done
[ "$state" = CANCELLED ] || fail "task ${j2}_$victim ended as '${state:-?}', not CANCELLED"
# The other tasks finish normally.
for ((t = 0; t < 1200; t++)); do [ -z "$(squeue -h -j "$j2" 2>/dev/null)" ] && break; sleep 0.1; done
[ -z "$(squeue -h -j "$j2" 2>/dev/null)" ] || fail "job $j2 still queued 120 s after the cancel"
declare -A before=()
for f in 1 2; do
  [ -f "$(out_of $f)" ] || fail "frame $f: no output after the cancel phase"
  [ "$(digest "$(out_of $f)")" = "${ref[$f]}" ] || fail "frame $f: digest differs from the local bake"
  before[$f]=$(statline "$(out_of $f)")
done
say "job $j2: task $victim cancelled mid-bake (no output, no temp file), frames 1 and 2 baked"
end cancel

# ---------------------------------------------------------------------------------------
begin resubmit
pending=$("$LPMBAKE" "${BAKE[@]}" --frames 1-3 --list-pending) || fail "lpmbake --list-pending exited $?"
[ "$pending" = "$victim" ] || fail "lpmbake --list-pending printed '$pending', expected '$victim'"
L=$W/logs_resubmit
set +e
j3=$("$SUBMIT" --frames 1-3 --cpus 1 --only-pending --wait --log-dir "$L" --lpmbake "$LPMBAKE" -- "${BAKE[@]}")
rc=$?
set -e
[ $rc = 0 ] || fail "--only-pending job ${j3:-?} exited $rc"
[[ $j3 =~ ^[0-9]+$ ]] || fail "--only-pending printed '$j3', not a job id"
tasks=$(grep -v '^#' "$L/lpmbake_$j3.frames" | tr '\n' ';')
[ "$tasks" = "$victim $victim;" ] || fail "--only-pending submitted tasks '$tasks', expected only frame $victim"
[ "$(frame_status "$L" "$j3" $victim)" = baked ] || fail "frame $victim: frame log says '$(frame_status "$L" "$j3" $victim)', not baked"
[ "$(digest "$(out_of $victim)")" = "${ref[$victim]}" ] || fail "frame $victim: re-baked digest differs from the local bake"
for f in 1 2; do
  [ "$(statline "$(out_of $f)")" = "${before[$f]}" ] || fail "frame $f was rewritten by the --only-pending job"
done
set +e
j4=$("$SUBMIT" --frames 1-3 --cpus 1 --only-pending --log-dir "$L" --lpmbake "$LPMBAKE" -- "${BAKE[@]}" 2>"$W/nothing_pending.txt")
rc=$?
set -e
[ $rc = 0 ] && [ -z "$j4" ] || fail "--only-pending with nothing pending: exit $rc, printed '$j4' ($(cat "$W/nothing_pending.txt"))"
say "job $j3: only frame $victim re-baked; nothing pending afterwards"
end resubmit

# ---------------------------------------------------------------------------------------
begin skip
for f in 1 2 3; do before[$f]=$(statline "$(out_of $f)"); done
L=$W/logs_skip
set +e
j5=$("$SUBMIT" --frames 1-3 --chunk 2 --cpus 1 --wait --log-dir "$L" --lpmbake "$LPMBAKE" -- "${BAKE[@]}")
rc=$?
set -e
[ $rc = 0 ] || fail "chunked job ${j5:-?} exited $rc"
tasks=$(grep -v '^#' "$L/lpmbake_$j5.frames" | tr '\n' ';')
[ "$tasks" = "0 1-2;1 3;" ] || fail "--chunk 2 made tasks '$tasks', expected '0 1-2;1 3;'"
for f in 1 2 3; do
  [ "$(frame_status "$L" "$j5" $f)" = skipped ] || fail "frame $f: frame log says '$(frame_status "$L" "$j5" $f)', not skipped"
  [ "$(statline "$(out_of $f)")" = "${before[$f]}" ] || fail "frame $f was rewritten although --skip-existing"
done
say "job $j5: 2 chunks, all 3 frames skipped"
end skip

# ---------------------------------------------------------------------------------------
begin stop
"$LOCAL" stop "$CLUSTER" || fail "slurm_local.sh stop"
end stop

failed=0
total=$(( ($(date +%s%N) - t_all) / 1000000 ))
line=""
for p in "${phases[@]}"; do line+="$p $(secs "${took[$p]}"), "; done
say "PASS ($cpus CPUs): ${line}total $(secs "$total")"

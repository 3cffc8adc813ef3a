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
#   cancel    outputs removed, submitted again; the lpmbake of frame 2 is frozen (SIGSTOP)
#             mid-solve and that of frame 3 mid-write (while its .lit.0003.lpmtmp-PID.vdb
#             exists; best effort, a warning if the write is missed), then their tasks are
#             scancelled (Slurm sends SIGCONT, SIGTERM): no file at their output paths, no
#             temporary file left, Slurm records them CANCELLED; frame 1 completes
#   resubmit  lpmbake --list-pending names exactly the cancelled frames;
#             lpm_slurm_submit.sh --only-pending --wait bakes those only (the others keep
#             inode and mtime); a second --only-pending submits nothing
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
# The bake arguments every phase uses. zip: the cancel phase freezes frame 3 while its
# temporary file exists and needs the rest of the write to outlast the moment between
# Slurm's SIGCONT and SIGTERM; uncompressed, the write of these small frames is so short
# that a resumed bake could finish it first (the content digests do not depend on it).
# Full resolution and 6x6 directions a face: the cancel phase freezes frame 2 after 1 s of
# CPU, and the default bake of that frame now takes 0.7 s (3.4 s with these, frame 3 4.2 s;
# one thread, 2026-12-02); under a loaded ctest -j2 the default bake ended before it.
QUALITY=(--multires off --directions-per-face 6)
BAKE=("$IN" --env "$ENV" -o "$OUT" --compression zip "${QUALITY[@]}")
# Bounded: Slurm ends a task after 3 minutes, and no --wait lasts longer than 4.
submit() { timeout 240 "$SUBMIT" --sbatch-arg --time=3 --lpmbake "$LPMBAKE" "$@"; }

# Clusters of earlier runs that were killed outright (CTest's timeout, SIGKILL) still run:
# stop those whose test process is gone.
for d in /tmp/lpmslurm.*; do
  [ -f "$d/owner" ] || continue
  owner=$(cat "$d/owner" 2>/dev/null || true)
  if [[ $owner =~ ^[0-9]+$ ]] && [ -d "/proc/$owner" ] && grep -qz slurm_test "/proc/$owner/cmdline" 2>/dev/null; then continue; fi
  say "stopping a leftover test cluster in $d"
  "$LOCAL" stop "$d" >/dev/null 2>&1 || true
  rm -rf "$d"
done

CLUSTER=$(mktemp -d /tmp/lpmslurm.XXXXXX)
echo $$ > "$CLUSTER/owner"
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
trap 'exit 130' INT
trap 'exit 143' TERM

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
expand() {  # frame spec (N, A-B, A-BxS, lists) -> sorted, space-separated frames
  local item a b st f out=()
  IFS=, read -ra items <<< "$1"
  for item in "${items[@]}"; do
    if [[ $item =~ ^([0-9]+)-([0-9]+)(x([0-9]+))?$ ]]; then
      a=${BASH_REMATCH[1]}; b=${BASH_REMATCH[2]}; st=${BASH_REMATCH[4]:-1}
      for ((f = a; f <= b; f += st)); do out+=("$f"); done
    elif [ -n "$item" ]; then out+=("$item"); fi
  done
  printf '%s\n' "${out[@]}" | sort -n | tr '\n' ' ' | sed 's/ $//'
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
"$LPMBAKE" "$IN" --env "$ENV" -o "$W/ref/ref.####.vdb" "${QUALITY[@]}" --frames 1-3 --threads 2 -q ||
  fail "local reference bake exited $?"
declare -A ref=()
for f in 1 2 3; do ref[$f]=$(digest "$(printf '%s/ref/ref.%04d.vdb' "$W" "$f")"); done
say "reference digests: 1=${ref[1]} 2=${ref[2]} 3=${ref[3]}"
end local

# ---------------------------------------------------------------------------------------
begin array
L=$W/logs_array
set +e
j1=$(submit --frames 1-3 --cpus 1 --wait --log-dir "$L" -- "${BAKE[@]}")
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
rm -f "$W"/out/lit.*.vdb
L=$W/logs_cancel
j2=$(submit --frames 1-3 --cpus 1 --log-dir "$L" -- "${BAKE[@]}") || fail "submit for the cancel phase"

# The lpmbake of task T of job j2: argv[0] (argv[1] for an interpreted stand-in) is $LPMBAKE
# and Slurm put SLURM_ARRAY_JOB_ID / SLURM_ARRAY_TASK_ID in its environment.
find_bake() {
  local p argv
  for p in /proc/[0-9]*; do
    mapfile -d '' -t argv 2>/dev/null < "$p/cmdline" || continue
    [ "${argv[0]:-}" = "$LPMBAKE" ] || [ "${argv[1]:-}" = "$LPMBAKE" ] || continue
    grep -qxz "SLURM_ARRAY_JOB_ID=$j2" "$p/environ" 2>/dev/null || continue
    grep -qxz "SLURM_ARRAY_TASK_ID=$1" "$p/environ" 2>/dev/null || continue
    echo "${p#/proc/}"; return 0
  done
  return 1
}
cpu_ticks() { local s; s=$(cat "/proc/$1/stat" 2>/dev/null) || { echo -1; return; }; s=${s##*) }; set -- $s; echo $(( ${12} + ${13} )); }
tmp_of() { printf '%s/out/.lit.%04d.lpmtmp-%s.vdb' "$W" "$1" "$2"; }   # lpmbake's .NAME.lpmtmp-PID.EXT
now_ms() { echo $(( $(date +%s%N) / 1000000 )); }

# Two victims, watched together (tasks 2 and 3 run side by side on 2 CPUs):
#  frame 2 mid-solve: frozen (SIGSTOP) after 1 s of CPU (its bake needs ~3.4 s), before any file;
#  frame 3 mid-write: frozen while its temporary file exists (the last ~0.3 s of the bake), so
#    SIGTERM must remove a real temporary file. Best effort: if the 20 ms polling misses the
#    write, frame 3 simply completes and only frame 2 counts as cancelled.
# Freezing first means the bake cannot finish between our check and scancel; Slurm sends
# SIGCONT, then SIGTERM (SIGKILL after KillWait = 10 s) to the cancelled task.
hz=$(getconf CLK_TCK)
declare -A vpid=() vstate=([2]=wait [3]=wait) vseen=()
cancelled=()
for ((t = 0; t < 4500; t++)); do   # 90 s
  for v in 2 3; do
    case ${vstate[$v]} in
      wait)
        if p=$(find_bake $v); then vpid[$v]=$p; vseen[$v]=$(now_ms); vstate[$v]=running
        elif [ -e "$(out_of $v)" ]; then fail "frame $v was baked before its lpmbake process was seen"
        fi ;;
      running)
        p=${vpid[$v]}
        if [ $v = 2 ]; then
          c=$(cpu_ticks "$p")
          [ "$c" -lt 0 ] && fail "lpmbake of frame 2 (pid $p) ended before 1 s of CPU: bake too short to cancel mid-solve"
          [ "$c" -ge "$hz" ] || [ $(( $(now_ms) - ${vseen[$v]} )) -ge 3000 ] || continue
          kill -STOP "$p" 2>/dev/null || fail "lpmbake of frame 2 (pid $p) ended before it could be frozen"
          [ -e "$(out_of 2)" ] && fail "frame 2 finished before it was frozen ($(cpu_ticks "$p") CPU ticks)"
          say "task ${j2}_2: lpmbake pid $p frozen mid-solve after $(cpu_ticks "$p") CPU ticks"
        else
          if [ -e "$(out_of 3)" ]; then
            say "warning: frame 3's write (temporary file) was not caught; it completed: mid-write cancel not checked"
            vstate[$v]=missed; continue
          fi
          if [ ! -e "$(tmp_of 3 "$p")" ]; then
            if [ ! -d "/proc/$p" ] && [ ! -e "$(out_of 3)" ]; then
              fail "lpmbake of frame 3 (pid $p) exited without writing $(out_of 3)"
            fi
            continue
          fi
          kill -STOP "$p" 2>/dev/null || continue   # ended just now: the next round sees the output
          if [ ! -e "$(tmp_of 3 "$p")" ]; then    # renamed between the check and SIGSTOP
            say "warning: frame 3 renamed its output just before SIGSTOP: mid-write cancel not checked"
            kill -CONT "$p"; vstate[$v]=missed; continue
          fi
          say "task ${j2}_3: lpmbake pid $p frozen mid-write ($(basename "$(tmp_of 3 "$p")") exists)"
        fi
        scancel "${j2}_$v" || fail "scancel ${j2}_$v"
        vstate[$v]=cancelled; cancelled+=("$v") ;;
    esac
  done
  [ "${vstate[2]}" != wait ] && [ "${vstate[2]}" != running ] && [ "${vstate[3]}" != wait ] && [ "${vstate[3]}" != running ] && break
  sleep 0.02
done
[ "${vstate[2]}" = cancelled ] || fail "frame 2 was never caught mid-solve (state ${vstate[2]}; squeue: $(squeue -h -j "$j2" 2>&1 | tr '\n' ';'))"
[ "${vstate[3]}" = cancelled ] || [ "${vstate[3]}" = missed ] || fail "frame 3: lpmbake never seen (state ${vstate[3]})"

# Wait for the whole job; then the cancelled frames must have left nothing behind.
for ((t = 0; t < 1200; t++)); do [ -z "$(squeue -h -j "$j2" 2>/dev/null)" ] && break; sleep 0.1; done
[ -z "$(squeue -h -j "$j2" 2>/dev/null)" ] || fail "job $j2 still queued 120 s after the cancel"
for v in "${cancelled[@]}"; do
  p=${vpid[$v]}
  for ((t = 0; t < 100; t++)); do [ -d "/proc/$p" ] || break; [ "$(awk '{ print $3 }' "/proc/$p/stat" 2>/dev/null)" = Z ] && break; sleep 0.1; done
  [ -d "/proc/$p" ] && [ "$(awk '{ print $3 }' "/proc/$p/stat" 2>/dev/null)" != Z ] && fail "frame $v: lpmbake pid $p still alive after scancel"
  [ -e "$(out_of $v)" ] && fail "cancelled frame $v left a file at its output path $(out_of $v)"
  [ -e "$(tmp_of $v "$p")" ] && fail "cancelled frame $v left its temporary file after SIGTERM: $(tmp_of $v "$p")"
  # Slurm's record of the task (JobCompType=jobcomp/filetxt, written when the task ends).
  state=""
  for ((t = 0; t < 50; t++)); do
    state=$(grep "ArrayJobId=$j2 ArrayTaskId=$v " "$CLUSTER/log/jobcomp.log" 2>/dev/null | sed -n 's/.*JobState=\([A-Z]*\).*/\1/p' | tail -n 1)
    [ -n "$state" ] && break
    sleep 0.1
  done
  [ "$state" = CANCELLED ] || fail "task ${j2}_$v ended as '${state:-?}', not CANCELLED"
done
left=$(find "$W/out" -name '.*lpmtmp*' | tr '\n' ' ')
[ -z "$left" ] || fail "temporary files left in the output directory: $left"
declare -A before=()
for f in 1 2 3; do
  [[ " ${cancelled[*]} " == *" $f "* ]] && continue
  [ -f "$(out_of $f)" ] || fail "frame $f: no output after the cancel phase"
  [ "$(digest "$(out_of $f)")" = "${ref[$f]}" ] || fail "frame $f: digest differs from the local bake"
  before[$f]=$(statline "$(out_of $f)")
done
say "job $j2: cancelled frames ${cancelled[*]} left no output and no temporary file; the others baked"
end cancel

# ---------------------------------------------------------------------------------------
begin resubmit
pending=$("$LPMBAKE" "${BAKE[@]}" --frames 1-3 --list-pending) || fail "lpmbake --list-pending exited $?"
want=$(IFS=,; echo "${cancelled[*]}")
[ "$(expand "$pending")" = "$(expand "$want")" ] || fail "lpmbake --list-pending printed '$pending', expected the cancelled frames $want"
L=$W/logs_resubmit
set +e
j3=$(submit --frames 1-3 --cpus 1 --only-pending --wait --log-dir "$L" -- "${BAKE[@]}")
rc=$?
set -e
[ $rc = 0 ] || fail "--only-pending job ${j3:-?} exited $rc"
[[ $j3 =~ ^[0-9]+$ ]] || fail "--only-pending printed '$j3', not a job id"
tasks=$(grep -v '^#' "$L/lpmbake_$j3.frames" | awk '{ print $2 }' | tr '\n' ',')
[ "$(expand "${tasks%,}")" = "$(expand "$want")" ] || fail "--only-pending submitted tasks for frames '$tasks', expected $want"
for f in 1 2 3; do
  if [[ " ${cancelled[*]} " == *" $f "* ]]; then
    [ "$(frame_status "$L" "$j3" $f)" = baked ] || fail "frame $f: frame log says '$(frame_status "$L" "$j3" $f)', not baked"
    [ "$(digest "$(out_of $f)")" = "${ref[$f]}" ] || fail "frame $f: re-baked digest differs from the local bake"
  else
    [ -z "$(frame_status "$L" "$j3" $f)" ] || fail "frame $f was not pending but the --only-pending job ran it"
    [ "$(statline "$(out_of $f)")" = "${before[$f]}" ] || fail "frame $f was rewritten by the --only-pending job"
  fi
done
set +e
j4=$(submit --frames 1-3 --cpus 1 --only-pending --log-dir "$L" -- "${BAKE[@]}" 2>"$W/nothing_pending.txt")
rc=$?
set -e
[ $rc = 0 ] && [ -z "$j4" ] || fail "--only-pending with nothing pending: exit $rc, printed '$j4' ($(cat "$W/nothing_pending.txt"))"
say "job $j3: only frames $want re-baked; nothing pending afterwards"
end resubmit

# ---------------------------------------------------------------------------------------
begin skip
for f in 1 2 3; do before[$f]=$(statline "$(out_of $f)"); done
L=$W/logs_skip
set +e
j5=$(submit --frames 1-3 --chunk 2 --cpus 1 --wait --log-dir "$L" -- "${BAKE[@]}")
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

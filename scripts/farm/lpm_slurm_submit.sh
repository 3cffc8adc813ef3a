#!/usr/bin/env bash
# Submit an lpmbake frame sequence to Slurm as one job array.
#
# Usage:
#   lpm_slurm_submit.sh --frames SPEC [options] -- IN.####.vdb --env SKY.exr -o OUT.####.vdb [lpmbake options]
#
# Each array task runs, on its node:
#   lpmbake <your arguments> --frames <the task's frames> --skip-existing --frame-log <log dir>/...
# so a task that is re-run (requeue, resubmission) skips the frames already baked, and a
# cancelled or killed task leaves no partial file under an output name (lpmbake writes a
# temporary file and renames it when complete).
#
# Options:
#   --frames SPEC        frames to bake, lpmbake syntax: 1001-1100, 1-50x2, 1,5,9-12 (required,
#                        or --frame N)
#   --frame N            a single frame
#   --chunk K            K frames per array task (default 1: one task per frame)
#   --cpus N             CPUs per task (sbatch --cpus-per-task=N); lpmbake runs N threads, as it
#                        reads SLURM_CPUS_PER_TASK. Without --cpus the task gets the partition's
#                        default allocation and lpmbake uses the CPUs allocated to it
#   --max-parallel P     at most P tasks run at the same time (--array=...%P)
#   --only-pending       first run `lpmbake ... --list-pending` here and submit only the frames
#                        that still need a bake (missing, incomplete, or baked with other
#                        settings); prints nothing and exits 0 when none is left
#   --wait               wait until every task has finished; exit status 0 when all succeeded,
#                        else the highest task exit status (lpmbake: 5 = some frames failed)
#   --log-dir DIR        task logs, generated job script and frames file (default ./lpm_slurm_logs)
#   --job-name NAME      Slurm job name (default lpmbake)
#   --lpmbake PATH       the lpmbake binary (default: $LPMBAKE, else lpmbake on PATH, else this
#                        repository's build/baker/lpmbake); it must be reachable from the nodes
#   --sbatch-arg ARG     pass ARG to sbatch, e.g. --sbatch-arg --partition=render
#                        --sbatch-arg --time=2:00:00 --sbatch-arg --mem=16G (repeatable; wins
#                        over the settings above)
#   --max-array-size N   Slurm's MaxArraySize (default: from `scontrol show config`, else 1001)
#   --dry-run            print the frames file, job script and sbatch command; submit nothing
#   -h, --help           this help
#
# Output: the job id on stdout (nothing when --only-pending finds no frame); messages on stderr.
#
# Files in the log dir, for job id J:
#   NAME_J_T.log             stdout+stderr of array task T
#   NAME_J_T.frames.jsonl    lpmbake --frame-log of task T: one JSON line per frame
#                            ({"frame":N,"status":"baked|skipped|failed",...})
#   NAME_J.frames            which frames each task bakes: lines "TASK FRAMES"
#   NAME_J.sbatch            the job script (sbatch it again by hand to resubmit the same tasks)
#
# Task ids: with --chunk 1 and frames inside Slurm's MaxArraySize (default 1001: ids 0..1000)
# the task id IS the frame number (scancel J_57 cancels frame 57). Otherwise (chunks, frames
# such as 1001-1100) tasks are numbered 0..N-1 and NAME_J.frames maps them to frames.
#
# Examples:
#   lpm_slurm_submit.sh --frames 1001-1100 --cpus 8 --max-parallel 20 -- \
#       cache/smoke.####.vdb --env sky.exr -o lit/smoke.####.vdb --g 0.5
#   lpm_slurm_submit.sh --frames 1001-1100 --cpus 8 --only-pending -- <same lpmbake arguments>
#   squeue -j J; tail -f lpm_slurm_logs/lpmbake_J_*.log; scancel J (all) or scancel J_57
set -euo pipefail

PROG=lpm_slurm_submit.sh
log() { echo "$PROG: $*" >&2; }
die() { echo "$PROG: error: $*" >&2; exit 1; }
usage() { sed -n '2,/^set -euo pipefail/p' "${BASH_SOURCE[0]}" | sed '$d' | sed 's/^# \{0,1\}//'; }

# ---------------------------------------------------------------------------------------
# Frame lists

# expand_frames SPEC: one frame number per line, in the order given, duplicates dropped.
# SPEC: comma-separated items N, A-B or A-BxS (non-negative integers, A <= B, S >= 1).
expand_frames() {
  local spec=$1 item a b s f
  local -A seen=()
  [ -n "$spec" ] || die "empty frame spec"
  IFS=, read -ra items <<< "$spec"
  for item in "${items[@]}"; do
    if [[ $item =~ ^([0-9]+)$ ]]; then
      a=$((10#${BASH_REMATCH[1]})); b=$a; s=1
    elif [[ $item =~ ^([0-9]+)-([0-9]+)(x([0-9]+))?$ ]]; then
      a=$((10#${BASH_REMATCH[1]})); b=$((10#${BASH_REMATCH[2]})); s=$((10#${BASH_REMATCH[4]:-1}))
      [ "$a" -le "$b" ] || die "frame range '$item': start after end"
      [ "$s" -ge 1 ] || die "frame range '$item': step must be at least 1"
    else
      die "bad frame spec item '$item' in '$spec' (expected N, A-B or A-BxS)"
    fi
    for ((f = a; f <= b; f += s)); do
      [ -n "${seen[$f]:-}" ] && continue
      seen[$f]=1; echo "$f"
    done
  done
}

# compress_frames SEP F1 F2 ...: a compact spec. Runs of 3 or more frames with the same
# step become A-B (step 1) or A-B<SEP>S; two consecutive frames become A-B.
# SEP is "x" for lpmbake (1-9x2) and ":" for sbatch --array (1-9:2).
compress_frames() {
  local sep=$1; shift
  local f=("$@") n=$# i=0 j d out=""
  while [ $i -lt $n ]; do
    j=$i
    if [ $((i + 1)) -lt $n ]; then
      d=$((f[i + 1] - f[i]))
      if [ $d -gt 0 ]; then
        while [ $((j + 1)) -lt $n ] && [ $((f[j + 1] - f[j])) -eq $d ]; do j=$((j + 1)); done
      fi
    fi
    if [ $j -gt $i ] && { [ $d -eq 1 ] || [ $((j - i)) -ge 2 ]; }; then
      if [ $d -eq 1 ]; then out+=",${f[i]}-${f[j]}"; else out+=",${f[i]}-${f[j]}${sep}${d}"; fi
      i=$((j + 1))
    else
      out+=",${f[i]}"; i=$((i + 1))
    fi
  done
  echo "${out#,}"
}

# ---------------------------------------------------------------------------------------
# Arguments

frames_spec=""; chunk=1; cpus=""; max_parallel=""; only_pending=0; wait_job=0; dry_run=0
log_dir=./lpm_slurm_logs; job_name=lpmbake; lpmbake=${LPMBAKE:-}; max_array=""
sbatch_args=(); bake_args=()

orig_args=("$@")
need() { [ $# -ge 2 ] || die "$1 needs a value"; }
while [ $# -gt 0 ]; do
  case $1 in
    -h | --help) usage; exit 0 ;;
    --frames) need "$@"; frames_spec=$2; shift 2 ;;
    --frames=*) frames_spec=${1#*=}; shift ;;
    --frame) need "$@"; frames_spec=$2; shift 2 ;;
    --frame=*) frames_spec=${1#*=}; shift ;;
    --chunk) need "$@"; chunk=$2; shift 2 ;;
    --chunk=*) chunk=${1#*=}; shift ;;
    --cpus) need "$@"; cpus=$2; shift 2 ;;
    --cpus=*) cpus=${1#*=}; shift ;;
    --max-parallel) need "$@"; max_parallel=$2; shift 2 ;;
    --max-parallel=*) max_parallel=${1#*=}; shift ;;
    --only-pending) only_pending=1; shift ;;
    --wait) wait_job=1; shift ;;
    --dry-run) dry_run=1; shift ;;
    --log-dir) need "$@"; log_dir=$2; shift 2 ;;
    --log-dir=*) log_dir=${1#*=}; shift ;;
    --job-name) need "$@"; job_name=$2; shift 2 ;;
    --job-name=*) job_name=${1#*=}; shift ;;
    --lpmbake) need "$@"; lpmbake=$2; shift 2 ;;
    --lpmbake=*) lpmbake=${1#*=}; shift ;;
    --max-array-size) need "$@"; max_array=$2; shift 2 ;;
    --max-array-size=*) max_array=${1#*=}; shift ;;
    --sbatch-arg) need "$@"; sbatch_args+=("$2"); shift 2 ;;
    --sbatch-arg=*) sbatch_args+=("${1#*=}"); shift ;;
    --) shift; bake_args=("$@"); break ;;
    *) die "unknown option '$1' (lpmbake arguments go after --; see --help)" ;;
  esac
done

[ -n "$frames_spec" ] || die "--frames SPEC (or --frame N) is required"
[ ${#bake_args[@]} -gt 0 ] || die "no lpmbake arguments after -- (IN.####.vdb --env SKY -o OUT.####.vdb ...)"
[[ $chunk =~ ^[1-9][0-9]*$ ]] || die "--chunk must be a positive integer, not '$chunk'"
[ -z "$cpus" ] || [[ $cpus =~ ^[1-9][0-9]*$ ]] || die "--cpus must be a positive integer, not '$cpus'"
[ -z "$max_parallel" ] || [[ $max_parallel =~ ^[1-9][0-9]*$ ]] || die "--max-parallel must be a positive integer"
[[ $job_name =~ ^[A-Za-z0-9._-]+$ ]] || die "--job-name: letters, digits, . _ - only"

# The frames of each task are ours to set; --skip-existing is always added (given once).
filtered=()
for a in "${bake_args[@]}"; do
  case $a in
    --frames | --frames=* | --frame | --frame=* | --list-pending)
      die "lpmbake argument '$a': give frames with $PROG --frames, not after --" ;;
    --skip-existing) ;;
    *) filtered+=("$a") ;;
  esac
done
bake_args=("${filtered[@]}")
user_frame_log=0
for a in "${bake_args[@]}"; do case $a in --frame-log | --frame-log=*) user_frame_log=1 ;; esac; done

# lpmbake: absolute, since the tasks run it from the nodes.
if [ -z "$lpmbake" ]; then
  lpmbake=$(command -v lpmbake 2>/dev/null || true)
  if [ -z "$lpmbake" ]; then
    repo_bin="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)/build/baker/lpmbake"
    [ -x "$repo_bin" ] && lpmbake=$repo_bin
  fi
fi
[ -n "$lpmbake" ] || die "lpmbake not found: use --lpmbake PATH or set LPMBAKE"
case $lpmbake in
  */*) [ -x "$lpmbake" ] || die "--lpmbake $lpmbake: not an executable"
       lpmbake="$(cd "$(dirname "$lpmbake")" && pwd)/$(basename "$lpmbake")" ;;
  *) lpmbake=$(command -v "$lpmbake") || die "--lpmbake $lpmbake: not on PATH" ;;
esac

# ---------------------------------------------------------------------------------------
# Which frames

list=$(expand_frames "$frames_spec") || exit 1
mapfile -t frames <<< "$list"
[ ${#frames[@]} -gt 0 ] || die "no frames in '$frames_spec'"

if [ $only_pending = 1 ]; then
  # Same arguments as the bake, so "pending" means: no complete bake with these settings.
  pending=$("$lpmbake" "${bake_args[@]}" --frames "$(compress_frames x "${frames[@]}")" --list-pending) ||
    die "lpmbake --list-pending failed (exit $?): fix the lpmbake arguments"
  pending=$(printf '%s' "$pending" | head -n 1 | tr -d '[:space:]')
  if [ -z "$pending" ]; then
    log "nothing to submit: all ${#frames[@]} frames are baked"
    exit 0
  fi
  list=$(expand_frames "$pending") || die "cannot read lpmbake --list-pending output '$pending'"
  mapfile -t frames <<< "$list"
  log "${#frames[@]} frames pending: $pending"
fi

# ---------------------------------------------------------------------------------------
# Tasks: task id -> frames

if [ -z "$max_array" ]; then
  max_array=1001   # Slurm's default MaxArraySize: task ids 0..1000
  if command -v scontrol >/dev/null 2>&1; then
    m=$(scontrol show config 2>/dev/null | awk '$1 == "MaxArraySize" { print $3 }' || true)
    if [[ ${m:-} =~ ^[0-9]+$ ]]; then max_array=$m; fi
  fi
fi
[[ $max_array =~ ^[1-9][0-9]*$ ]] || die "--max-array-size must be a positive integer"

task_ids=(); task_frames=()
min=${frames[0]}; max=${frames[0]}
for f in "${frames[@]}"; do [ "$f" -lt "$min" ] && min=$f; [ "$f" -gt "$max" ] && max=$f; done
if [ "$chunk" = 1 ] && [ "$max" -lt "$max_array" ]; then
  # Task id = frame number.
  mapfile -t sorted < <(printf '%s\n' "${frames[@]}" | sort -n)
  for f in "${sorted[@]}"; do task_ids+=("$f"); task_frames+=("$f"); done
  array_spec=$(compress_frames : "${sorted[@]}")
else
  # Tasks 0..N-1, each with up to $chunk frames in the order given.
  n=0
  for ((i = 0; i < ${#frames[@]}; i += chunk)); do
    task_ids+=("$n"); task_frames+=("$(compress_frames x "${frames[@]:i:chunk}")"); n=$((n + 1))
  done
  [ "$n" -le "$max_array" ] || die "$n tasks exceed Slurm's MaxArraySize ($max_array): use --chunk $(( (${#frames[@]} + max_array - 1) / max_array ))"
  array_spec="0-$((n - 1))"
fi
[ -z "$max_parallel" ] || array_spec+="%$max_parallel"

# ---------------------------------------------------------------------------------------
# Files: frames file and job script in the log dir

mkdir -p "$log_dir"
log_dir=$(cd "$log_dir" && pwd)
# lpmbake reads frame patterns (#, @, %04d, $F4) anywhere in a --frame-log path: a log dir
# holding one would send the frame logs elsewhere, so go without them there.
if [ $user_frame_log = 0 ] && [[ $log_dir =~ [#@]|%0?[0-9]*d|\$F ]]; then
  log "warning: log dir '$log_dir' holds a frame-pattern character (# @ %d \$F): no per-task frame logs"
  user_frame_log=2
fi
tag="${job_name}_$(date +%Y%m%d-%H%M%S)_$$"
frames_file="$log_dir/$tag.frames"
script="$log_dir/$tag.sbatch"

{
  echo "# $PROG: array task id -> lpmbake --frames (job script $script)"
  for ((i = 0; i < ${#task_ids[@]}; i++)); do echo "${task_ids[i]} ${task_frames[i]}"; done
} > "$frames_file"

# sbatch options: all on the command line (safe for paths with spaces); --sbatch-arg last, so
# they override ours.
sbatch_cmd=(sbatch --parsable --job-name="$job_name" --array="$array_spec"
            --output="$log_dir/${job_name}_%A_%a.log" --chdir="$PWD" --ntasks=1)
[ -z "$cpus" ] || sbatch_cmd+=(--cpus-per-task="$cpus")
sbatch_cmd+=("${sbatch_args[@]}")

quoted_bake=$(printf ' %q' "${bake_args[@]}")
{
  echo "#!/usr/bin/env bash"
  echo "# Generated by $PROG on $(date '+%Y-%m-%d %H:%M:%S') in $PWD"
  printf '# Submitted as:%s\n' "$(printf ' %q' "$0" "${orig_args[@]}")"
  echo "# The sbatch options are on its command line; to run these tasks again:"
  echo "#   $(printf '%q ' "${sbatch_cmd[@]}")$(printf '%q' "$script")"
  cat <<EOF
set -euo pipefail
frames_file=$(printf '%q' "$frames_file")
task=\${SLURM_ARRAY_TASK_ID:?this script runs as a Slurm array task}
frames=\$(awk -v t="\$task" '\$1 == t { print \$2; exit }' "\$frames_file")
[ -n "\$frames" ] || { echo "lpm_slurm: no frames for task \$task in \$frames_file" >&2; exit 1; }
# lpmbake's default --threads is SLURM_CPUS_PER_TASK, which Slurm sets only for jobs
# submitted with --cpus-per-task: otherwise use the CPUs allocated on this node.
export SLURM_CPUS_PER_TASK=\${SLURM_CPUS_PER_TASK:-\${SLURM_CPUS_ON_NODE:-1}}
echo "lpm_slurm: job \${SLURM_ARRAY_JOB_ID}_\$task on \$(hostname -s): frames \$frames, \$SLURM_CPUS_PER_TASK CPUs" >&2
EOF
  if [ $user_frame_log != 0 ]; then
    echo "exec $(printf '%q' "$lpmbake")$quoted_bake --frames \"\$frames\" --skip-existing"
  else
    echo "exec $(printf '%q' "$lpmbake")$quoted_bake --frames \"\$frames\" --skip-existing \\"
    echo "  --frame-log $(printf '%q' "$log_dir")/${job_name}_\${SLURM_ARRAY_JOB_ID}_\${task}.frames.jsonl"
  fi
} > "$script"
chmod +x "$script"
[ $wait_job = 1 ] && sbatch_cmd+=(--wait)
sbatch_cmd+=("$script")

if [ $dry_run = 1 ]; then
  {
    echo "== $frames_file"; cat "$frames_file"
    echo "== $script"; cat "$script"
    echo "== command"; printf '%q ' "${sbatch_cmd[@]}"; echo
  } >&2
  exit 0
fi

# ---------------------------------------------------------------------------------------
# Submit

command -v sbatch >/dev/null || die "sbatch not found (is this a Slurm submit host?)"
ntasks=${#task_ids[@]}
nframes=${#frames[@]}
announce() {  # JOBID: print it, name the files after it
  local jid=${1%%;*}   # --parsable prints "id" or "id;cluster"
  ln -sf "$(basename "$frames_file")" "$log_dir/${job_name}_$jid.frames"
  ln -sf "$(basename "$script")" "$log_dir/${job_name}_$jid.sbatch"
  echo "$jid"
  log "job $jid: $ntasks tasks, $nframes frames, array $array_spec; logs $log_dir/${job_name}_${jid}_<task>.log"
}

if [ $wait_job = 0 ]; then
  out=$("${sbatch_cmd[@]}") || die "sbatch failed"
  announce "$(printf '%s' "$out" | head -n 1)"
  exit 0
fi

# --wait: sbatch prints the id at once and exits when the whole array has finished, with the
# highest exit status of its tasks. Print the id as soon as it comes.
jid_file=$(mktemp)
trap 'rm -f "$jid_file"' EXIT
set +e
"${sbatch_cmd[@]}" | {
  IFS= read -r line && { printf '%s\n' "$line" > "$jid_file"; announce "$line"; }
  cat >&2
}
rc=${PIPESTATUS[0]}
set -e
jid=$(cut -d';' -f1 "$jid_file")
[ -n "$jid" ] || die "sbatch failed (exit $rc)"
if [ $user_frame_log = 0 ]; then
  # Summary from the frame logs of this job.
  summary=$(cat "$log_dir/${job_name}_${jid}"_*.frames.jsonl 2>/dev/null |
    sed -n 's/.*"status" *: *"\([a-z]*\)".*/\1/p' | sort | uniq -c | awk '{ printf "%s%s %s", sep, $1, $2; sep = ", " }')
  log "job $jid finished (exit $rc): ${summary:-no frame log}"
else
  log "job $jid finished (exit $rc)"
fi
exit "$rc"

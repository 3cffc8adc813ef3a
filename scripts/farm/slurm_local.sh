#!/usr/bin/env bash
# A throw-away one-node Slurm cluster under a directory, for tests and for trying the farm
# scripts on one machine (Debian 12: slurm-wlm 22.05, munge 0.5.15; run as root).
#
#   slurm_local.sh start DIR [--cpus N]   start munged, slurmctld, slurmd; wait until the node is idle;
#                                         write DIR/env (". DIR/env" sets SLURM_CONF for sbatch & co.)
#   slurm_local.sh stop DIR               cancel every job, wait for an empty queue, stop the daemons
#                                         by the pids recorded at start, end leftover job steps
#   slurm_local.sh status DIR             print what runs; exit 0 when all three daemons are alive
#
# start is idempotent (a running cluster is reused; leftovers of a dead one are cleared first).
# stop is idempotent and safe in a trap: it never needs the daemons to be healthy, it only
# signals processes tied to this DIR (daemons whose /proc/PID/cmdline names it, job steps with
# their cwd or open files in it, job processes with this cluster's SLURM_CLUSTER_NAME), and
# it returns 0 unless one of them survived SIGKILL. --cpus N (default nproc) must not exceed
# the machine's CPUs.
#
# Layout of DIR (keep DIR short: Slurm and munge put unix sockets in it, 107 bytes at most):
#   env                    export SLURM_CONF=DIR/etc/slurm.conf
#   etc/slurm.conf         one node (this host), one partition "lpm", ports chosen free at start
#   munge/                 munge.key (our own, mode 0600), socket, munged.log, seed
#   state/ spool/          StateSaveLocation, SlurmdSpoolDir
#   log/                   slurmctld.log, slurmd.log, jobcomp.log (one line per finished job)
#   run/                   pid files written by the daemons (they delete them on exit)
#   pids/NAME              the same pids, copied at start: stop reads these
#
# Pitfalls handled here (docs/farm.md and the ecosystem notes list them): munged refuses a
# socket directory that is not o+x (or any directory above it), and a key not owned by its
# user with mode 0600; clients need SLURM_CONF and AuthInfo=socket=...; slurmd leaves running
# jobs alone when it exits; kill -0 reports zombies as alive; MinJobAge=4 so that sbatch --wait
# polls every 2 s instead of 10, 42, 74 s.
set -euo pipefail

PROG=slurm_local.sh
log() { echo "$PROG: $*" >&2; }
die() { log "error: $*"; exit 1; }

usage() {
  sed -n '2,16p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'
}

# ---------------------------------------------------------------------------------------
# Process helpers (pure /proc: no pgrep/pkill, which match by name across the machine).

# proc_state PID -> one letter (R, S, D, Z, T, ...) or nothing if the pid does not exist.
# The comm field in /proc/PID/stat may hold spaces and parentheses: cut after the last ')'.
proc_state() {
  local stat
  stat=$(cat "/proc/$1/stat" 2>/dev/null) || return 0
  stat=${stat##*) }
  echo "${stat%% *}"
}

# alive PID: the process exists and is not a zombie (kill -0 succeeds on zombies).
alive() {
  local s
  s=$(proc_state "$1")
  [ -n "$s" ] && [ "$s" != Z ] && [ "$s" != X ]
}

# cmdline PID -> the command line with NULs as spaces (empty for zombies/kernel threads).
cmdline() { tr '\0' ' ' 2>/dev/null < "/proc/$1/cmdline" || true; }

# ppid PID
ppid_of() {
  local stat
  stat=$(cat "/proc/$1/stat" 2>/dev/null) || return 0
  stat=${stat##*) }
  set -- $stat
  echo "$2"
}

# descendants PID -> all pids below PID (children first listed after their parent).
descendants() {
  local root=$1 p q changed=1
  local -A inset=(["$root"]=1)
  local all=()
  for p in /proc/[0-9]*; do all+=("${p#/proc/}"); done
  while [ $changed = 1 ]; do
    changed=0
    for q in "${all[@]}"; do
      [ -n "${inset[$q]:-}" ] && continue
      p=$(ppid_of "$q")
      if [ -n "$p" ] && [ -n "${inset[$p]:-}" ]; then inset[$q]=1; echo "$q"; changed=1; fi
    done
  done
}

# stop_pids SECONDS PID...: SIGTERM, wait up to SECONDS for them to go, then SIGKILL.
# Returns 1 if one survives SIGKILL (e.g. stuck in D state).
stop_pids() {
  local wait_s=$1; shift
  local p t left
  [ $# -eq 0 ] && return 0
  for p in "$@"; do alive "$p" && kill -TERM "$p" 2>/dev/null || true; done
  for ((t = 0; t < wait_s * 10; t++)); do
    left=0
    for p in "$@"; do alive "$p" && left=1; done
    [ $left = 0 ] && return 0
    sleep 0.1
  done
  for p in "$@"; do
    if alive "$p"; then log "pid $p ($(cmdline "$p")) ignored SIGTERM: SIGKILL"; kill -KILL "$p" 2>/dev/null || true; fi
  done
  for ((t = 0; t < 30; t++)); do
    left=0
    for p in "$@"; do alive "$p" && left=1; done
    [ $left = 0 ] && return 0
    sleep 0.1
  done
  for p in "$@"; do alive "$p" && log "pid $p survives SIGKILL (state $(proc_state "$p"))"; done
  return 1
}

# ---------------------------------------------------------------------------------------
# Paths

resolve_dir() {  # absolute path, without creating anything
  local d=$1
  case $d in /*) ;; *) d="$PWD/$d" ;; esac
  # squeeze // and trailing /
  d=$(printf '%s' "$d" | sed 's#//*#/#g; s#/$##')
  echo "${d:-/}"
}

set_paths() {
  DIR=$(resolve_dir "$1")
  CONF=$DIR/etc/slurm.conf
  MUNGE_SOCKET=$DIR/munge/munge.socket
  PIDS=$DIR/pids
}

# The daemon's pid recorded at start, if it still names this cluster in its command line.
recorded_pid() {  # NAME -> pid or nothing
  local name=$1 pid cl
  [ -f "$PIDS/$name" ] || return 0
  pid=$(cat "$PIDS/$name" 2>/dev/null || true)
  [[ $pid =~ ^[0-9]+$ ]] || return 0
  alive "$pid" || return 0
  cl=$(cmdline "$pid")
  case $cl in
    *"$name"*"$DIR/"*) echo "$pid" ;;
    *) log "pid $pid from $PIDS/$name is now '$cl': not ours, left alone" ;;
  esac
}

all_alive() {
  [ -n "$(recorded_pid munged)" ] && [ -n "$(recorded_pid slurmctld)" ] && [ -n "$(recorded_pid slurmd)" ]
}

# ---------------------------------------------------------------------------------------
# start

port_in_use() {  # PORT: listening on any address (IPv4 or IPv6)?
  local hex
  hex=$(printf '%04X' "$1")
  awk -v p=":$hex" 'NR > 1 && $4 == "0A" && substr($2, length($2) - 4) == p { f = 1 } END { exit !f }' \
    /proc/net/tcp /proc/net/tcp6 2>/dev/null
}

free_port_pair() {  # two consecutive free ports in 20000..59999, from a random start
  local p tries
  p=$((20000 + (RANDOM * 32768 + RANDOM) % 40000))
  for ((tries = 0; tries < 200; tries++)); do
    if ! port_in_use "$p" && ! port_in_use $((p + 1)); then echo "$p"; return 0; fi
    p=$((20000 + (p - 20000 + 7) % 39998))
  done
  die "no free TCP port pair found"
}

check_dirs_searchable() {  # every directory from / down to $1 must be o+x for munged
  local d=$1 bad=""
  while :; do
    if [ -d "$d" ] && [ -z "$(find "$d" -maxdepth 0 -perm -o+x 2>/dev/null)" ]; then bad="$bad $d"; fi
    [ "$d" = / ] && break
    d=$(dirname "$d")
  done
  [ -z "$bad" ] || die "munged needs every directory above its socket to be o+x; not:$bad (chmod o+x, or use a DIR under /tmp)"
}

write_conf() {
  local host cpus mem port cluster
  host=$(hostname -s)
  cpus=$1
  mem=$(slurmd -C 2>/dev/null | sed -n 's/.*RealMemory=\([0-9]*\).*/\1/p')
  mem=${mem:-1000}
  port=$(free_port_pair)
  # A cluster name unique to this start: Slurm puts it in every job's environment
  # (SLURM_CLUSTER_NAME), which lets stop find orphaned job processes of this cluster only.
  cluster=lpm$(printf '%s' "$DIR$$$(date +%s%N)" | md5sum | cut -c1-8)
  echo "$cluster" > "$DIR/cluster_name"
  cat > "$CONF" <<EOF
# Generated by scripts/farm/slurm_local.sh for a one-node test cluster in $DIR
ClusterName=$cluster
# Loopback addresses: the host name need not resolve.
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=$port
SlurmdPort=$((port + 1))
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$MUNGE_SOCKET
StateSaveLocation=$DIR/state
SlurmdSpoolDir=$DIR/spool
SlurmctldPidFile=$DIR/run/slurmctld.pid
SlurmdPidFile=$DIR/run/slurmd.pid
SlurmctldLogFile=$DIR/log/slurmctld.log
SlurmdLogFile=$DIR/log/slurmd.log
SlurmctldDebug=info
SlurmdDebug=info
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/filetxt
JobCompLoc=$DIR/log/jobcomp.log
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
SchedulerType=sched/backfill
# Start jobs as soon as they are submitted or a CPU frees up (defaults wait up to 3 s).
SchedulerParameters=batch_sched_delay=0,sched_min_interval=0
MpiDefault=none
MailProg=/bin/true
ReturnToService=2
# Finished jobs leave squeue after 4 s; sbatch --wait then polls every 2 s.
MinJobAge=4
# scancel: SIGCONT + SIGTERM, then SIGKILL after KillWait seconds (default 30).
KillWait=10
SlurmdTimeout=30
InactiveLimit=0
NodeName=$host NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$mem State=UNKNOWN
PartitionName=lpm Nodes=$host Default=YES MaxTime=INFINITE State=UP OverSubscribe=NO
EOF
}

wait_pidfile() {  # FILE SECONDS -> pid once the daemon wrote it
  local f=$1 t pid
  for ((t = 0; t < $2 * 10; t++)); do
    pid=$(cat "$f" 2>/dev/null || true)
    if [[ $pid =~ ^[0-9]+$ ]] && alive "$pid"; then echo "$pid"; return 0; fi
    sleep 0.1
  done
  return 1
}

start_daemon() {  # NAME PIDFILE LOGFILE CMD...: run, record its pid in pids/NAME
  local name=$1 pidfile=$2 logfile=$3 pid; shift 3
  rm -f "$pidfile"
  "$@" || { tail -n 20 "$logfile" >&2 2>/dev/null || true; die "$name failed to start: $*"; }
  pid=$(wait_pidfile "$pidfile" 15) || { tail -n 20 "$logfile" >&2 2>/dev/null || true; die "$name wrote no live pid to $pidfile"; }
  echo "$pid" > "$PIDS/$name"
}

cmd_start() {
  local cpus="" t state
  while [ $# -gt 0 ]; do
    case $1 in
      --cpus) cpus=$2; shift 2 ;;
      --cpus=*) cpus=${1#*=}; shift ;;
      *) die "start: unknown option '$1'" ;;
    esac
  done
  [ "$(id -u)" = 0 ] || die "run as root (SlurmUser=root, munged and slurmd as root)"
  for b in munged mungekey slurmctld slurmd sinfo sbatch squeue scancel; do
    command -v "$b" >/dev/null || die "$b not found (apt-get install --no-install-recommends slurm-wlm munge)"
  done
  # Unix socket paths are limited to 107 bytes; slurmd puts NODE_JOBID.STEPID sockets in spool/.
  [ $(( ${#DIR} + 40 )) -le 107 ] || die "DIR too long for unix sockets (${#DIR} bytes; keep it under 67): $DIR"

  if all_alive; then
    log "cluster in $DIR already running"
  else
    # Leftovers of an earlier cluster in DIR (crashed test, killed shell): clear them first.
    if [ -d "$PIDS" ]; then cmd_stop >/dev/null 2>&1 || true; fi
    mkdir -p "$DIR"
    chmod 755 "$DIR"   # mktemp -d makes 0700: munged needs o+x on every directory above its socket
    check_dirs_searchable "$DIR"
    rm -rf "$DIR/state" "$DIR/spool" "$DIR/run" "$PIDS" "$DIR/munge"
    mkdir -p "$DIR/etc" "$DIR/munge" "$DIR/state" "$DIR/spool" "$DIR/log" "$DIR/run" "$PIDS"
    chmod 755 "$DIR/etc" "$DIR/log" "$DIR/run" "$PIDS"
    chmod 700 "$DIR/munge" "$DIR/state" "$DIR/spool"
    chmod 755 "$DIR/munge"    # socket dir: o+x so clients reach the socket
    [ -n "$cpus" ] || cpus=$(nproc)
    write_conf "$cpus"

    # munge: our own key (Debian's /etc/munge/munge.key belongs to uid munge and a root munged
    # refuses it), owned by root, mode 0600.
    mungekey -c -k "$DIR/munge/munge.key" >/dev/null 2>&1 || die "mungekey -c failed"
    chmod 600 "$DIR/munge/munge.key"
    start_daemon munged "$DIR/munge/munged.pid" "$DIR/munge/munged.log" \
      munged --socket="$MUNGE_SOCKET" --key-file="$DIR/munge/munge.key" \
      --pid-file="$DIR/munge/munged.pid" --log-file="$DIR/munge/munged.log" \
      --seed-file="$DIR/munge/munged.seed"
    # -c: no state from an earlier run; -i: ignore unreadable state files.
    start_daemon slurmctld "$DIR/run/slurmctld.pid" "$DIR/log/slurmctld.log" slurmctld -c -i -f "$CONF"
    start_daemon slurmd "$DIR/run/slurmd.pid" "$DIR/log/slurmd.log" slurmd -f "$CONF"
    printf 'export SLURM_CONF=%q\n' "$CONF" > "$DIR/env"
  fi

  # Wait for the node to register and go idle (about 1 s; "mixed"/"allocated" if jobs run).
  export SLURM_CONF=$CONF
  for ((t = 0; t < 300; t++)); do
    state=$(sinfo -h -o %T 2>/dev/null | head -n 1 || true)
    case $state in idle | mixed | allocated | completing) break ;; esac
    all_alive || { tail -n 20 "$DIR/log/slurmctld.log" "$DIR/log/slurmd.log" >&2 2>/dev/null || true; die "a daemon died during start"; }
    sleep 0.1
  done
  case $state in
    idle | mixed | allocated | completing) ;;
    *) tail -n 20 "$DIR/log/slurmctld.log" "$DIR/log/slurmd.log" >&2 2>/dev/null || true
       die "node not idle after 30 s (state '${state:-none}')" ;;
  esac
  log "cluster up in $DIR (node $(hostname -s), $(sed -n 's/^NodeName=.* CPUs=\([0-9]*\).*/\1/p' "$CONF") CPUs, state $state); . $DIR/env"
}

# ---------------------------------------------------------------------------------------
# stop

# Job-step daemons (slurmstepd) of this cluster: their cwd or an open fd points into DIR.
stepd_pids() {
  local p comm f
  for p in /proc/[0-9]*; do
    p=${p#/proc/}
    comm=""
    read -r comm 2>/dev/null < "/proc/$p/comm" || continue
    [ "$comm" = slurmstepd ] || continue
    alive "$p" || continue
    if [[ "$(readlink "/proc/$p/cwd" 2>/dev/null)" == "$DIR/"* ]]; then echo "$p"; continue; fi
    for f in /proc/"$p"/fd/*; do
      if [[ "$(readlink "$f" 2>/dev/null)" == "$DIR/"* ]]; then echo "$p"; break; fi
    done
  done
}

# Job processes of this cluster whose slurmstepd is gone: Slurm set SLURM_CLUSTER_NAME=<ours>
# in their environment. The caller and its ancestors are never listed.
orphan_job_pids() {
  local name p a
  name=$(cat "$DIR/cluster_name" 2>/dev/null || true)
  [ -n "$name" ] || return 0
  local -A mine=()
  a=$$
  while [ -n "$a" ] && [ "$a" != 0 ]; do mine[$a]=1; a=$(ppid_of "$a"); done
  for p in /proc/[0-9]*; do
    p=${p#/proc/}
    [ -n "${mine[$p]:-}" ] && continue
    alive "$p" || continue
    if grep -qxz "SLURM_CLUSTER_NAME=$name" "/proc/$p/environ" 2>/dev/null; then echo "$p"; fi
  done
}

cmd_stop() {
  local rc=0 t jobs pid name stray steps
  [ -d "$DIR" ] || { log "nothing in $DIR"; return 0; }
  export SLURM_CONF=$CONF
  # 1. Cancel every job and wait for the queue to drain (slurmd does not end running jobs
  #    when it exits). Only possible while slurmctld answers.
  if [ -n "$(recorded_pid slurmctld)" ] && [ -f "$CONF" ]; then
    jobs=$(squeue -h -o %A 2>/dev/null | sort -u | tr '\n' ' ' || true)
    if [ -n "${jobs// /}" ]; then
      # shellcheck disable=SC2086
      scancel $jobs 2>/dev/null || true
      for ((t = 0; t < 300; t++)); do   # KillWait is 10 s; allow 30 s
        [ -z "$(squeue -h -o %A 2>/dev/null || true)" ] && break
        [ -n "$(recorded_pid slurmd)" ] || break
        sleep 0.1
      done
      [ -z "$(squeue -h -o %A 2>/dev/null || true)" ] || log "queue not empty after 30 s: $(squeue -h 2>/dev/null | tr '\n' ';')"
    fi
  fi
  # 2. Daemons by the pids recorded at start (their own pid files are gone once they exit).
  for name in slurmd slurmctld munged; do
    pid=$(recorded_pid "$name")
    [ -n "$pid" ] || continue
    stop_pids 10 "$pid" || rc=1
  done
  # 3. Job steps that outlived slurmd (hard death): first the job processes below them and
  #    the ones already orphaned (SIGTERM lets lpmbake remove its temp file), then the
  #    slurmstepd themselves (they ignore SIGTERM: 1 s grace, then SIGKILL).
  steps=$(stepd_pids | sort -un | tr '\n' ' ')
  stray=$(for pid in $steps; do descendants "$pid"; done; orphan_job_pids)
  stray=$(echo "$stray" | sort -un | tr '\n' ' ')
  if [ -n "${stray// /}" ]; then
    log "ending leftover job processes: $stray"
    # shellcheck disable=SC2086
    stop_pids 5 $stray || rc=1
  fi
  if [ -n "${steps// /}" ]; then
    log "ending leftover slurmstepd: $steps"
    # shellcheck disable=SC2086
    stop_pids 1 $steps || rc=1
  fi
  rm -f "$PIDS"/* 2>/dev/null || true
  [ $rc = 0 ] && log "cluster in $DIR stopped"
  return $rc
}

cmd_status() {
  local name pid rc=0
  for name in munged slurmctld slurmd; do
    pid=$(recorded_pid "$name")
    if [ -n "$pid" ]; then echo "$name: pid $pid"; else echo "$name: not running"; rc=1; fi
  done
  if [ $rc = 0 ]; then
    export SLURM_CONF=$CONF
    sinfo 2>&1 || true
    squeue 2>&1 || true
  fi
  return $rc
}

# ---------------------------------------------------------------------------------------
case ${1:-} in
  -h | --help | help | "") usage; [ -n "${1:-}" ]; exit $? ;;
  start | stop | status)
    [ $# -ge 2 ] || die "usage: $PROG $1 DIR"
    cmd=$1; set_paths "$2"; shift 2
    case $cmd in
      start) cmd_start "$@" ;;
      stop) cmd_stop ;;
      status) cmd_status ;;
    esac
    ;;
  *) die "unknown command '$1' (start, stop, status; --help)" ;;
esac

#!/usr/bin/env bash
# What a sequence saves over one lpmbake process per frame (docs/farm.md): the smoke
# frames 1-3 of data/vdb under a 4096x2048 environment (rooftop_small.hdr resized with
# oiiotool), g = 0.6, baked (a) as one sequence and (b) as three separate runs, each
# three times; prints a markdown table of the medians and checks the outputs agree.
#   scripts/bench/sequence_reuse.sh [BUILD_DIR]
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
bin="${1:-$root/build}/baker/lpmbake"
work="$root/out/bench/sequence_reuse"
rm -rf "$work" && mkdir -p "$work/in"
for f in 1 2 3; do cp "$root/data/vdb/smoke_seq.000$f.vdb" "$work/in/smoke.000$f.vdb"; done
oiiotool "$root/data/env/rooftop_small.hdr" --resize 4096x2048 -o "$work/sky4k.exr"
common=(--env "$work/sky4k.exr" --g 0.6 --threads 2 -q)
now() { date +%s.%N; }
median() { sort -g | sed -n 2p; }
seq_t=(); sep_t=()
for rep in 1 2 3; do
  t0=$(now)
  "$bin" "$work/in/smoke.####.vdb" --frames 1-3 "${common[@]}" -o "$work/seq.####.vdb"
  t1=$(now)
  for f in 1 2 3; do "$bin" "$work/in/smoke.000$f.vdb" "${common[@]}" -o "$work/sep.000$f.vdb"; done
  t2=$(now)
  seq_t+=("$(echo "$t1 - $t0" | bc -l)"); sep_t+=("$(echo "$t2 - $t1" | bc -l)")
done
for f in 1 2 3; do
  a=$("$bin" info --digest "$work/seq.000$f.vdb"); b=$("$bin" info --digest "$work/sep.000$f.vdb")
  [ "$a" = "$b" ] || { echo "sequence_reuse: frame $f differs ($a vs $b)" >&2; exit 1; }
done
s=$(printf '%s\n' "${seq_t[@]}" | median); p=$(printf '%s\n' "${sep_t[@]}" | median)
echo "| 3 smoke frames, 4096x2048 environment, g = 0.6, 2 threads | seconds (median of 3) |"
echo "|---|---|"
printf '| one sequence (environment read and binned once) | %.2f |\n' "$s"
printf '| three separate lpmbake runs | %.2f |\n' "$p"
printf '| saved per frame | %.2f |\n' "$(echo "($p - $s) / 3" | bc -l)"
echo "(outputs of both ways have equal content digests)"

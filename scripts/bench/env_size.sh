#!/usr/bin/env bash
# Time and memory of a bake against the environment map's size (docs/performance.md,
# "Session 31"). Production skies are 4K to 16K lat-longs; the bundled one is 300x150.
# Makes half-float ZIP EXR skies of 2048x1024, 4096x2048 and 8192x4096 from
# data/env/rooftop_small.hdr (oiiotool, Debian's openimageio-tools) and bakes one volume
# with each and with the bundled sky, each bake a separate process, interleaved with
# --original's when given. This build runs three ways (docs/image_cache.md): `off`
# (LPMBAKE_IMAGE_CACHE=off: the helper decodes, as for a sky seen once), `miss` (an empty
# cache: decodes, then stores the decoded image), `hit` (the next process: reads it).
#   scripts/bench/env_size.sh [--reps N] [--original LPMBAKE] VOLUME.vdb [bake args...]
# Prints a markdown table: the bake's environment stage (waiting for the helper's decode,
# then checks, colour conversion and the map), solve (which bins the map), total, the
# peak RSS of lpmbake and the helper it waits for (/usr/bin/time: the larger of the two;
# lpmbake's own is the stats JSON's peak_rss_mib), and the content digest. Skies go to out/bench/env/.
set -euo pipefail
cd "$(dirname "$0")/../.."
reps=1; original=""
while [ "${1:-}" = --reps ] || [ "${1:-}" = --original ]; do
  if [ "$1" = --reps ]; then reps=$2; else original=$2; fi
  shift 2
done
vdb=${1:?usage: env_size.sh [--reps N] [--original LPMBAKE] VOLUME.vdb [bake args...]}; shift
command -v oiiotool >/dev/null || { echo "env_size.sh: oiiotool not found (apt-get install openimageio-tools)" >&2; exit 2; }
[ -x build/baker/lpmbake ] || bash scripts/build.sh >/dev/null
dir=out/bench/env; mkdir -p "$dir"
skies=(data/env/rooftop_small.hdr)
for size in 2048x1024 4096x2048 8192x4096; do
  sky=$dir/rooftop_$size.exr
  [ -s "$sky" ] || oiiotool data/env/rooftop_small.hdr --resize "$size" -d half --compression zip -o "$sky"
  skies+=("$sky")
done
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
modes=(this:off this:miss this:hit)
[ -z "$original" ] || modes+=(original:off)
echo "| sky | lpmbake (cache) | environment s | solve s | total s | peak RSS MiB | lpmbake's own MiB | digest |"
echo "|---|---|---|---|---|---|---|---|"
for sky in "${skies[@]}"; do
  for ((i = 1; i <= reps; ++i)); do
    for mode in "${modes[@]}"; do
      name=${mode%%:*}; cache=${mode#*:}
      b=$([ "$name" = this ] && echo build/baker/lpmbake || echo "$original")
      cachedir=off
      if [ "$cache" != off ]; then cachedir=$out/cache; fi
      if [ "$cache" = miss ]; then rm -rf "$out/cache"; fi
      LPMBAKE_IMAGE_CACHE=$cachedir /usr/bin/time -f "%M" -o "$out/rss" "$b" "$vdb" --env "$sky" "$@" --stats "$out/s.json" -o "$out/b.vdb" \
        >/dev/null 2>"$out/err" || { cat "$out/err" >&2; exit 1; }
      digest=$("$b" info --digest "$out/b.vdb")
      python3 - "$out/s.json" "$(tail -1 "$out/rss")" "$sky" "$name ($cache)" "$digest" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
t = s["timings_s"]
sky = sys.argv[3].rsplit("/", 1)[-1]
print(f"| {sky} | {sys.argv[4]} | {t['environment']:.2f} | {t['solve']:.2f} | {t['total']:.2f} | "
      f"{int(sys.argv[2]) / 1024:.0f} | {s['peak_rss_mib']:.0f} | {sys.argv[5]} |")
PY
      rm -f "$out/b.vdb"
    done
  done
done

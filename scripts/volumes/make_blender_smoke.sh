#!/usr/bin/env bash
# Simulates a smoke (or fire) plume with Debian's Blender (Mantaflow, headless) and
# leaves its OpenVDB frames as OUT_DIR/smoke.NNNN.vdb (density, temperature, flame,
# velocity; Blender's Z-up). Needs the `blender` package (installed when missing).
#   scripts/volumes/make_blender_smoke.sh OUT_DIR [--res 128] [--end 30] [--fire]
# Cost on this 2-core machine: resolution 224, 60 frames (the ~1M-active-voxel smoke of
# the benchmarks, scripts/bench/scale.sh --mantaflow: frame 60 holds 983,564 active voxels
# in a 98 x 110 x 215 box) took 15 minutes; resolution 96, 40 frames about one.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
out="${1:?usage: make_blender_smoke.sh OUT_DIR [--res N] [--end F] [--fire]}"; shift
if ! command -v blender >/dev/null; then
  SUDO=""; [ "$(id -u)" = 0 ] || SUDO=sudo
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends blender
fi
mkdir -p "$out"
cache="$(mktemp -d "$out/.mantaflow.XXXXXX")"
trap 'rm -rf "$cache"' EXIT
blender -b --factory-startup --python "$here/blender_smoke.py" -- --out "$cache" "$@" > "$cache.log" 2>&1 || {
  tail -20 "$cache.log" >&2; rm -f "$cache.log"; echo "make_blender_smoke: blender failed" >&2; exit 1; }
rm -f "$cache.log"
n=0
for f in "$cache"/data/fluid_data_*.vdb; do
  [ -e "$f" ] || continue
  frame=$(basename "$f" .vdb); frame=${frame##*_}
  mv "$f" "$out/smoke.$frame.vdb"; n=$((n + 1))
done
[ "$n" -gt 0 ] || { echo "make_blender_smoke: no VDB frames were written" >&2; exit 1; }
echo "make_blender_smoke: $n frames in $out (smoke.NNNN.vdb)"

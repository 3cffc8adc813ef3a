#!/usr/bin/env bash
# Builds and runs the benchmarks; writes markdown tables to out/bench/.
#   scripts/bench/run.sh [--quick]
# Full run on 2 cores: about 55 minutes (the thick-media table alone ~20, the furnace ~10).
set -euo pipefail
cd "$(dirname "$0")/../.."
bash scripts/build.sh >/dev/null
mkdir -p out/bench
quick=""; max=64
if [ "${1:-}" = "--quick" ]; then quick="--quick"; max=32; fi
echo "== VDB read: layout walk overhead"; ./build/scripts/bench/lpm_bench_vdb_read --n "$((max * 4))" | tee out/bench/vdb_read.md
echo "== solver speed"; ./build/scripts/bench/lpm_bench_speed "$max" | tee out/bench/speed.md
echo "== whole bakes against the active voxels"; bash scripts/bench/scale.sh $quick | tee out/bench/scale.md
echo "== accuracy vs time"; ./build/scripts/bench/lpm_bench_accuracy $quick | tee out/bench/accuracy.md
if [ -z "$quick" ]; then
  echo "== white furnace, GMRES vs plain iteration"; ./build/scripts/bench/lpm_bench_furnace | tee out/bench/furnace.md
fi
echo "== optically thick media"; ./build/scripts/bench/lpm_bench_thick $quick | tee out/bench/thick_media.md
if [ -z "$quick" ]; then
  echo "== forward peaks (sky + sun, 32^3)"; ./build/scripts/bench/lpm_bench_forward_peak | tee out/bench/forward_peak.md
  echo "== forward peaks (sky only, 16^3)"
  ./build/scripts/bench/lpm_bench_forward_peak --n 16 --sky-only | tee out/bench/forward_peak_sky.md
fi

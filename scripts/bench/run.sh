#!/usr/bin/env bash
# Builds and runs the benchmarks; writes markdown tables to out/bench/.
#   scripts/bench/run.sh [--quick]
set -euo pipefail
cd "$(dirname "$0")/../.."
bash scripts/build.sh >/dev/null
mkdir -p out/bench
quick=""; max=64
if [ "${1:-}" = "--quick" ]; then quick="--quick"; max=32; fi
echo "== solver speed"; ./build/scripts/bench/lpm_bench_speed "$max" | tee out/bench/speed.md
echo "== accuracy vs time"; ./build/scripts/bench/lpm_bench_accuracy $quick | tee out/bench/accuracy.md

#!/usr/bin/env bash
# Builds the whole project with AddressSanitizer + UBSan (build-asan/) and runs every test.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install_deps.sh
cmake -S . -B build-asan -DCMAKE_BUILD_TYPE=RelWithDebInfo -DLPM_SANITIZE=ON -DLPM_BUILD_BENCH=OFF >/dev/null
cmake --build build-asan -j"${JOBS:-2}"
export ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
export LSAN_OPTIONS=suppressions=$PWD/scripts/lsan.supp
# The farm tests (label farm) drive the release lpmbake through Slurm in the plain run;
# the sequence code they call is covered here by tests/baker/sequence_test.
ctest --test-dir build-asan --output-on-failure -j"${JOBS:-2}" --timeout 1500 -LE farm

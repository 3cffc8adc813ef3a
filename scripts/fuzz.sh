#!/usr/bin/env bash
# Builds the libFuzzer targets with clang + ASan/UBSan and runs each for a fixed time.
#   scripts/fuzz.sh [seconds per target, default 300]
# Seeds: the files in data/ (and findings kept in tests/fuzz/regressions/). New crashing
# inputs land in out/fuzz/<target>/ ; copy them to tests/fuzz/regressions/ once fixed.
# Fork mode with -ignore_ooms: OpenVDB itself allocates whatever a corrupt length field
# asks for while parsing headers; the release reader caps its address space around that
# (vdb_io/vdb_file.cpp), which cannot run under ASan, so OOMs are logged, not fatal.
set -euo pipefail
cd "$(dirname "$0")/.."
secs=${1:-300}
bash scripts/install_deps.sh
command -v clang++ >/dev/null || apt-get install -y -qq clang
cmake -S . -B build-fuzz -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_COMPILER=clang++ -DLPM_FUZZ=ON \
      -DLPM_BUILD_TESTS=OFF -DLPM_BUILD_BENCH=OFF >/dev/null
cmake --build build-fuzz -j"${JOBS:-2}" --target fuzz_vdb_reader fuzz_env_reader
mkdir -p out/fuzz/vdb out/fuzz/env out/fuzz/corpus_vdb out/fuzz/corpus_env
cp data/vdb/*.vdb out/fuzz/corpus_vdb/
for f in data/env/*; do printf '\x00' | cat - "$f" > "out/fuzz/corpus_env/$(basename "$f").seed"; done
for f in data/env/*.hdr; do printf '\x01' | cat - "$f" > "out/fuzz/corpus_env/$(basename "$f").hdrseed"; done
[ -d tests/fuzz/regressions ] && cp tests/fuzz/regressions/* out/fuzz/corpus_vdb/ 2>/dev/null || true
export ASAN_OPTIONS=detect_leaks=0:allocator_may_return_null=1
./build-fuzz/tests/fuzz/fuzz_vdb_reader out/fuzz/corpus_vdb -max_total_time="$secs" -rss_limit_mb=4096 \
    -timeout=30 -artifact_prefix=out/fuzz/vdb/ -print_final_stats=1 -fork=1 -ignore_ooms=1
./build-fuzz/tests/fuzz/fuzz_env_reader out/fuzz/corpus_env -max_total_time="$secs" -rss_limit_mb=4096 \
    -timeout=30 -artifact_prefix=out/fuzz/env/ -print_final_stats=1 -fork=1 -ignore_ooms=1

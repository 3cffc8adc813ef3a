#!/usr/bin/env bash
# Builds the libFuzzer targets with clang + ASan/UBSan and runs each for a fixed time.
#   scripts/fuzz.sh [seconds for the VDB target, default 300] [seconds for the env target, default the same]
# Seeds: the files in data/ (and findings kept in tests/fuzz/regressions/). New crashing
# inputs land in out/fuzz/<target>/ ; copy them to tests/fuzz/regressions/ once fixed.
# Fork mode with -ignore_ooms and -ignore_crashes: a long unattended campaign keeps going
# after a finding; every crash or OOM input is saved under out/fuzz/<target>/ and the
# script lists them at the end (exit status 1 when there are any).
set -euo pipefail
cd "$(dirname "$0")/.."
secs=${1:-300}
secs_env=${2:-$secs}
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
stamp=$(mktemp)
./build-fuzz/tests/fuzz/fuzz_vdb_reader out/fuzz/corpus_vdb -max_total_time="$secs" -rss_limit_mb=4096 \
    -timeout=30 -artifact_prefix=out/fuzz/vdb/ -print_final_stats=1 -fork=1 -ignore_ooms=1 -ignore_crashes=1
./build-fuzz/tests/fuzz/fuzz_env_reader out/fuzz/corpus_env -max_total_time="$secs_env" -rss_limit_mb=4096 \
    -timeout=30 -artifact_prefix=out/fuzz/env/ -print_final_stats=1 -fork=1 -ignore_ooms=1 -ignore_crashes=1
findings=$(find out/fuzz/vdb out/fuzz/env -type f -newer "$stamp" | sort)
rm -f "$stamp"
if [ -n "$findings" ]; then
    echo "fuzz: findings (inputs saved):"; echo "$findings"; exit 1
fi
echo "fuzz: no findings"

#!/usr/bin/env bash
# Install dependencies (Debian 12), build, and run the whole test suite with ctest.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install_deps.sh --test
bash scripts/build.sh
JOBS=${JOBS:-2}
ctest --test-dir build --output-on-failure -j"$JOBS"

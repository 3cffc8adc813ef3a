#!/usr/bin/env bash
# Configure and build lpmbake (Release, ccache when present) into ./build.
#   scripts/build.sh [extra cmake args...]
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install_deps.sh
JOBS=${JOBS:-2}
# LPM_WERROR=1 (CI): compiler warnings are errors.
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release -DLPM_WERROR="${LPM_WERROR:-OFF}" "$@"
cmake --build build -j"$JOBS"

#!/usr/bin/env bash
# Install lpmbake's build and test dependencies on Debian 12 (run as root, or with sudo available).
#   scripts/install_deps.sh          what building and the unit tests need
#   scripts/install_deps.sh --test   also what the whole suite and CI's checks need: Debian's
#                                    blender (tests/blender), clang-format and clang-tidy
#                                    (scripts/lint.sh), python3-matplotlib (tests/accuracy)
# Quirks from docs (ecosystem notes): libopenvdb-dev needs libboost-iostreams-dev for its CMake module.
set -euo pipefail
PKGS=(build-essential cmake ccache pkg-config
      libopenvdb-dev libboost-iostreams-dev libtbb-dev
      libopenimageio-dev openimageio-tools libopencolorio-dev
      libcli11-dev libgtest-dev libbenchmark-dev   # Google Benchmark: scripts/bench/sweep_kernel.cpp
      nlohmann-json3-dev                           # sidecar and stats JSON
      libxxhash-dev                                # the decoded-image cache (vdb_io/image_cache.h)
      slurm-wlm munge procps)   # test only: tests/farm/slurm_test.sh runs a one-node Slurm cluster
if [ "${1:-}" = "--test" ]; then
  PKGS+=(blender               # tests/blender: the Blender import script against lpmbake render
         clang-format clang-tidy   # scripts/lint.sh
         python3-matplotlib)       # scripts/accuracy/plot.py (the study's smoke test)
fi
missing=()
for p in "${PKGS[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "install_deps: all packages present"; exit 0
fi
SUDO=""
if [ "$(id -u)" != 0 ]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"

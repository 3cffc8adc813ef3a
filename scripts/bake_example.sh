#!/usr/bin/env bash
# Bakes the bundled example (data/vdb/torus01.vdb under data/env/rooftop_small.hdr plus a
# sun) and renders PNG/EXR previews into out/. Installs missing Debian packages first
# (scripts/install_deps.sh), then configures and builds with 2 jobs.
# Usage: scripts/bake_example.sh [extra lpmbake bake options...]
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"

"$root/scripts/install_deps.sh"
cmake -S . -B build >/dev/null
cmake --build build -j2 --target lpmbake
bin="$root/build/baker/lpmbake"
mkdir -p out

# Sun toward (0.3, 0.8, 0.5): up, to the right (+X) and toward the default camera (+Z).
"$bin" data/vdb/torus01.vdb --grid voxel_fog_density \
  --env data/env/rooftop_small.hdr \
  --sun 0.3,0.8,0.5 --sun-irradiance 3 --sun-angle 0.53 \
  --density-scale 0.04 --albedo 0.9 --g 0.5 --sh-order 2 \
  --stats out/torus01_stats.json \
  -o out/torus01_lit.vdb "$@"

"$bin" info out/torus01_lit.vdb > out/torus01_info.txt
# Default camera frames the volume from +Z, slightly above and to the right.
"$bin" render out/torus01_lit.vdb --env data/env/rooftop_small.hdr --fov-y 40 --size 480x360 -o out/torus01_preview.png
"$bin" render out/torus01_lit.vdb --env data/env/rooftop_small.hdr --fov-y 40 --size 480x360 -o out/torus01_preview.exr
echo "bake_example: wrote out/torus01_lit.vdb, out/torus01_preview.png/.exr, out/torus01_stats.json, out/torus01_info.txt"

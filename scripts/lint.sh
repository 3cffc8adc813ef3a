#!/usr/bin/env bash
# Style and static checks CI runs (.ci/run): clang-format (.clang-format) on every C++
# source, and clang-tidy (.clang-tidy: function size, shadowing, bug-prone patterns) on the
# product's sources (core/, vdb_io/, baker/) with the compile commands of ./build.
#   scripts/lint.sh           check (exit 1 on any finding)
#   scripts/lint.sh --fix     rewrite the files clang-format would change
set -euo pipefail
cd "$(dirname "$0")/.."
mapfile -t all < <(git ls-files '*.cpp' '*.h')
if [ "${1:-}" = "--fix" ]; then
  clang-format -i "${all[@]}"
  exit 0
fi
status=0
if ! clang-format --dry-run --Werror "${all[@]}" 2>/tmp/lpm_format.log; then
  grep -m 20 "error:" /tmp/lpm_format.log || true
  echo "lint: clang-format: $(grep -c 'error:' /tmp/lpm_format.log) place(s) differ (scripts/lint.sh --fix)" >&2
  status=1
fi
[ -f build/compile_commands.json ] || { echo "lint: no build/compile_commands.json (run scripts/build.sh)" >&2; exit 1; }
mapfile -t product < <(git ls-files 'core/*.cpp' 'vdb_io/*.cpp' 'baker/*.cpp')
# -j: one clang-tidy per core; each file's findings printed together.
if ! printf '%s\n' "${product[@]}" | xargs -P "${JOBS:-2}" -n 4 clang-tidy -p build --quiet >/tmp/lpm_tidy.log 2>&1; then
  grep -E "(error|warning):" /tmp/lpm_tidy.log | sort -u | head -40
  echo "lint: clang-tidy found problems (full log /tmp/lpm_tidy.log)" >&2
  status=1
fi
[ $status -eq 0 ] && echo "lint: clang-format and clang-tidy clean"
exit $status

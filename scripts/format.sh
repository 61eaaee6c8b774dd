#!/usr/bin/env bash
# clang-format over the project's C++ (style in .clang-format).
#   bash scripts/format.sh           reformat in place
#   bash scripts/format.sh --check   list files that are not formatted and fail (what CI runs)
set -euo pipefail
cd "$(dirname "$0")/.."
mapfile -t files < <(git ls-files '*.hpp' '*.cpp' '*.h')
if [ "${1:-}" = "--check" ]; then
  bad=()
  for f in "${files[@]}"; do
    clang-format --dry-run --Werror "$f" > /dev/null 2>&1 || bad+=("$f")
  done
  if [ ${#bad[@]} -ne 0 ]; then
    echo "[format] ${#bad[@]} of ${#files[@]} files are not clang-formatted (run: bash scripts/format.sh):"
    printf '  %s\n' "${bad[@]}"
    exit 1
  fi
  echo "[format] ${#files[@]} files clang-formatted"
else
  clang-format -i "${files[@]}"
  echo "[format] formatted ${#files[@]} files"
fi

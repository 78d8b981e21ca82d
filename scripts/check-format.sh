#!/usr/bin/env bash
# Checks that every C++ source in the repository is formatted by the project's
# .clang-format (Debian 12's clang-format 14: another version may format differently).
# Prints the files that differ and exits 1; run `scripts/check-format.sh --fix` to format
# them in place.
set -euo pipefail
source "$(dirname "$0")/common.sh"
cd "$STEREOD_ROOT"
ensure_packages check-format clang-format

mapfile -t files < <(git ls-files '*.cpp' '*.hpp' '*.h')
if [ "${1:-}" = "--fix" ]; then
  clang-format -i "${files[@]}"
  exit 0
fi
unformatted=()
for f in "${files[@]}"; do
  if ! clang-format --dry-run -Werror "$f" >/dev/null 2>&1; then unformatted+=("$f"); fi
done
if [ ${#unformatted[@]} -gt 0 ]; then
  echo "check-format: ${#unformatted[@]} file(s) not formatted by .clang-format:" >&2
  printf '  %s\n' "${unformatted[@]}" >&2
  echo "check-format: run scripts/check-format.sh --fix" >&2
  exit 1
fi
echo "check-format: ${#files[@]} files formatted"

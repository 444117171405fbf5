#!/usr/bin/env bash
# tests/format/check.sh SOURCE_DIR: every C, C++ and header file of the repository is
# formatted as .clang-format says (clang-format from Debian, the version CI installs:
# setup.sh test). Fails listing the files that are not, with the command that formats
# them; skips (exit 77) where clang-format is not installed, except under CI (CI set),
# where a missing formatter is a failure.
set -euo pipefail
cd "$1"
FORMAT=${CLANG_FORMAT:-clang-format}
if ! command -v "$FORMAT" >/dev/null; then
    echo "format: $FORMAT not installed (apt-get install clang-format)"
    [ -n "${CI:-}" ] && exit 1
    exit 77
fi
if git rev-parse --is-inside-work-tree >/dev/null 2>&1; then
    mapfile -t files < <(git ls-files '*.c' '*.h' '*.cpp')
else
    mapfile -t files < <(find . \( -name 'build*' -o -name out -o -name .git \) -prune -o \
        \( -name '*.c' -o -name '*.h' -o -name '*.cpp' \) -print | sed 's|^\./||' | sort)
fi
bad=()
for f in "${files[@]}"; do
    [ -f "$f" ] || continue # deleted in the working tree
    if ! "$FORMAT" --dry-run --Werror "$f" >/dev/null 2>&1; then
        bad+=("$f")
    fi
done
echo "format: ${#files[@]} files checked with $("$FORMAT" --version | head -1)"
if [ "${#bad[@]}" -gt 0 ]; then
    printf 'format: not formatted: %s\n' "${bad[@]}"
    echo "format: run  clang-format -i ${bad[*]}"
    exit 1
fi

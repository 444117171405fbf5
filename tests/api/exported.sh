#!/usr/bin/env bash
# exported.sh LIBRARY LIST: the mcp_* symbols that the shared library exports (nm -D
# --defined-only) must be exactly LIST (tests/api/exported.txt), so that every change
# to the ABI is deliberate (docs/library.md, "Exported symbols"). On a difference it
# prints the diff (- listed but not exported, + exported but not listed) and fails.
# It also fails on any exported symbol outside mcp_*.
# exported.sh LIBRARY LIST --update rewrites LIST instead.
set -euo pipefail
lib=$1 list=$2
actual=$(nm -D --defined-only "$lib" | awk '$3 ~ /^mcp_/ {print $3}' | LC_ALL=C sort -u)
if [ -z "$actual" ]; then
    echo "exported.sh: $lib exports no mcp_* symbol (nm missing, or the wrong file?)" >&2
    exit 1
fi
# and nothing but mcp_* (cmake/exported.map): not, for one, OpenMP's names for critical
# sections
others=$(nm -D --defined-only "$lib" | awk '$3 !~ /^mcp_/ {print $3}' | LC_ALL=C sort -u)
if [ -n "$others" ]; then
    echo "exported.sh: $lib exports symbols outside mcp_*: $(echo $others)" \
         "(cmake/exported.map keeps them local)" >&2
    exit 1
fi
if [ "${3:-}" = --update ]; then
    printf '%s\n' "$actual" > "$list"
    echo "exported.sh: wrote $(wc -l < "$list") symbols to $list"
    exit 0
fi
if ! diff -u --label "$list" --label "$lib (nm -D)" "$list" <(printf '%s\n' "$actual"); then
    echo "exported.sh: $lib exports other mcp_* symbols than $list lists. If the change" \
         "is meant, update the list (tests/api/exported.sh $lib $list --update)" \
         "and the ABI version (MCP_ABI_VERSION in CMakeLists.txt) when a symbol went" \
         "away or changed" >&2
    exit 1
fi
echo "exported.sh: $(printf '%s\n' "$actual" | wc -l) mcp_* symbols, as listed"

#!/usr/bin/env bash
# umbrella.sh UMBRELLA INCLUDE_DIR: <mcpost/mcpost.h> includes every public header,
# i.e. every header the build mirrors into INCLUDE_DIR/mcpost (the installed set,
# CMakeLists.txt's MCP_PUBLIC_HEADERS), and no other; internal headers (exr_zip.h,
# fastpow.h, *internal.h, *_shim.h) are not among them.
set -euo pipefail
umbrella=$1 dir=$2/mcpost
included=$(sed -n 's|^#include <mcpost/\([a-z_]*\.h\)>.*|\1|p' "$umbrella" | LC_ALL=C sort)
public=$(cd "$dir" && ls -- *.h | grep -vx mcpost.h | LC_ALL=C sort)
if ! diff -u --label "includes of $umbrella" --label "headers in $dir" \
        <(printf '%s\n' "$included") <(printf '%s\n' "$public"); then
    echo "umbrella.sh: $umbrella and the public headers differ" >&2
    exit 1
fi
internal=$(printf '%s\n' "$public" | grep -E '^(exr_zip|fastpow)\.h$|(internal|_shim)\.h$' || true)
if [ -n "$internal" ]; then
    echo "umbrella.sh: internal headers are public: $internal" >&2
    exit 1
fi
echo "umbrella.sh: mcpost.h includes the $(printf '%s\n' "$public" | wc -l) public headers"

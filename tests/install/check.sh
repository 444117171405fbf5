#!/usr/bin/env bash
# check.sh BUILD_DIR: installs mcpost into a scratch prefix and builds two consumers
# against it, one with find_package(mcpost), one with pkg-config; runs both.
set -euo pipefail
build=$(cd "$1" && pwd)
src=$(cd "$(dirname "$0")" && pwd)
prefix=$build/test-install/prefix
work=$build/test-install/work
rm -rf "$build/test-install"
mkdir -p "$work"
cmake --install "$build" --prefix "$prefix" >/dev/null
# the public headers and only they (CMakeLists.txt's MCP_PUBLIC_HEADERS, mirrored into
# the build tree): no internal one (exr_zip.h, fastpow.h, *internal.h) is installed
diff <(ls "$prefix/include/mcpost") <(ls "$build/include/mcpost")
cmake -S "$src/consumer" -B "$work/cmake" -DCMAKE_PREFIX_PATH="$prefix" >/dev/null
cmake --build "$work/cmake" >/dev/null
"$work/cmake/consumer" "$work"
libdir=$(dirname "$(find "$prefix" -name mcpost.pc)")
export PKG_CONFIG_PATH=$libdir
cc -std=c11 "$src/consumer/consumer.c" -o "$work/pc-consumer" $(pkg-config --cflags --libs mcpost) \
    -Wl,-rpath,"$(pkg-config --variable=libdir mcpost)"
"$work/pc-consumer" "$work"
test -s "$work/consumer.png"
# the tool, installed with the procedural renderer beside it: an adaptive loop whose
# render command names mcpost-procedural without a path finds it there (cli/main.c),
# with a PATH that holds neither the build nor the prefix
test -x "$prefix/bin/mcpost-procedural"
PATH=/usr/bin:/bin "$prefix/bin/mcpost" adaptive --size 16x16 --budget 8 \
    --spp-per-iteration 4 --denoiser gauss --quiet -o "$work/adaptive" \
    --render 'mcpost-procedural --sample-counts {counts} --pass {pass} --seed {seed} -o {output}'
test -s "$work/adaptive/accumulated.exr"
# the Python module, when it was built: installed under the prefix, it imports from
# there and finds libmcpost and the U-Net's weights (share/mcpost) relative to itself
python=$(sed -n 's/^Python3_EXECUTABLE:[A-Z]*=//p' "$build/CMakeCache.txt")
if compgen -G "$build/python/mcpost*.so" >/dev/null; then
    module=$(find "$prefix" -name 'mcpost*.so' -path '*-packages/*')
    test -n "$module"
    (cd "$work" && PYTHONPATH=$(dirname "$module") "$python" -c '
import sys, mcpost, numpy as np
assert mcpost.__file__.startswith(sys.argv[1]), mcpost.__file__
rng = np.random.default_rng(1)
c, a, n = (rng.random((32, 32, 3), dtype=np.float32) for _ in range(3))
assert mcpost.denoise(c, albedo=a, normal=n, denoiser="unet").shape == (32, 32, 3)
' "$prefix")
    echo "install check: the Python module imports from $(dirname "$module")"
fi
echo "install check: find_package and pkg-config consumers ran; the installed tool found mcpost-procedural beside it"

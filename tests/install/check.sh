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
cmake -S "$src/consumer" -B "$work/cmake" -DCMAKE_PREFIX_PATH="$prefix" >/dev/null
cmake --build "$work/cmake" >/dev/null
"$work/cmake/consumer" "$work"
libdir=$(dirname "$(find "$prefix" -name mcpost.pc)")
export PKG_CONFIG_PATH=$libdir
cc -std=c11 "$src/consumer/consumer.c" -o "$work/pc-consumer" $(pkg-config --cflags --libs mcpost) \
    -Wl,-rpath,"$(pkg-config --variable=libdir mcpost)"
"$work/pc-consumer" "$work"
test -s "$work/consumer.png"
echo "install check: find_package and pkg-config consumers ran"

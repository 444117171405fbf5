#!/usr/bin/env bash
# setup.sh: everything from a fresh Debian 12 machine to results.
#
#   ./setup.sh demo    install what is missing, build, run the frame job samples/jobs/
#                      shot.yaml, the Python sample and samples/jobs/demo.yaml (and,
#                      with chromium installed, screenshot its page: out/demo/report.png)
#   ./setup.sh test    install what is missing, build (plain and ASan+UBSan), run all tests,
#                      build everything with clang, run the SIMD modules' tests once
#                      more with their scalar code, and run each fuzz target (tests/fuzz)
#                      for a short while
#   ./setup.sh build   install what is missing and build only (demo and build also make
#                      `python3 -c "import mcpost"` find build/python: docs/python.md)
#
# Builds go to build/ (build-asan/ for the sanitizer build, build-clang/ for clang,
# build-scalar/ for the one with MCP_NO_SIMD, whose SSE2 loops fall back to their plain
# C, build-fuzz/ for the libFuzzer targets), all with warnings as errors (MCPOST_WERROR).
# Set MCPOST_NO_ASAN=1, MCPOST_NO_CLANG=1, MCPOST_NO_SCALAR=1 or MCPOST_NO_FUZZ=1 to skip
# those in `test`, MCPOST_FUZZ_SECONDS to fuzz each target longer or shorter than 60 s,
# MCPOST_JOBS to change the parallelism.
set -euo pipefail
cd "$(dirname "$0")"

# Debian 12 packages that mcpost needs (README.md lists what each is for; the library
# links none of the bench-only ones: libopenblas-dev and libdnnl-dev are bench_unet's
# baselines).
PACKAGES=(gcc g++ make cmake pkg-config
          libopenexr-dev libopenimageio-dev libopencv-core-dev libopencv-imgproc-dev
          libyaml-dev libcjson-dev libcmocka-dev libopenblas-dev libdnnl-dev libpng-dev
          libdeflate-dev python3-dev python3-numpy python3-pytest python3-matplotlib
          python3-pip python3-setuptools python3-wheel python3-venv)
JOBS=${MCPOST_JOBS:-$(nproc)}

install_packages() { # install_packages [PACKAGE...]: PACKAGES when none are named
    local missing=() wanted=("$@")
    [ ${#wanted[@]} -gt 0 ] || wanted=("${PACKAGES[@]}")
    for p in "${wanted[@]}"; do
        dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" ||
            missing+=("$p")
    done
    [ ${#missing[@]} -eq 0 ] && return 0
    echo "setup: installing ${missing[*]}" >&2
    local sudo=""
    [ "$(id -u)" -eq 0 ] || sudo="sudo"
    $sudo apt-get update -q
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -q --no-install-recommends \
        "${missing[@]}"
}

# The Python module is built for Debian's interpreter, the one python3-numpy is for
# (a python3 earlier on PATH, e.g. pyenv's, may have no numpy).
PYTHON=/usr/bin/python3

build() { # build DIR [cmake args...]: warnings are errors here (MCPOST_WERROR)
    # cmake's and the compiler's lines go to DIR/setup-build.log, so that the demo
    # prints mcpost's lines only: one line says when something was built, and a
    # failed build shows the end of the log (and where the rest is)
    local dir=$1 log
    shift
    log=$dir/setup-build.log
    [ -f "$dir/CMakeCache.txt" ] ||
        echo "setup: building $dir (the first time takes minutes; cmake's output: $log)" >&2
    mkdir -p "$dir"
    if ! { cmake -S . -B "$dir" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DMCPOST_WERROR=ON \
               -DPython3_EXECUTABLE="$PYTHON" "$@" &&
               cmake --build "$dir" -j "$JOBS"; } >"$log" 2>&1; then
        tail -n 60 "$log" >&2
        echo "setup: building $dir failed; the whole log is $log" >&2
        exit 1
    fi
    if grep -q -E '^\[ *[0-9]+(%|/[0-9]+)\] (Building|Linking)' "$log"; then
        echo "setup: built $dir (cmake's output: $log)" >&2
    fi
}

link_python() { # lets `python3 -c "import mcpost"` find build/python: a .pth file in
    # the user's site-packages ($PYTHONUSERBASE), as `pip install --user -e` would do
    compgen -G "build/python/mcpost*.so" >/dev/null || return 0
    local site
    site=$("$PYTHON" -c 'import site; print(site.getusersitepackages())') || return 0
    # said once, when the link is made (a second demo prints mcpost's lines only)
    [ "$(cat "$site/mcpost-build.pth" 2>/dev/null)" != "$PWD/build/python" ] || return 0
    mkdir -p "$site" && echo "$PWD/build/python" >"$site/mcpost-build.pth"
    echo "setup: python3 finds the mcpost module in build/python ($site/mcpost-build.pth)" >&2
}

run_tests() { # run_tests DIR: a passing run leaves no scratch files in DIR/test-tmp
    # but the build of NVIDIA's FLIP tool (docs/testing.md), rebuilt only when older
    ctest --test-dir "$1" --output-on-failure -j "$JOBS"
    find "$1/test-tmp" -mindepth 1 -maxdepth 1 ! -name common_test_flip_stats \
        -exec rm -rf {} + 2>/dev/null || true
}

say_free_disk() { # a whole `./setup.sh test` peaks at 1.9 GB in the checkout (the
    # five builds, and up to 1 GB of test files at a time in build/test-tmp), and a
    # disk that fills fails tests at random ("No space left on device"): say how much
    # there is
    local free_kb
    free_kb=$(df -Pk . | awk 'NR == 2 { print $4 }')
    echo "setup: $((free_kb / 1024 / 1024)) GB free on the disk of $PWD" >&2
    [ "$free_kb" -ge $((3 * 1024 * 1024)) ] ||
        echo "setup: warning: the tests need about 3 GB free; expect 'No space left'" >&2
}

case "${1:-}" in
demo)
    install_packages
    build build
    link_python
    # what is not a stage: a shot of frames (run two at a time, then one report over
    # them; a second demo skips the frames already complete) and the Python module
    # (estimated against true error over a progressive render, as a figure)
    ./build/mcpost run samples/jobs/shot.yaml -j 2
    ./build/mcpost collect out/shot
    mkdir -p out/python
    PYTHONPATH=$PWD/build/python "$PYTHON" samples/python/error_vs_spp.py \
        -o out/python/error_vs_spp.png
    # every stage, every module: the report ends the demo
    ./build/mcpost run samples/jobs/demo.yaml
    # where Chromium is installed (setup.sh test installs it): the page checked in a
    # real browser and a screenshot of it, out/demo/report.png; the check's own lines
    # only when it fails (the demo prints mcpost's lines)
    if command -v chromium >/dev/null; then
        if ! check=$(tests/report/check_page.sh out/demo 1280 2>&1); then
            printf '%s\n' "$check" >&2
            echo "setup: report.html check failed" >&2
        fi
    fi
    ;;
test)
    say_free_disk
    install_packages
    # a one-node Slurm for tests/cli/slurm_frames.sh (frame jobs on a cluster)
    install_packages slurm-wlm munge
    # headless Chromium opens report.html in the test report/page_in_chromium
    install_packages chromium
    # the test format/clang_format checks every source file against .clang-format
    install_packages clang-format
    # Blender's Cycles renders a tiny .blend through tools/mcpost-cycles-render.py in
    # the test cli/cycles_render
    install_packages blender
    build build
    run_tests build
    if [ -z "${MCPOST_NO_ASAN:-}" ]; then
        build build-asan -DMCPOST_SANITIZE=ON -DMCPOST_BENCH=OFF
        ASAN_OPTIONS=detect_leaks=1:abort_on_error=1:intercept_tls_get_addr=0 \
            LSAN_OPTIONS=suppressions=$PWD/tests/lsan.supp:print_suppressions=0 \
            UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
            run_tests build-asan
    fi
    if [ -z "${MCPOST_NO_CLANG:-}" ]; then
        # clang builds everything warning-free too (its own warnings, -Werror), in the
        # Release configuration packagers use; the tests' numbers are gcc's, so of its
        # tests only the install test runs (find_package and pkg-config on a Release
        # install)
        install_packages clang libomp-dev
        CC=clang CXX=clang++ build build-clang -DCMAKE_BUILD_TYPE=Release -DMCPOST_BENCH=OFF
        ctest --test-dir build-clang --output-on-failure -R '^install/'
    fi
    if [ -z "${MCPOST_NO_SCALAR:-}" ]; then
        # the portable code behind the SSE2 loops (blend, perceptual, EXR zip) gives
        # the same results: their tests compare with plain reimplementations or with
        # OpenEXR Core's own decoder value for value
        build build-scalar -DCMAKE_C_FLAGS=-DMCP_NO_SIMD -DMCPOST_BENCH=OFF
        ctest --test-dir build-scalar --output-on-failure -j "$JOBS" \
            -R '^(blend|perceptual)/|^common/test_exr$'
    fi
    if [ -z "${MCPOST_NO_FUZZ:-}" ]; then
        # every reader and parser under libFuzzer with ASan+UBSan, from the committed
        # seeds and regression inputs, MCPOST_FUZZ_SECONDS each [60]; any finding (a
        # crash, a sanitizer report, a leak, a broken error message) fails the run.
        # The plain and ASan builds above replay the same corpora without libFuzzer.
        install_packages clang libomp-dev libfuzzer-14-dev
        CC=clang CXX=clang++ build build-fuzz -DMCPOST_FUZZ=ON -DMCPOST_TESTS=OFF \
            -DMCPOST_BENCH=OFF
        MCPOST_FUZZ_JOBS=$JOBS tests/fuzz/run.sh build-fuzz "${MCPOST_FUZZ_SECONDS:-60}"
    fi
    ;;
build)
    install_packages
    build build
    link_python
    ;;
*)
    echo "usage: ./setup.sh demo|test|build" >&2
    exit 2
    ;;
esac

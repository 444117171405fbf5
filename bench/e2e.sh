#!/usr/bin/env bash
# bench/e2e.sh: whole commands as a user runs them, timed as processes (start, I/O,
# plug-ins and reports included), median and range of N runs, each beside its target.
# Run through `bench/run e2e`. With NVIDIA's FLIP tool available (FLIP=path/to/flip, or
# `flip` on PATH, or FLIP_SRC=a checkout of github.com/NVlabs/flip to build with
# g++ -O3 -fopenmp) its times on the same inputs are printed in the same run.
#
#   bench/e2e.sh [RUNS]      RUNS per command [5]; OMP_NUM_THREADS [2]
set -euo pipefail
cd "$(dirname "$0")/.."
RUNS=${1:-5}
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-2}
MCPOST=$PWD/build/mcpost
PROC=$PWD/build/mcpost-procedural
WORK=${TMPDIR:-/tmp}/mcpost-e2e
mkdir -p "$WORK"
cd "$WORK"

# ---- inputs (made once, kept in $WORK) ----
if [ ! -f hd_test.exr ]; then
    echo "e2e: rendering inputs in $WORK (once)" >&2
    "$PROC" --width 1920 --height 1080 --spp 4 --seed 1 -o hd_a >/dev/null
    "$PROC" --width 1920 --height 1080 --spp 16 --seed 2 -o hd_b >/dev/null
    mv hd_a_0000.exr hd_test.exr
    mv hd_b_0000.exr hd_ref.exr
    "$MCPOST" convert hd_test.exr hd_test.png --channels R,G,B >/dev/null
    "$MCPOST" convert hd_ref.exr hd_ref.png --channels R,G,B >/dev/null
    "$PROC" --width 512 --height 512 --spp 1 --seed 10 --realizations 4 -o cand >/dev/null
    "$PROC" --width 512 --height 512 --spp 64 --seed 99 -o ref512 >/dev/null
fi

# ---- timing ----
# bash's own clock (EPOCHREALTIME): forking `date` around a command would add
# milliseconds to it

# time_runs LABEL TARGET_S CMD...: RUNS timed runs after one warm-up; prints the
# median, min and max in seconds and whether the median meets TARGET_S ("-": none).
time_runs() {
    local label=$1 target=$2
    shift 2
    "$@" >/dev/null 2>&1 || { echo "e2e: '$label' failed: $*" >&2; return 1; }
    local times=()
    for _ in $(seq "$RUNS"); do
        local t0 t1
        t0=${EPOCHREALTIME/,/.}
        "$@" >/dev/null 2>&1
        t1=${EPOCHREALTIME/,/.}
        times+=("$(awk -v a="$t0" -v b="$t1" 'BEGIN { print b - a }')")
    done
    printf '%s\n' "${times[@]}" | sort -g | awk -v label="$label" -v target="$target" '
        { t[NR] = $1 }
        END {
            med = NR % 2 ? t[(NR + 1) / 2] : (t[NR / 2] + t[NR / 2 + 1]) / 2
            verdict = target == "-" ? "" : (med <= target ? "met" : "not met")
            printf "%-52s %7.3f s  [%.3f, %.3f]  target %-7s %s\n", label, med, t[1],
                   t[NR], target == "-" ? "-" : target " s", verdict
        }'
}

echo "whole processes, median of $RUNS, $OMP_NUM_THREADS threads ($(nproc) cores)"
flip_bin=${FLIP:-$(command -v flip || true)}
if [ -z "$flip_bin" ] && [ -n "${FLIP_SRC:-}" ]; then
    tool=$(find "$FLIP_SRC" -path '*cpp/tool/*.cpp' | head -1)
    if [ -n "$tool" ] && g++ -O3 -fopenmp -std=c++17 -I"$(dirname "$tool")/.." "$tool" \
        -o "$WORK/flip" 2>/dev/null; then
        flip_bin=$WORK/flip
    else
        echo "e2e: could not build NVIDIA's flip from $FLIP_SRC" >&2
    fi
fi

time_runs "mcpost --version" 0.010 "$MCPOST" --version
time_runs "metrics 1080p PNG pair, LDR-FLIP" 0.5 \
    "$MCPOST" metrics hd_test.png hd_ref.png --flip ldr --no-spectra
[ -n "$flip_bin" ] && time_runs "  NVIDIA flip, same pair, LDR" - \
    "$flip_bin" -r hd_ref.png -t hd_test.png -nerm -nexm
time_runs "metrics 1080p EXR pair, HDR-FLIP" 1.2 \
    "$MCPOST" metrics hd_test.exr hd_ref.exr --flip hdr --no-spectra
[ -n "$flip_bin" ] && time_runs "  NVIDIA flip, same pair, HDR" - \
    "$flip_bin" -r hd_ref.exr -t hd_test.exr -nerm -nexm
time_runs "perceptual vertical-iterative, 4 x 512², --ref" 0.4 \
    "$MCPOST" perceptual cand_000{0,1,2,3}.exr --surrogate reference --ref ref512_0000.exr \
    -o "$WORK/perc"
time_runs "estimate 1080p dump, gauss" 0.6 \
    "$MCPOST" estimate hd_test.exr --denoiser gauss -o "$WORK/est_gauss"
"$MCPOST" estimate hd_test.exr --denoiser gauss -o "$WORK/est_gauss" 2>/dev/null |
    sed -n 's/^time (ms): */  its steps (ms): /p'
# the same with the heap on 4 kB pages (one process: docs/conventions.md "Memory")
MCPOST_HUGE_PAGES=0 time_runs "  the same, MCPOST_HUGE_PAGES=0" - \
    "$MCPOST" estimate hd_test.exr --denoiser gauss -o "$WORK/est_gauss"
time_runs "estimate 1080p dump, nlm" - \
    "$MCPOST" estimate hd_test.exr --denoiser nlm -o "$WORK/est_nlm"
"$MCPOST" estimate hd_test.exr --denoiser nlm -o "$WORK/est_nlm" 2>/dev/null |
    sed -n 's/^time (ms): */  its steps (ms): /p'
echo "(target for nlm: the whole command <= 1.2x its 'denoise+jvp' step)"
# the default estimate with the U-Net (3 probes: one apply and 3 tangents) against one
# apply, the cost docs/fidelity.md "The defaults" reports
time_runs "denoise 1080p dump, unet (one apply)" - \
    "$MCPOST" denoise hd_test.exr --denoiser unet -o "$WORK/den_unet.exr"
time_runs "estimate 1080p dump, unet, the defaults" - \
    "$MCPOST" estimate hd_test.exr --denoiser unet -o "$WORK/est_unet"
echo "(target for unet: the default estimate <= 3x one apply)"

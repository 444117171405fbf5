#!/usr/bin/env bash
# The U-Net's memory is bounded by default (max_memory_mb, 2048): under an address-space
# limit (ulimit -v) that the whole image's activations do not fit in, a bounded run
# writes the bits of the unbounded one; with a bound above the limit the same run fails
# with one line, not a crash. 2400x1600 with the official weights: the unbounded run
# needs more than 1700 MB of address space (its activations alone are 1.48 GB).
#   - The whole image read at once, its network in tiles (MCPOST_UNET_BAND_ROWS=whole;
#     900 MB: crops of up to 1400 x 1400, tiles of 624 and 352 pixels of margin) runs
#     within 1100 (peak resident 0.96 GB); the limit is 1200.
#   - Where the image read whole and its output would not fit beside the network within
#     the bound, `mcpost denoise` reads and writes it in bands of rows by default
#     (docs/denoisers.md, "Images larger than memory"): with the bound of 900 MB it runs
#     within 800 MB of address space (peak resident 0.66 GB), and under a limit of 950
#     MB, where the whole-image run fails, it writes the same bits.
# The truth is the unbounded whole-image run, in one pass.
#   unet_memory_bound.sh BUILD_DIR
set -euo pipefail
build=$1
. "$(dirname "$0")/same_pixels.sh"
mcpost=$build/mcpost
source "$(dirname "$0")/../support/work_dir.sh"
begin_work_dir "$build" unet_memory_bound
"$build/mcpost-procedural" --width 2400 --height 1600 --spp 4 --seed 3 -o in >/dev/null
mv in_0000.exr in.exr
MCPOST_UNET_BAND_ROWS=whole "$mcpost" denoise in.exr --denoiser unet -o whole.exr --quiet
run_limited() { # run_limited LIMIT_MB NAME ARGS...: the exit status of a limited run
    local limit_kb=$(($1 * 1024)) name=$2
    shift 2
    set +e
    ( ulimit -v "$limit_kb"; "$mcpost" denoise in.exr --denoiser unet "$@" \
        -o "$name.exr" --quiet ) 2>"$name.err"
    local rc=$?
    set -e
    echo "$name under ulimit -v $limit_kb kB: exit $rc $(cat "$name.err")"
    return $rc
}
MCPOST_UNET_BAND_ROWS=whole run_limited 1200 tiled --denoiser-opt max_memory_mb=900 ||
    { cat tiled.err; echo "FAIL: the bounded run failed"; exit 1; }
same_pixels tiled.exr whole.exr
run_limited 950 bands --denoiser-opt max_memory_mb=900 ||
    { cat bands.err; echo "FAIL: the banded run failed"; exit 1; }
same_pixels bands.exr whole.exr
if MCPOST_UNET_BAND_ROWS=whole run_limited 950 tiled_950 --denoiser-opt max_memory_mb=900
then
    echo "FAIL: the whole-image run fit in 950 MB too: the limit proves nothing"
    exit 1
fi
unbounded=0
run_limited 1200 untiled --denoiser-opt max_memory_mb=100000 || unbounded=$?
[ "$unbounded" -ne 0 ] && [ "$unbounded" -lt 128 ] ||
    { echo "FAIL: without a bound the run should fail cleanly (exit $unbounded)"; exit 1; }
[ "$(wc -l < untiled.err)" -eq 1 ] || { echo "FAIL: not one line"; exit 1; }
[ ! -e untiled.exr ] || { echo "FAIL: a failed run left its output"; exit 1; }
echo PASS

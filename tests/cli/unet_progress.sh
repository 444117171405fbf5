#!/usr/bin/env bash
# A U-Net apply of a megapixel shows its progress on a terminal (a pseudo-terminal from
# script(1)) and stays silent in a log and with --quiet; the bar changes nothing in the
# output. Skipped (77) without script(1).
#   unet_progress.sh BUILD_DIR
set -euo pipefail
build=$1
command -v script >/dev/null || { echo "no script(1): skipped"; exit 77; }
source "$(dirname "$0")/../support/work_dir.sh"
begin_work_dir "$build" unet_progress
"$build/mcpost-procedural" --width 1024 --height 1024 --spp 4 --seed 5 -o in >/dev/null
mv in_0000.exr in.exr
script -qec "'$build/mcpost' denoise in.exr --denoiser unet -o tty.exr" /dev/null \
    > tty.txt
"$build/mcpost" denoise in.exr --denoiser unet -o log.exr 2> log.txt
script -qec "'$build/mcpost' denoise in.exr --denoiser unet -o quiet.exr --quiet" \
    /dev/null > quiet.txt
fail=0
grep -q "U-Net.*100%" tty.txt || { echo "FAIL: no bar reaching 100% on a terminal"; fail=1; }
! grep -q "U-Net" log.txt || { echo "FAIL: the bar in a log"; fail=1; }
! grep -q "U-Net" quiet.txt || { echo "FAIL: the bar with --quiet"; fail=1; }
cmp -s tty.exr log.exr || { echo "FAIL: the outputs differ"; fail=1; }
[ "$fail" -eq 0 ] && echo PASS
exit "$fail"

#!/usr/bin/env bash
# nlm and bilateral on a megapixel show their progress on a terminal (a pseudo-terminal
# from script(1)), from the command line and from a job file, and stay silent in a log
# and with --quiet; the bar changes nothing in the output. Skipped (77) without
# script(1).
#   nlm_progress.sh BUILD_DIR
set -euo pipefail
build=$1
command -v script >/dev/null || { echo "no script(1): skipped"; exit 77; }
source "$(dirname "$0")/../support/work_dir.sh"
begin_work_dir "$build" nlm_progress
"$build/mcpost-procedural" --width 1024 --height 1024 --spp 4 --seed 5 -o in >/dev/null
mv in_0000.exr in.exr
mcpost=$build/mcpost
on_tty() { script -qec "$1" /dev/null; }
fail=0
# nlm's apply: a bar on a terminal, nothing in a log or with --quiet, the same pixels
on_tty "'$mcpost' denoise in.exr --denoiser nlm -o tty.exr" > tty.txt
"$mcpost" denoise in.exr --denoiser nlm -o log.exr 2> log.txt
on_tty "'$mcpost' denoise in.exr --denoiser nlm -o quiet.exr --quiet" > quiet.txt
grep -q "nlm .*100%" tty.txt || { echo "FAIL: no nlm bar reaching 100% on a terminal"; fail=1; }
! grep -q "nlm " log.txt || { echo "FAIL: the nlm bar in a log"; fail=1; }
! grep -q "nlm " quiet.txt || { echo "FAIL: the nlm bar with --quiet"; fail=1; }
cmp -s tty.exr log.exr || { echo "FAIL: the outputs differ"; fail=1; }
# bilateral's estimate (the apply and its tangents in one pass) from the command line
on_tty "'$mcpost' estimate in.exr --denoiser bilateral --json" > est_tty.txt
grep -q "bilateral and its tangents .*100%" est_tty.txt ||
    { echo "FAIL: no bar for the estimate's tangents on a terminal"; fail=1; }
# and from a job file: a bar on a terminal, none with --quiet
cat > job.yaml <<'YAML'
inputs:
  noisy: {dump: in.exr}
output: out
stages:
  - estimate: {input: noisy, denoiser: bilateral}
YAML
on_tty "'$mcpost' run job.yaml" > job_tty.txt
on_tty "'$mcpost' run job.yaml --quiet" > job_quiet.txt
grep -q "bilateral and its tangents .*100%" job_tty.txt ||
    { echo "FAIL: no bar for a job's estimate on a terminal"; fail=1; }
! grep -q "bilateral" job_quiet.txt || { echo "FAIL: the bar in a job run with --quiet"; fail=1; }
[ "$fail" -eq 0 ] && echo PASS
exit "$fail"

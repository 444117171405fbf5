#!/usr/bin/env bash
# The commands that take seconds on large images show progress on a terminal (a
# pseudo-terminal from script(1)) and stay silent in a log and with --quiet: metrics'
# figures and maps, compare's renders, an estimate (the denoiser's bar nested in its
# line) and its files, the perceptual passes (vertical-iterative's, power-set's), and
# the read and write of a 4K dump by convert. The bars change nothing in the outputs.
# Skipped (77) without script(1).
#   long_progress.sh BUILD_DIR
set -euo pipefail
build=$1
command -v script >/dev/null || { echo "no script(1): skipped"; exit 77; }
source "$(dirname "$0")/../support/work_dir.sh"
begin_work_dir "$build" long_progress
mcpost=$build/mcpost
procedural=$build/mcpost-procedural
"$procedural" --width 1024 --height 1024 --spp 4 --seed 5 --singles 4 -o in >/dev/null
"$procedural" --width 1024 --height 1024 --spp 16 --seed 6 -o ref >/dev/null
mv in_0000.exr in.exr && mv ref_0000.exr ref.exr
on_tty() { script -qec "$1" /dev/null | tr '\r' '\n'; }
fail=0
expect() { # expect FILE REGEX WHAT
    grep -Eq "$2" "$1" || { echo "FAIL: $3 (no line matching '$2' in $1)"; fail=1; }
}
refuse() { # refuse FILE REGEX WHAT
    ! grep -Eq "$2" "$1" || { echo "FAIL: $3 ('$2' in $1)"; fail=1; }
}
done_with() { # done_with OUTPUT...: removed once checked, while nothing has failed
    [ "$fail" -ne 0 ] || rm -rf "$@"
}

# metrics: the figures and the maps
on_tty "'$mcpost' metrics in.exr ref.exr -o m_tty" > metrics_tty.txt
"$mcpost" metrics in.exr ref.exr -o m_log > /dev/null 2> metrics_log.txt
on_tty "'$mcpost' metrics in.exr ref.exr -o m_quiet --quiet" > metrics_quiet.txt
expect metrics_tty.txt "^metrics in\.exr +\[#{40}\] 100%" "no metrics bar on a terminal"
expect metrics_tty.txt "^writing maps +\[#{40}\] 100%" "no bar for the maps"
refuse metrics_log.txt "metrics in|writing maps" "a metrics bar in a log"
refuse metrics_quiet.txt "metrics in|writing maps" "a metrics bar with --quiet"
cmp -s m_tty/flip_hdr.exr m_log/flip_hdr.exr || { echo "FAIL: the maps differ"; fail=1; }
done_with m_tty m_log m_quiet

# compare: the renders it writes for the page
on_tty "'$mcpost' compare ref.exr in.exr -o c_tty" > compare_tty.txt
"$mcpost" compare ref.exr in.exr -o c_log > /dev/null 2> compare_log.txt
expect compare_tty.txt "^writing the renders +\[#{40}\] 100%" "no bar for compare's renders"
refuse compare_log.txt "writing the" "compare's bar in a log"
done_with c_tty c_log

# estimate: its own bar with nlm's as a sub-count, then its files
on_tty "'$mcpost' estimate in.exr --denoiser nlm -o e_tty" > estimate_tty.txt
"$mcpost" estimate in.exr --denoiser nlm -o e_log > /dev/null 2> estimate_log.txt
expect estimate_tty.txt "^estimate +\[[#.]{16}\] +[0-9]+% \| nlm and its tangents +[0-9]+%" \
    "no nlm bar nested in the estimate's line"
expect estimate_tty.txt "^estimate +\[#{40}\] 100%" "no estimate bar reaching 100%"
expect estimate_tty.txt "^writing [0-9]+ files +\[#{40}\] 100%" "no bar for the files"
refuse estimate_log.txt "estimate +\[|estimate:|writing|nlm" "an estimate bar in a log"
cmp -s e_tty/sure.exr e_log/sure.exr || { echo "FAIL: the estimates differ"; fail=1; }
done_with e_tty e_log

# perceptual: vertical-iterative's passes
on_tty "'$mcpost' perceptual in_single_000*.exr --denoiser nlm -o p_tty" > perc_tty.txt
"$mcpost" perceptual in_single_000*.exr --denoiser nlm -o p_log > /dev/null 2> perc_log.txt
expect perc_tty.txt "^vertical-iterative, pass 1 +\[" "no bar for the first pass"
expect perc_tty.txt "^vertical-iterative, pass [0-9]+ +\[#{40}\] 100%" "no last pass at 100%"
refuse perc_log.txt "pass [0-9]" "a pass bar in a log"
cmp -s p_tty/vertical-iterative.exr p_log/vertical-iterative.exr ||
    { echo "FAIL: the optimised images differ"; fail=1; }
# ... and power-set's search, the method named in the label
on_tty "'$mcpost' perceptual in_single_000*.exr --denoiser nlm -m power-set -o ps" > ps_tty.txt
expect ps_tty.txt "^power-set, pass 1 +\[" "no bar for power-set's first pass"
refuse ps_tty.txt "vertical-iterative" "power-set's passes named vertical-iterative"
done_with p_tty p_log ps

# convert: the read and the write of a 4K dump (400 MB of pixels): an EXR into an EXR
# goes in bands of rows, one bar for the bands; into a PFM it is read and written whole
"$procedural" --width 3840 --height 2160 --spp 1 --seed 7 -o big >/dev/null
on_tty "'$mcpost' convert big_0000.exr tty.exr" > convert_tty.txt
"$mcpost" convert big_0000.exr log.exr 2> convert_log.txt
expect convert_tty.txt "^convert big_0000\.exr +\[#{40}\] 100%" "no bar for the bands"
refuse convert_log.txt "convert big" "a bar in a log"
cmp -s tty.exr log.exr || { echo "FAIL: the converted files differ"; fail=1; }
on_tty "'$mcpost' convert big_0000.exr tty.pfm" > convert_pfm_tty.txt
expect convert_pfm_tty.txt "^reading big_0000\.exr +\[#{40}\] 100%" "no bar for the read"
"$mcpost" convert big_0000.exr log.pfm 2> convert_pfm_log.txt
refuse convert_pfm_log.txt "reading|writing" "a read or write bar in a log"
done_with log.exr tty.pfm log.pfm
# merge and info of the 4K dump: a bar for the bands of each
on_tty "'$mcpost' merge big_0000.exr tty.exr -o merged.exr" > merge_tty.txt
expect merge_tty.txt "^merge merged\.exr +\[#{40}\] 100%" "no bar for merge's bands"
done_with tty.exr merged.exr
on_tty "'$mcpost' info big_0000.exr" > info_tty.txt
expect info_tty.txt "^info big_0000\.exr +\[#{40}\] 100%" "no bar for info's bands"
"$mcpost" info big_0000.exr > info_log.txt 2>&1
refuse info_log.txt "info big" "an info bar in a log"

[ "$fail" -eq 0 ] && echo PASS
exit "$fail"

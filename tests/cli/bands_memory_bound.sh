#!/usr/bin/env bash
# `mcpost merge`, `convert`, `info` and `estimate` read and write an EXR a band of rows
# at a time (docs/conventions.md, "Files larger than memory"): under an address-space
# limit (ulimit -v) that the whole command does not fit in, each gives what the whole
# command gives. Three 2-spp dumps of 2400x1600 (12 channels each, 88 MB of zip): in bands
# each command runs within 150 MB of address space (merge 89 MB resident, where the
# whole merge held 1.0 GB; with --pool 2, whose bands read the rows around them, 108
# MB); whole, merge needs more than 900 MB, convert more than 400 and info more than
# 200. The limit here is 200 MB; for the estimate (gauss, in bands of 64 rows, which
# MCPOST_ESTIMATE_BAND_ROWS forces at this size) 450 MB, where the whole estimate fails
# at 500 MB and the bands run at 400. The truth is each command run whole
# (MCPOST_BAND_ROWS=whole) without a limit: files compared value for value, every
# channel, rewritten without compression (EXR files of the same pixels may differ in
# which zip chunks are stored raw), and info's JSON and text compared as they are.
#   bands_memory_bound.sh BUILD_DIR
set -euo pipefail
build=$1
mcpost=$build/mcpost
source "$(dirname "$0")/../support/work_dir.sh"
begin_work_dir "$build" bands_memory_bound
for s in 1 2 3; do
    "$build/mcpost-procedural" --width 2400 --height 1600 --spp 2 --seed $s -o r$s >/dev/null
done
inputs=(r1_0000.exr r2_0000.exr r3_0000.exr)
limit_mb=200
limited() { # limited NAME COMMAND ARGS...: its exit status under limit_mb
    local name=$1
    shift
    set +e
    ( ulimit -v $((limit_mb * 1024)); "$mcpost" "$@" --quiet ) >"$name.out" 2>"$name.err"
    local rc=$?
    set -e
    echo "$name under ulimit -v $limit_mb MB: exit $rc $(head -c 300 "$name.err")"
    return $rc
}
same_values() { # same_values A.exr B.exr: every channel's float bits
    "$mcpost" convert "$1" "${1%.exr}_raw.exr" --compression none --quiet
    "$mcpost" convert "$2" "${2%.exr}_raw.exr" --compression none --quiet
    cmp "${1%.exr}_raw.exr" "${2%.exr}_raw.exr" || { echo "FAIL: $1 and $2 differ"; exit 1; }
    echo "the same values in every channel: $1 $2"
    rm -f "${1%.exr}_raw.exr" "${2%.exr}_raw.exr" "$2" # the disk is shared (work_dir.sh)
}
unlimited() { # unlimited NAME COMMAND ARGS...: as limited, without the limit
    local name=$1
    shift
    "$mcpost" "$@" --quiet >"$name.out" 2>"$name.err"
}
whole_fails() { # whole_fails NAME COMMAND ARGS...: the whole command does not fit
    local rc=0 name=$1
    shift
    MCPOST_BAND_ROWS=whole limited "$name" "$@" || rc=$?
    [ "$rc" -ne 0 ] || { echo "FAIL: $name fit in $limit_mb MB: the limit proves nothing"; exit 1; }
    [ "$rc" -lt 128 ] || { echo "FAIL: $name crashed (exit $rc)"; exit 1; }
    [ "$(wc -l < "$name.err")" -eq 1 ] || { echo "FAIL: $name: not one line"; exit 1; }
}

MCPOST_BAND_ROWS=whole "$mcpost" merge "${inputs[@]}" -o merge_whole.exr --quiet
limited merge merge "${inputs[@]}" -o merge.exr || { echo "FAIL: merge"; exit 1; }
same_values merge.exr merge_whole.exr
MCPOST_BAND_ROWS=whole "$mcpost" merge "${inputs[@]}" -o pool_whole.exr --pool 2 --quiet
limited pool merge "${inputs[@]}" -o pool.exr --pool 2 || { echo "FAIL: merge --pool"; exit 1; }
same_values pool.exr pool_whole.exr
rm -f pool.exr
whole_fails merge_limited merge "${inputs[@]}" -o merge_limited.exr
[ ! -e merge_limited.exr ] || { echo "FAIL: a failed merge left its output"; exit 1; }

i=0
for args in "" "--channels N.X,Variance.G,R --half" "--dump mitsuba"; do
    tag=convert$((i++))
    # shellcheck disable=SC2086
    MCPOST_BAND_ROWS=whole "$mcpost" convert r1_0000.exr "${tag}_whole.exr" $args --quiet
    # shellcheck disable=SC2086
    limited "$tag" convert r1_0000.exr "$tag.exr" $args || { echo "FAIL: $tag"; exit 1; }
    same_values "$tag.exr" "${tag}_whole.exr"
    rm -f "$tag.exr"
done
whole_fails convert_limited convert r1_0000.exr convert_limited.exr

for fmt in "" --json; do
    MCPOST_BAND_ROWS=whole "$mcpost" info r1_0000.exr merge.exr $fmt >info_whole.txt
    limited info info r1_0000.exr merge.exr $fmt || { echo "FAIL: info"; exit 1; }
    cmp info.out info_whole.txt || { echo "FAIL: info$fmt differs"; exit 1; }
    echo "info$fmt: the same"
done
whole_fails info_limited info r1_0000.exr

# the estimate: the dump read and F(X), SURE and Var[F] written band by band
limit_mb=450
export MCPOST_ESTIMATE_BAND_ROWS=64
# nlm (a wider halo, and its own bands' progress) on a smaller render, without the limit
"$build/mcpost-procedural" --width 600 --height 400 --spp 4 --seed 4 -o small >/dev/null
for den in gauss nlm; do
    tag=estimate_$den
    input=r1_0000.exr run=limited
    [ "$den" = gauss ] || { input=small_0000.exr run=unlimited; }
    MCPOST_ESTIMATE_BAND_ROWS=whole "$mcpost" estimate "$input" --denoiser "$den" \
        -o "${tag}_whole" --budget 1000000 --quiet
    "$run" "$tag" estimate "$input" --denoiser "$den" -o "$tag" --budget 1000000 ||
        { echo "FAIL: $tag"; exit 1; }
    n=0
    for f in "${tag}_whole"/*; do
        b=$(basename "$f")
        case $b in
        *.exr) same_values "$tag/$b" "$f" ;;
        estimate.json) # the same but for the timings
            diff <(sed '/"time_ms"/,/}/d' "$f") <(sed '/"time_ms"/,/}/d' "$tag/$b") ||
                { echo "FAIL: $tag/$b differs"; exit 1; } ;;
        *) cmp "$f" "$tag/$b" || { echo "FAIL: $tag/$b differs"; exit 1; } ;;
        esac
        n=$((n + 1))
    done
    [ "$n" -eq "$(find "$tag" -type f | wc -l)" ] || { echo "FAIL: $tag: other files"; exit 1; }
    echo "$tag: the whole estimate's $n files"
    rm -rf "$tag" "${tag}_whole"
done
MCPOST_ESTIMATE_BAND_ROWS=whole whole_fails estimate_limited estimate r1_0000.exr \
    --denoiser gauss -o estimate_limited
[ ! -e estimate_limited ] || { echo "FAIL: a failed estimate left its output"; exit 1; }
echo PASS

#!/usr/bin/env bash
# `mcpost merge` of EXR dumps goes a band of rows at a time (common/dump/merge_stream.c;
# docs/conventions.md, "Merging renders"): under an address-space limit (ulimit -v)
# that the whole merge does not fit in, it writes the whole merge's file. Three 2-spp
# replicates of 2400x1600 (12 channels each, 88 MB of zip): the whole merge held 1.0
# GB resident and needs more than 900 MB of address space; in bands it runs within 300
# MB (66 MB resident). The limit here is 600 MB. The truth is the whole merge
# (MCPOST_MERGE_BAND_ROWS=whole), unlimited; the files are compared value for value,
# every channel, rewritten without compression (EXR files of the same pixels may differ
# in which zip chunks are stored raw).
#   merge_memory_bound.sh BUILD_DIR
set -euo pipefail
build=$1
mcpost=$build/mcpost
work=$build/test-tmp/merge_memory_bound
rm -rf "$work" && mkdir -p "$work" && cd "$work"
for s in 1 2 3; do
    "$build/mcpost-procedural" --width 2400 --height 1600 --spp 2 --seed $s -o r$s >/dev/null
done
inputs=(r1_0000.exr r2_0000.exr r3_0000.exr)
MCPOST_MERGE_BAND_ROWS=whole "$mcpost" merge "${inputs[@]}" -o whole.exr --quiet
limited() { # limited NAME [ENV...]: the exit status of a merge under 600 MB
    local name=$1
    shift
    set +e
    ( ulimit -v $((600 * 1024)); env "$@" "$mcpost" merge "${inputs[@]}" -o "$name.exr" \
        --quiet ) >"$name.out" 2>"$name.err"
    local rc=$?
    set -e
    echo "$name under ulimit -v 600 MB: exit $rc $(cat "$name.out" "$name.err")"
    return $rc
}
limited bands || { echo "FAIL: the merge in bands failed"; exit 1; }
"$mcpost" convert bands.exr bands_raw.exr --compression none --quiet
"$mcpost" convert whole.exr whole_raw.exr --compression none --quiet
cmp bands_raw.exr whole_raw.exr || { echo "FAIL: the merges differ"; exit 1; }
echo "the same values in every channel"
rc=0
limited whole_limited MCPOST_MERGE_BAND_ROWS=whole || rc=$?
[ "$rc" -ne 0 ] || { echo "FAIL: the whole merge fit in 600 MB: the limit proves nothing"; exit 1; }
[ "$rc" -lt 128 ] || { echo "FAIL: the whole merge crashed (exit $rc)"; exit 1; }
[ "$(wc -l < whole_limited.err)" -eq 1 ] || { echo "FAIL: not one line"; exit 1; }
[ ! -e whole_limited.exr ] || { echo "FAIL: a failed run left its output"; exit 1; }
echo PASS

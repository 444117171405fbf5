#!/usr/bin/env bash
# run.sh BUILD_DIR [SECONDS] [TARGET...]: runs the libFuzzer targets of a
# MCPOST_FUZZ=ON build (clang) for SECONDS each [60], every target when none is named
# (pfm exr dump job tza bands). Starts from the committed seed corpus and the regression
# inputs; what a run adds to the corpus stays in BUILD_DIR/fuzz/corpus/<target>.
# Exits non-zero on the first finding (a crash, a sanitizer report, a leak, a timeout
# over 10 s, an allocation over 2 GiB), whose input is left in
# BUILD_DIR/fuzz/findings/<target>/ to add to regressions/<target>/ with the fix.
#
# MCPOST_FUZZ_RUNS=N stops each target after N executions instead of the time limit
# (a campaign: MCPOST_FUZZ_RUNS=10000000 tests/fuzz/run.sh build-fuzz 0).
# MCPOST_FUZZ_JOBS=N runs N targets at a time [1]. MCPOST_FUZZ_MAX_LEN=N caps the
# inputs at N bytes [65536]: a job campaign at 4096 stays on job files of a few dozen
# stages, which the checks take thousands of times a second (docs/testing.md). The last line per target is
# "fuzz: TARGET: N executions in S s, no findings".
set -uo pipefail
here=$(cd "$(dirname "$0")" && pwd)
build=$(cd "${1:?usage: run.sh BUILD_DIR [SECONDS] [TARGET...]}" && pwd)
seconds=${2:-60}
shift $(($# > 1 ? 2 : 1))
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(pfm exr dump job tza bands)
runs=${MCPOST_FUZZ_RUNS:--1}
max_len=${MCPOST_FUZZ_MAX_LEN:-65536}

run_one() { # run_one TARGET: one target, its log in BUILD_DIR/fuzz/TARGET.log
    local t=$1 bin=$build/tests/fuzz/fuzz_$1 out=$build/fuzz
    local corpus=$out/corpus/$t findings=$out/findings/$t log=$out/$t.log
    mkdir -p "$corpus" "$findings"
    if [ ! -x "$bin" ]; then
        echo "fuzz: $bin missing (configure with CC=clang -DMCPOST_FUZZ=ON)" >&2
        return 1
    fi
    local limit=()
    [ "$runs" -ge 0 ] && limit+=(-runs="$runs")
    [ "$seconds" -gt 0 ] && limit+=(-max_total_time="$seconds")
    local dict=()
    [ -f "$here/$t.dict" ] && dict=(-dict="$here/$t.dict")
    # the regressions are read as seeds too: each run starts by replaying them
    "$bin" "${limit[@]}" "${dict[@]}" -timeout=10 -rss_limit_mb=2048 -max_len="$max_len" \
        -print_final_stats=1 -artifact_prefix="$findings/" \
        "$corpus" "$here/corpus/$t" "$here/regressions/$t" >"$log" 2>&1
    local rc=$? execs secs
    execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
    secs=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log" | tail -1)
    if [ $rc -ne 0 ]; then
        echo "fuzz: $t: FINDING (exit $rc) after ${execs:-?} executions; log $log," \
             "input in $findings/" >&2
        grep -m 5 -E "ERROR|SUMMARY|runtime error|broke the error contract" "$log" >&2
        return 1
    fi
    echo "fuzz: $t: ${execs:-?} executions (${secs:-?}/s), no findings"
}

status=0
jobs=${MCPOST_FUZZ_JOBS:-1}
pids=()
for t in "${targets[@]}"; do
    # at most `jobs` at a time: wait for the oldest before starting another
    if [ ${#pids[@]} -ge "$jobs" ]; then
        wait "${pids[0]}" || status=1
        pids=("${pids[@]:1}")
    fi
    run_one "$t" &
    pids+=($!)
done
for p in "${pids[@]}"; do
    wait "$p" || status=1
done
exit $status

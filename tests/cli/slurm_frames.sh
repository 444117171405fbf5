#!/usr/bin/env bash
# slurm_frames.sh BUILD_DIR: a frame job on a real Slurm (issue 19).
#
# Starts munged, slurmctld and slurmd on this machine (one node, 127.0.0.1, config,
# key, state, spool and logs in a temporary folder, ports that are free), renders 4
# frames with mcpost-procedural, submits the frame job through `mcpost submit --slurm`,
# waits for the array and its collect job, and checks:
#   - Slurm ran one array task per frame (its log files frames-JOB_FRAME.log);
#   - every frame's report.json is there, names its frame, and holds the same MSE and
#     relMSE as the same frame run here with `mcpost run --frames F` (one thread both);
#   - the collected report lists 4 complete frames with those figures;
#   - a resubmission after losing frame 3's report.json runs frame 3 alone.
# Then it stops everything it started (trap on exit). Slurm that cannot start fails
# the test, with the reason and the daemons' logs: it never passes silently. Only
# MCPOST_SLURM_TEST=skip turns a missing Slurm into ctest's "skipped" (exit 77).
set -euo pipefail
BUILD=$(cd "$1" && pwd)
MCPOST=$BUILD/mcpost
PROCEDURAL=$BUILD/mcpost-procedural

T=""
PIDS=()
fail() {
    echo "slurm test: FAIL: $*" >&2
    if [ -n "$T" ]; then
        for log in slurmctld.log slurmd.log munged.log; do
            [ -f "$T/$log" ] && { echo "--- $log (last lines)"; tail -n 15 "$T/$log"; } >&2
        done
    fi
    exit 1
}
cleanup() {
    local rc=$?
    if [ -n "$T" ] && [ -f "$T/slurm.conf" ]; then
        # our jobs only: this cluster's controller knows no others; their steps
        # (slurmstepd) end with them
        SLURM_CONF=$T/slurm.conf scancel --quiet --user=root 2>/dev/null || true
    fi
    # the daemons, newest first; then anything of theirs still there
    local i
    for ((i = ${#PIDS[@]} - 1; i >= 0; i--)); do
        kill -TERM "${PIDS[i]}" 2>/dev/null || true
    done
    for i in 1 2 3 4 5 6 7 8 9 10; do
        local alive=0
        for p in "${PIDS[@]}"; do kill -0 "$p" 2>/dev/null && alive=1; done
        [ $alive = 0 ] && break
        sleep 0.5
    done
    for p in "${PIDS[@]}"; do kill -KILL "$p" 2>/dev/null || true; done
    if [ -n "$T" ]; then
        [ $rc = 0 ] && rm -rf "$T" || echo "slurm test: files kept in $T" >&2
    fi
    exit $rc
}
trap cleanup EXIT

missing=()
for b in munged mungekey slurmctld slurmd sbatch sinfo scontrol scancel; do
    command -v $b >/dev/null || missing+=($b)
done
if [ ${#missing[@]} -gt 0 ]; then
    if [ "${MCPOST_SLURM_TEST:-}" = skip ]; then
        echo "slurm test: SKIPPED (MCPOST_SLURM_TEST=skip): ${missing[*]} not installed" >&2
        exit 77
    fi
    fail "${missing[*]} not found: install the Debian packages slurm-wlm and munge" \
        "(./setup.sh test does; MCPOST_SLURM_TEST=skip skips this test instead)"
fi
[ "$(id -u)" = 0 ] || fail "Slurm's daemons run as root here (SlurmUser=root): run as root"

T=$(mktemp -d /tmp/mcpost-slurm.XXXXXX)
# munged wants every folder above its socket searchable, and none writable by others
chmod 755 "$T"
mkdir -p "$T/state" "$T/spool" "$T/work"

# ports nobody listens on
free_port() {
    local p
    while :; do
        p=$((20000 + RANDOM % 30000))
        (exec 3<>/dev/tcp/127.0.0.1/$p) 2>/dev/null || { echo $p; return; }
    done
}
CTLD_PORT=$(free_port)
SLURMD_PORT=$(free_port)
[ "$CTLD_PORT" != "$SLURMD_PORT" ] || SLURMD_PORT=$((CTLD_PORT + 1))

# ---- munge: its own key and socket ----
mungekey -c -k "$T/munge.key" || fail "mungekey could not write a key"
munged -F --key-file="$T/munge.key" --socket="$T/munge.sock" --pid-file="$T/munged.pid" \
    --log-file="$T/munged.log" --seed-file="$T/munged.seed" 2>>"$T/munged.log" &
PIDS+=($!)
for i in $(seq 50); do [ -S "$T/munge.sock" ] && break; sleep 0.1; done
[ -S "$T/munge.sock" ] || fail "munged did not start"

# ---- slurm.conf: one node, this machine, no cgroups, no accounting ----
HOST=$(hostname -s)
CPUS=$(nproc)
MEM_MB=$(awk '/MemTotal/ {print int($2 / 1024 / 2)}' /proc/meminfo)
cat >"$T/slurm.conf" <<EOF
ClusterName=mcpost-test
SlurmctldHost=$HOST(127.0.0.1)
SlurmctldPort=$CTLD_PORT
SlurmdPort=$SLURMD_PORT
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$T/munge.sock
SlurmUser=root
SlurmdUser=root
StateSaveLocation=$T/state
SlurmdSpoolDir=$T/spool
SlurmctldPidFile=$T/slurmctld.pid
SlurmdPidFile=$T/slurmd.pid
SlurmctldLogFile=$T/slurmctld.log
SlurmdLogFile=$T/slurmd.log
SlurmctldDebug=info
SlurmdDebug=info
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
MpiDefault=none
SwitchType=switch/none
SchedulerType=sched/builtin
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
MinJobAge=600
NodeName=mcpnode NodeAddr=127.0.0.1 NodeHostname=$HOST CPUs=$CPUS RealMemory=$MEM_MB State=UNKNOWN
PartitionName=mcptest Nodes=mcpnode Default=YES MaxTime=INFINITE State=UP
EOF
# slurmd 22.05 always starts a cgroup plugin (v1 or v2, detected); nothing here uses
# it (linuxproc, task/none), and without systemd a v2 one must not ask systemd
cat >"$T/cgroup.conf" <<EOF
CgroupAutomount=no
IgnoreSystemd=yes
EOF
export SLURM_CONF=$T/slurm.conf

slurmctld -D -i -f "$T/slurm.conf" >>"$T/slurmctld.log" 2>&1 &
PIDS+=($!)
slurmd -D -N mcpnode -f "$T/slurm.conf" >>"$T/slurmd.log" 2>&1 &
PIDS+=($!)

state=""
for i in $(seq 60); do
    state=$(sinfo -h -N -n mcpnode -o %t 2>/dev/null || true)
    [ "$state" = idle ] && break
    for p in "${PIDS[@]}"; do kill -0 "$p" 2>/dev/null || fail "a Slurm daemon exited"; done
    sleep 0.5
done
[ "$state" = idle ] || fail "the node did not become idle in 30 s (state '$state')"
echo "slurm test: slurmctld and slurmd up (ports $CTLD_PORT, $SLURMD_PORT), node idle"

# ---- the frame job: 4 frames of the procedural scene, other seeds ----
cd "$T/work"
mkdir -p renders
for f in 1 2 3 4; do
    "$PROCEDURAL" --width 32 --height 32 --spp 8 --seed $((100 + f)) --truth \
        -o renders/shot_$(printf %04d $f) >/dev/null
done
cat >shot.yaml <<'EOF'
title: slurm test shot
frames: 1-4
inputs:
  noisy: {dump: renders/shot_####_0000.exr}
  reference: {image: renders/shot_%04d_truth.exr}
output: out/shot
stages:
  - metrics: {input: noisy, reference: reference}
EOF

# waits for job $1 (and all its array tasks) to leave the queue
wait_job() {
    local i
    for i in $(seq 240); do
        [ -z "$(squeue -h -j "$1" -o %i 2>/dev/null)" ] && return 0
        sleep 0.5
    done
    fail "job $1 still queued or running after 120 s: $(squeue -h -j "$1" -o '%i %T %R')"
}
ids() { # the two job ids that submit printed
    sed -n 's/^submitted job \([0-9]*\):.*/\1/p' "$1"
}

"$MCPOST" submit shot.yaml --slurm --partition mcptest --cpus-per-task 1 \
    --array-parallel 2 >submit.out || fail "mcpost submit failed: $(cat submit.out)"
cat submit.out
ARRAY=$(ids submit.out | sed -n 1p); COLLECT=$(ids submit.out | sed -n 2p)
[ -n "$ARRAY" ] && [ -n "$COLLECT" ] || fail "no job ids in: $(cat submit.out)"
grep -q '^#SBATCH --array=1-4%2$' out/shot/slurm/frames.sbatch ||
    fail "frames.sbatch has no --array=1-4%2"
wait_job "$ARRAY"
wait_job "$COLLECT"

# Slurm's own record: every array task and the collect job completed
for id in "${ARRAY}_1" "${ARRAY}_2" "${ARRAY}_3" "${ARRAY}_4" "$COLLECT"; do
    st=$(scontrol -o show job "$id" | sed -n 's/.*JobState=\([A-Z_]*\).*/\1/p')
    [ "$st" = COMPLETED ] || fail "job $id: $st, not COMPLETED"
    case $id in *_*) [ -f "out/shot/slurm/frames-$id.log" ] || fail "no log of array task $id" ;; esac
done

# the same figures as each frame run here, one thread as the tasks ran
figure() { # figure FILE KEY: the number after "KEY": (cJSON prints a double one way)
    grep -o "\"$2\":[[:space:]]*[-0-9.eE+]*" "$1" | head -1 | sed 's/.*:[[:space:]]*//'
}
for f in 1 2 3 4; do
    d=out/shot/000$f
    [ -f $d/report.json ] && [ -f $d/report.html ] || fail "frame $f: no report"
    grep -q "\"frame\":[[:space:]]*$f,\?\$" $d/report.json || fail "frame $f: report names no frame $f"
    OMP_NUM_THREADS=1 "$MCPOST" run shot.yaml --frames $f --output local --quiet ||
        fail "local run of frame $f failed"
    for key in mse relmse; do
        a=$(figure $d/report.json $key)
        b=$(figure local/000$f/report.json $key)
        [ -n "$a" ] && [ "$a" = "$b" ] || fail "frame $f: $key on Slurm '$a', here '$b'"
        grep -q "\"metrics: noisy against reference: $([ $key = mse ] && echo MSE || echo relMSE)\":[[:space:]]*$a,\?\$" \
            out/shot/report.json || fail "frame $f: collected report lacks $key $a"
    done
done
grep -q '"complete":[[:space:]]*4,' out/shot/report.json ||
    fail "collected report: not 4 complete frames"
[ -f out/shot/report.html ] || fail "no collected report.html"
grep -q 'href="0004/report.html"' out/shot/report.html || fail "report.html has no frame links"

# resume: frame 3 lost its report (a killed task); a new submission runs it alone
rm out/shot/0003/report.json
"$MCPOST" submit shot.yaml --slurm --partition mcptest >resubmit.out ||
    fail "resubmission failed: $(cat resubmit.out)"
ARRAY2=$(ids resubmit.out | sed -n 1p); COLLECT2=$(ids resubmit.out | sed -n 2p)
grep -q '^#SBATCH --array=3$' out/shot/slurm/frames.sbatch || fail "resubmission's array is not 3"
wait_job "$ARRAY2"
wait_job "$COLLECT2"
[ -f out/shot/0003/report.json ] || fail "frame 3 not run again"
[ -f "out/shot/slurm/frames-${ARRAY2}_3.log" ] || fail "no log of the resubmitted task 3"
grep -q '"complete":[[:space:]]*4,' out/shot/report.json ||
    fail "collected report after the resubmission: not 4 complete frames"
echo "slurm test: 4 frames on Slurm (job $ARRAY, collect $COLLECT), figures equal to local runs; frame 3 resubmitted alone (job $ARRAY2)"

#!/usr/bin/env bash
# Tests scripts/slurm-frames.sh on a one-node Slurm cluster it starts
# itself (Debian's slurm-wlm and munge, installed if missing; daemons run
# as root from a temporary folder, stopped on exit): submits a small smoke
# animation as a job array of two tasks, waits, and checks that every
# frame was written and equals the same frame rendered locally in one
# process. Exits 0 on success, 1 on a wrong result, and 3 if the cluster
# does not start within --start-timeout seconds (default 60).
#
#   scripts/test-slurm.sh [--start-timeout S]
set -euo pipefail
cd "$(dirname "$0")/.."
timeout_s=60
[ "${1:-}" = "--start-timeout" ] && timeout_s=$2
binary="${CARGO_TARGET_DIR:-$HOME/.cache/slicelight/target}/release/slicelight"
[ -x "$binary" ] || { echo "test-slurm: build slicelight first (cargo build --release)" >&2; exit 2; }
[ "$(id -u)" = 0 ] || { echo "test-slurm: needs root (it starts munged, slurmctld and slurmd)" >&2; exit 3; }
if ! command -v slurmctld >/dev/null || ! command -v munged >/dev/null; then
    echo "test-slurm: installing slurm-wlm and munge" >&2
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends slurm-wlm munge >/dev/null
fi
work=$(mktemp -d /tmp/slicelight-slurm.XXXXXX)
node=$(hostname -s)
cleanup() {
    for p in slurmd slurmctld munged; do
        [ -f "$work/$p.pid" ] && kill "$(cat "$work/$p.pid")" 2>/dev/null || true
    done
    sleep 1
    rm -rf "$work"
}
trap cleanup EXIT
mkdir -p "$work/state" "$work/spool" "$work/munge"
# munge: a key of our own, its socket in the work folder.
dd if=/dev/urandom of="$work/munge/munge.key" bs=1024 count=1 2>/dev/null
chmod 400 "$work/munge/munge.key"
munged --force --key-file="$work/munge/munge.key" --socket="$work/munge/socket" \
    --pid-file="$work/munged.pid" --log-file="$work/munged.log" --seed-file="$work/munge/seed"
cat > "$work/slurm.conf" <<CONF
ClusterName=slicelight-test
SlurmctldHost=$node(127.0.0.1)
AuthType=auth/munge
AuthInfo=socket=$work/munge/socket
CredType=cred/munge
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
SlurmUser=root
SlurmdUser=root
StateSaveLocation=$work/state
SlurmdSpoolDir=$work/spool
SlurmctldPidFile=$work/slurmctld.pid
SlurmdPidFile=$work/slurmd.pid
SlurmctldLogFile=$work/slurmctld.log
SlurmdLogFile=$work/slurmd.log
SlurmctldPort=16817
SlurmdPort=16818
ReturnToService=2
MpiDefault=none
NodeName=$node NodeAddr=127.0.0.1 CPUs=$(nproc) State=UNKNOWN
PartitionName=test Nodes=$node Default=YES MaxTime=INFINITE State=UP
CONF
export SLURM_CONF="$work/slurm.conf"
slurmctld -i
slurmd
started=0
for ((t = 0; t < timeout_s; t++)); do
    if sinfo -h -o '%T' 2>/dev/null | grep -qE '^(idle|mixed|allocated)'; then
        started=1
        break
    fi
    sleep 1
done
if [ "$started" = 0 ]; then
    echo "test-slurm: the one-node cluster did not start within $timeout_s s" >&2
    tail -5 "$work/slurmctld.log" "$work/slurmd.log" >&2 || true
    exit 3
fi
echo "test-slurm: cluster up after ${t} s: $(sinfo -h -o '%P %D %T %C')" >&2
# A small smoke animation: 4 frames, 2 per task.
cp tests/data/smoke_small.toml "$work/scene.toml"
job=$(SLICELIGHT_CACHE_DIR="$work/cache" scripts/slurm-frames.sh "$work/scene.toml" "$work/out/f_%02d.png" 0 4 \
    --per-task 2 --fps 5 --binary "$binary")
echo "test-slurm: submitted job array $job" >&2
for ((t = 0; t < 300; t++)); do
    [ -z "$(squeue -h -j "$job" 2>/dev/null)" ] && break
    sleep 1
done
cat "$work"/out/slurm-*.log >&2 || true
mkdir -p "$work/local"
SLICELIGHT_CACHE_DIR=off "$binary" render "$work/scene.toml" -o "$work/local/f_%02d.png" --frames 0..4 --fps 5 \
    --backend auto -q
status=0
for f in 00 01 02 03; do
    if ! cmp -s "$work/out/f_$f.png" "$work/local/f_$f.png"; then
        echo "test-slurm: frame $f from the cluster differs from the local render (or is missing)" >&2
        status=1
    fi
done
sacct_line=$(sacct -j "$job" -n -X -o JobID,State 2>/dev/null | tr -s ' ' | head -3 || true)
[ "$status" = 0 ] && echo "test-slurm: ok: 4 frames from 2 array tasks equal the local render ${sacct_line:+($sacct_line)}" >&2
exit "$status"

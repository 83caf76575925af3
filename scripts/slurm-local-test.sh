#!/usr/bin/env bash
# The cluster path on a real Slurm: a raw procedural scene → DSM through `seasonstereo jobs slurm
# reconstruct` (a path with a space, an extra option passed through), byte-identical to a local
# `reconstruct`; then a damaged image: the merge refuses (exit 3), `jobs status` names the failed
# tiles, and `jobs resubmit` of only those completes the DSM, identical again.
# `--dataset`: the training-set chain instead (`jobs slurm dataset` on procedural worlds' sources,
# 2 shards per stage), then a failed teacher shard: the check names it, the later stages are
# cancelled, `jobs resubmit` of only that shard completes the set, with the same lists.
#
# Usage: scripts/slurm-local-test.sh [--setup] [--dataset] [SIZE (default 4096; 256 with
# --dataset)]   — needs sbatch on PATH and a running
# cluster whose nodes see this folder. `--setup` first configures a one-node cluster on this
# machine (Debian/Ubuntu, root: apt-get install -y slurm-wlm; munge, slurmctld, slurmd).
set -euo pipefail
BIN=${BIN:-$(pwd)/target/release/seasonstereo}
if [[ ${1:-} == --setup ]]; then
    shift
    cpus=$(nproc); mem=$(( $(free -m | awk '/Mem:/ {print $2}') - 1024 )); host=$(hostname -s)
    mkdir -p /etc/slurm /var/spool/slurmctld /var/spool/slurmd /var/log/slurm
    cat > /etc/slurm/slurm.conf <<CONF
ClusterName=local
SlurmctldHost=$host
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
ReturnToService=2
StateSaveLocation=/var/spool/slurmctld
SlurmdSpoolDir=/var/spool/slurmd
SlurmctldLogFile=/var/log/slurm/slurmctld.log
SlurmdLogFile=/var/log/slurm/slurmd.log
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
NodeName=$host CPUs=$cpus RealMemory=$mem State=UNKNOWN
PartitionName=debug Nodes=$host Default=YES MaxTime=INFINITE State=UP
CONF
    [[ -f /etc/munge/munge.key ]] || mungekey --create 2>/dev/null || /usr/sbin/create-munge-key
    pgrep -x munged >/dev/null || (mkdir -p /run/munge && chown munge: /run/munge && runuser -u munge -- /usr/sbin/munged || /usr/sbin/munged --force)
    pgrep -x slurmctld >/dev/null || slurmctld
    pgrep -x slurmd >/dev/null || slurmd
    sleep 3; sinfo
fi
command -v sbatch >/dev/null || { echo "no sbatch on PATH: nothing to test"; exit 0; }
T=$(mktemp -d "$PWD/slurm test XXXX")   # a path with a space, on a file system the node sees
trap 'rm -rf "$T"' EXIT

if [[ ${1:-} == --dataset ]]; then
    "$BIN" dataset world --size "${2:-256}" --worlds 4 -o "$T/world set" >/dev/null
    src="$T/world set/sources/train"
    args=(--pairs "$src/pairs" --raw "$src/raw" --shards 2 --curate-args "--keep 100%"
          --build-args "--teacher-name 'sgm x'" --sbatch-args "--mem=2G")
    /usr/bin/time -f "jobs slurm dataset: %e s" "$BIN" jobs slurm dataset "${args[@]}" \
        --work "$T/work" -o "$T/set" --wait
    [[ -f "$T/set/manifest.json" && -d "$T/set/disparity_maps/sgm x" ]] && echo "PASS: training set"
    first=$(ls "$src/pairs/L" | sort | head -1)
    mkdir -p "$T/work2/teacher/${first%.*}.iio/x"   # teacher shard 0 cannot write its first pair
    set +e
    /usr/bin/time -f "failing chain: %e s" "$BIN" jobs slurm dataset "${args[@]}" \
        --work "$T/work2" -o "$T/set2" --wait; rc=$?
    set -e
    echo "exit with a failed teacher shard: $rc (expected 2)"; [[ $rc == 2 ]]
    scontrol show job 2>/dev/null | grep -oE "JobName=ss-[a-z-]+|JobState=[A-Z]+|Reason=[A-Za-z]+" \
        | paste - - - | tail -12 || true
    cat "$T/work2/jobs/logs/check-teacher-"*.log
    rm -rf "$T/work2/teacher/${first%.*}.iio"
    /usr/bin/time -f "resubmit: %e s" "$BIN" jobs resubmit --work "$T/work2" --wait
    for f in sub1_synchronic sub2_synchronic sub5_syndiach sub3_diachronic; do
        cmp "$T/set/experiments/$f.csv" "$T/set2/experiments/$f.csv"
    done
    echo "PASS: resubmitted the failed shard; same lists"
    exit 0
fi
SIZE=${1:-4096}
W="$T/world"
"$BIN" world --size "$SIZE" --seed 3 --raw -o "$W" >/dev/null
args=("$W/raw/WORLD_3_A.tif" "$W/raw/WORLD_3_B.tif" --rpc-left "$W/rpc/WORLD_3_A.json"
      --rpc-right "$W/rpc/WORLD_3_B.json" --median-filter 5 --max-memory 1.5)
/usr/bin/time -f "local reconstruct: %e s" "$BIN" reconstruct "${args[@]}" -o "$T/local.tif" | tail -1
/usr/bin/time -f "jobs slurm reconstruct: %e s" "$BIN" jobs slurm reconstruct "${args[@]}" -o "$T/out dir/dsm.tif" --wait
cmp "$T/local.tif" "$T/out dir/dsm.tif" && echo "PASS: DSM byte-identical to the local reconstruct"

cp "$W/raw/WORLD_3_A.tif" "$T/good.tif"
python3 - "$W/raw/WORLD_3_A.tif" <<'PY'
import sys
p = sys.argv[1]; b = bytearray(open(p, 'rb').read())
# Damage the last 64 KiB of pixel data (the image's last TIFF tiles): the tiles reading them fail.
b[len(b) - 65536:len(b) - 1024] = b'\xa5' * (65536 - 1024)
open(p, 'wb').write(bytes(b))
PY
set +e
"$BIN" jobs slurm reconstruct "${args[@]}" -o "$T/failing/dsm.tif" --wait; rc=$?
set -e
echo "merge exit with a damaged image: $rc (expected 3)"; [[ $rc == 3 ]]
sacct -X -n -o JobID,State,ExitCode 2>/dev/null | tail -5 || true
"$BIN" jobs status --work "$T/failing/dsm_work" || true
cp "$T/good.tif" "$W/raw/WORLD_3_A.tif"
"$BIN" jobs resubmit --work "$T/failing/dsm_work" --wait
cmp "$T/local.tif" "$T/failing/dsm.tif" && echo "PASS: resubmitted failed tiles; DSM byte-identical"

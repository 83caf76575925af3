#!/usr/bin/env bash
# A whole satellite scene → one DSM on Slurm: N array tasks share the scene's tiles
# (`seasonstereo reconstruct --shard I/N`: the tiles at positions ≡ I mod N of the plan), all
# writing into one --work folder on a shared file system; then one merge task assembles the DSM.
# Every tile leaves tiles/<id>.json (status, time, disparity range, coverage) and tiles/<id>.tif,
# so a failed or preempted task is just resubmitted: finished tiles are skipped, failed tiles
# retried. The shard that finds every tile finished also writes the DSM; the merge task is the
# safety net (and fails naming the missing tiles if a shard did not finish).
#
# Usage:  LEFT=... RIGHT=... RPC_LEFT=... RPC_RIGHT=... bash docs/jobs/reconstruct-slurm.sh
# Memory: --max-memory is per task; keep it under --mem (the process plans its tiles in flight
# to stay under it).
set -euo pipefail

LEFT=${LEFT:?the left raw image (GeoTIFF)}
RIGHT=${RIGHT:?the right raw image}
RPC_LEFT=${RPC_LEFT:-}                # SatNeRF/rpcm JSON, else the images' RPC tags
RPC_RIGHT=${RPC_RIGHT:-}
OUT=${OUT:-dsm.tif}                   # Cloud-Optimized GeoTIFF
WORK=${WORK:-${OUT%.tif}_work}        # shared by every task
N=${N:-32}                            # array tasks
BIN=${BIN:-seasonstereo}
MEM_GIB=${MEM_GIB:-8}
SBATCH_COMMON=(--cpus-per-task=4 --mem=$((MEM_GIB + 2))G --time=02:00:00)

cameras=()
[[ -n "$RPC_LEFT" ]] && cameras+=(--rpc-left "$RPC_LEFT")
[[ -n "$RPC_RIGHT" ]] && cameras+=(--rpc-right "$RPC_RIGHT")
cmd="$BIN reconstruct $LEFT $RIGHT ${cameras[*]} --tile 1024 --collar 64 --max-memory $MEM_GIB --work $WORK -o $OUT"
mkdir -p logs

tiles=$(sbatch --parsable --job-name=ss-tiles --array=0-$((N - 1)) "${SBATCH_COMMON[@]}" \
    --output="logs/tiles-%A_%a.log" --wrap="$cmd --shard \$SLURM_ARRAY_TASK_ID/$N")
merge=$(sbatch --parsable --job-name=ss-merge --dependency=afterany:"$tiles" "${SBATCH_COMMON[@]}" \
    --output="logs/merge-%j.log" --wrap="$cmd --merge")
echo "submitted: tiles=$tiles merge=$merge (failed tiles: grep -l '\"failed\"' $WORK/tiles/*.json)"

#!/usr/bin/env bash
# Every date of an area → one DSM on Slurm: an array of N tasks shares the chosen pairs' tiles
# (`reconstruct-many --shard $SLURM_ARRAY_TASK_ID/N`, pair k's tiles at positions p with
# p + k ≡ task mod N), then one task, after them all, reruns the same command without a shard: it
# retries any failed tile, assembles each pair's DSM and fuses them. Every task shares --work on
# a shared file system (NFS, Lustre), and sees the binary and the inputs at the same paths.
#
# Usage:  N=8 bash docs/jobs/reconstruct-many-slurm.sh IMAGE... --rpc-dir DIR -o dsm.tif \
#             --work dsm_work [reconstruct-many options]
# Environment: N (array tasks, default 4), BIN (default seasonstereo), SBATCH_ARGS (e.g. "-p long
# --mem=8G", given to both jobs). Prints the two job ids; the fused DSM's log is the second job's.
set -euo pipefail
N="${N:-4}"
BIN="${BIN:-seasonstereo}"
case " $* " in
*" --work "* | *" --work="*) ;;
*) echo "give --work DIR (a folder every node sees): the shards meet there" >&2; exit 1 ;;
esac
command=$(printf '%q ' "$BIN" reconstruct-many "$@")
# shellcheck disable=SC2086 # SBATCH_ARGS is a list of sbatch options.
tiles=$(sbatch --parsable ${SBATCH_ARGS:-} --job-name=ss-many-tiles --array="0-$((N - 1))" \
    --wrap "$command --shard \$SLURM_ARRAY_TASK_ID/$N")
# shellcheck disable=SC2086
fuse=$(sbatch --parsable ${SBATCH_ARGS:-} --job-name=ss-many-fuse \
    --dependency="afterany:${tiles%%;*}" --wrap "$command")
echo "tiles: job ${tiles%%;*} ($N tasks); fusion: job ${fuse%%;*} (after them)"

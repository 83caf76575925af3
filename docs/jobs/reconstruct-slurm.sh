#!/usr/bin/env bash
# A whole satellite scene → one DSM on Slurm, with `seasonstereo jobs slurm reconstruct`: an array
# of tile tasks sized to the scene's tile plan and a merge task after them, all sharing one --work
# folder on a shared file system. Any `reconstruct` option can follow the images.
#
# Usage:  bash docs/jobs/reconstruct-slurm.sh left.tif right.tif --rpc-left l.json \
#             --rpc-right r.json -o dsm.tif [reconstruct options] [--sbatch-args "-p long"]
# Follow: seasonstereo jobs status --work dsm_work; rerun failed tiles: seasonstereo jobs
# resubmit --work dsm_work
set -euo pipefail
exec "${BIN:-seasonstereo}" jobs slurm reconstruct "$@" --wait

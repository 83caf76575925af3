#!/usr/bin/env bash
# A sharded SeasonStereo training-set build on Slurm, from a login node: teacher → curate →
# synthesize → masks → dataset build, one array job of N tasks (`--shard I/N`) per stage, then one
# unsharded `dataset build` that writes the lists and manifest.json. This only calls
# `seasonstereo jobs slurm dataset`, which writes the job scripts (every argument quoted) into
# $WORK/jobs/ and chains the stages with a check step after each (`afterany`): a failed shard
# makes the check fail, naming it and the resubmit command, and cancels the later stages
# (`afterok` + `--kill-on-invalid-dep=yes`) instead of leaving them pending for ever.
# Then: seasonstereo jobs status --work $WORK ; seasonstereo jobs resubmit --work $WORK
#
# Usage:  bash docs/jobs/slurm-array.sh            (set the variables below or in the environment)
# Inputs: $DATA/synchronic_only/{L,R,homography}   (the release's layout or `seasonstereo rectify`)
#         $DATA/raw/**/<image id>.tif              (raw tiles of the pairs' image ids)
# MonSter++ teacher: TEACHER_ARGS="--model monsterpp --weights checkpoints/monster++-mix_all.pth
# --config vitl" and a GPU in SBATCH_ARGS. Generative seasons: SYNTH_ARGS="--generator gemini
# --prompts seasons.toml" (key in $GEMINI_API_KEY on the nodes).
set -euo pipefail

DATA=${DATA:-data}                            # inputs
WORK=${WORK:-work}                            # intermediate outputs of the stages, and jobs/
OUT=${OUT:-data/diachronic-stereo-synthetic}  # the training set
N=${N:-16}                                    # shards (array tasks) per stage
BIN=${BIN:-seasonstereo}

"$BIN" jobs slurm dataset --pairs "$DATA/synchronic_only" --raw "$DATA/raw" --work "$WORK" \
    -o "$OUT" --shards "$N" \
    --teacher-args "${TEACHER_ARGS:-}" --curate-args "${CURATE_ARGS:---keep 1000}" \
    --synthesize-args "${SYNTH_ARGS:-}" --masks-args "${MASKS_ARGS:-}" \
    --sbatch-args "${SBATCH_ARGS:---cpus-per-task=8 --mem=32G --time=04:00:00}" "$@"

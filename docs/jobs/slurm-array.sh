#!/usr/bin/env bash
# A sharded SeasonStereo training-set build on Slurm: one array job per stage, each waiting for the
# previous one (afterok). Every stage takes `--shard I/N` (0-based I, the items at positions ≡ I
# mod N of the sorted work list), skips finished items and writes atomically, so a failed or
# preempted task is simply resubmitted (`sbatch --array=<failed ids>` or rerun this script).
#
# Usage:  bash docs/jobs/slurm-array.sh            (edit the paths and N first)
# Inputs: $DATA/synchronic_only/{L,R,homography}   (the release's layout or `seasonstereo rectify`)
#         $DATA/raw/**/<image id>.tif              (raw tiles of the pairs' image ids)
set -euo pipefail

DATA=${DATA:-data}                       # inputs
WORK=${WORK:-work}                       # intermediate outputs of the stages
OUT=${OUT:-data/diachronic-stereo-synthetic}  # the training set
N=${N:-16}                               # shards (array tasks) per stage
BIN=${BIN:-seasonstereo}
SBATCH_COMMON=(--cpus-per-task=8 --mem=32G --time=04:00:00)

submit() {  # submit NAME DEPENDENCY COMMAND… ; prints the job id
    local name=$1 dep=$2; shift 2
    local deps=()
    [[ -n "$dep" ]] && deps=(--dependency=afterok:"$dep")
    sbatch --parsable --job-name="ss-$name" --array=0-$((N - 1)) "${SBATCH_COMMON[@]}" ${deps[@]+"${deps[@]}"} \
        --output="logs/$name-%A_%a.log" \
        --wrap="$* --shard \$SLURM_ARRAY_TASK_ID/$N"
}
mkdir -p logs

# 1. Teacher disparities of every real pair (SGM offline; MonSter++: add
#    --model monsterpp --weights checkpoints/monster++-mix_all.pth --config vitl and a GPU).
teacher=$(submit teacher "" "$BIN teacher --pairs $DATA/synchronic_only -o $WORK/teacher")

# 2. Curation: every shard scores its pairs; the last one to finish ranks and writes selected.txt.
curate=$(submit curate "$teacher" "$BIN curate --pairs $DATA/synchronic_only --teacher $WORK/teacher -o $WORK/curate --keep 1000")

# 3. Seasonal variants of the selected pairs' images (centre crop 1024, fidelity check, rectified).
#    For the generative API: --generator gemini --prompts seasons.toml (key in $GEMINI_API_KEY).
synth=$(submit synthesize "$curate" "$BIN synthesize --pairs $DATA/synchronic_only --raw $DATA/raw --selected $WORK/curate/selected.txt -o $WORK/synthetic")

# 4. Water/tree/building masks of the crops written by synthesize.
masks=$(submit masks "$synth" "$BIN masks --images $WORK/synthetic/cropped -o $WORK/masks")

# 5. The training set: 25 combinations per pair, masks, disparities. The last shard to finish
#    writes the subsets (S1/S2/S3) and manifest.json.
build=$(submit build "$masks" "$BIN dataset build --pairs $DATA/synchronic_only --selected $WORK/curate/selected.txt --synthetic $WORK/synthetic --masks $WORK/masks --teacher $WORK/teacher -o $OUT")

# 6. Safety net: one unsharded pass (every pair is skipped) that (re)writes the lists and manifest.
fin=$(sbatch --parsable --job-name=ss-finalize --dependency=afterok:"$build" "${SBATCH_COMMON[@]}" \
    --output=logs/finalize-%j.log \
    --wrap="$BIN dataset build --pairs $DATA/synchronic_only --selected $WORK/curate/selected.txt --synthetic $WORK/synthetic --masks $WORK/masks --teacher $WORK/teacher -o $OUT")
echo "submitted: teacher=$teacher curate=$curate synthesize=$synth masks=$masks build=$build finalize=$fin"

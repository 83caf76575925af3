#!/usr/bin/env bash
# The real-imagery benchmark of the README and BENCHMARKS.md: `seasonstereo reconstruct` on the
# DFC2019 JAX_068 development pairs (read in place from ../shared/data/dfc2019-jax068-dev), each
# DSM scored against the LiDAR truth with the benchmark's metric (NCC shift, vertical offset,
# foliage masked) and its coverage.
#
#   scripts/jax-dev-benchmark.sh [OUT] [-- extra reconstruct flags, e.g. --method sgm]
#
# Prints one line per pair and the means of the near-synchronic and cross-season groups; writes
# OUT/results.tsv (default OUT: out/jax-dev). Then scores the same disparities with
# `seasonstereo eval` (the released benchmark's protocol: centre crop, 32-px trim, highest point
# per cell, no hole filling) and prints its table (OUT/eval/pairs.csv).
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-out/jax-dev}
[ $# -gt 0 ] && shift
[ "${1:-}" = "--" ] && shift
D=${JAX_DEV:-../shared/data/dfc2019-jax068-dev}
BIN=${SEASONSTEREO:-target/release/seasonstereo}
[ -x "$BIN" ] || cargo build --release --quiet
NEAR="014-015 013-014 003-004 004-005 013-015"
CROSS="006-020 012-020 006-014 012-015 006-013 004-013 022-020"
mkdir -p "$OUT"
printf 'group\tpair\tmae_filtered\tcoverage\tseconds\n' > "$OUT/results.tsv"
for group in near cross; do
  pairs=$NEAR; [ $group = cross ] && pairs=$CROSS
  for p in $pairs; do
    l=${p%-*}; r=${p#*-}
    start=$(date +%s.%N)
    "$BIN" reconstruct "$D/images/JAX_068_${l}_RGB.tif" "$D/images/JAX_068_${r}_RGB.tif" \
      --rpc-left "$D/rpcs/ba/JAX_068_${l}_RGB.json" --rpc-right "$D/rpcs/ba/JAX_068_${r}_RGB.json" \
      --like "$D/truth/JAX_068_DSM.tif" --truth "$D/truth/JAX_068_DSM.tif" \
      -o "$OUT/$p.tif" "$@" > "$OUT/$p.log" 2>&1 || { echo "$p failed:"; tail -3 "$OUT/$p.log"; exit 1; }
    secs=$(echo "$(date +%s.%N) - $start" | bc)
    line=$(grep '^vs truth:' "$OUT/$p.log")
    mae=$(echo "$line" | sed -E 's/.*MAE filtered ([0-9.]+) m.*/\1/')
    cov=$(echo "$line" | sed -E 's/.*coverage ([0-9.]+) %.*/\1/')
    printf '%s\t%s\t%s\t%s\t%.1f\n' $group $p $mae $cov $secs | tee -a "$OUT/results.tsv"
  done
done
awk -F'\t' 'NR > 1 { m[$1] += $3; c[$1] += $4; n[$1]++; if (min[$1] == "" || $4 < min[$1]) min[$1] = $4 }
  END { for (g in n) printf "%s: mean MAE %.3f m, mean coverage %.1f %% (min %.1f %%) over %d pairs\n", g, m[g]/n[g], c[g]/n[g], min[g], n[g];
        if (n["near"] && n["cross"]) printf "cross/near MAE ratio %.2f\n", (m["cross"]/n["cross"])/(m["near"]/n["near"]) }' "$OUT/results.tsv"

# The same disparities through the benchmark's evaluator: one split folder per group.
rm -rf "$OUT/split-near" "$OUT/split-cross" "$OUT/pred" "$OUT/eval"
mkdir -p "$OUT/pred"
for group in near cross; do
  pairs=$NEAR; [ $group = cross ] && pairs=$CROSS
  SPLIT="$OUT/split-$group"
  mkdir -p "$SPLIT/L" "$SPLIT/R" "$SPLIT/homography"
  for p in $pairs; do
    w="$OUT/${p}_work"
    for sub in L R homography; do
      for f in "$w/$sub"/*; do ln -sf "$(realpath "$f")" "$SPLIT/$sub/"; done
    done
    for f in "$w/disparity"/*; do ln -sf "$(realpath "$f")" "$OUT/pred/"; done
  done
done
"$BIN" eval --split "near-synchronic=$OUT/split-near" --split "cross-season=$OUT/split-cross" \
  --rpc-dir "$D/rpcs/ba" --truth-dir "$D/truth" --predictions "$OUT/pred" \
  --name "seasonstereo (benchmark protocol)" -o "$OUT/eval" 2>/dev/null | grep -v '^$' | head -8

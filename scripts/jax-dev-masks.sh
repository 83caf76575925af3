#!/usr/bin/env bash
# The masks benchmark of BENCHMARKS.md ("Masks on real imagery"): the offline segmenters on the
# 10 DFC2019 JAX_068 development images (read in place from ../shared/data/dfc2019-jax068-dev),
# scored against the LiDAR classes with `seasonstereo masks-score`.
#
#   scripts/jax-dev-masks.sh [OUT]
#
# rectify + teacher (the default SGM) on the 12 dev pairs give the heights; then `masks` with the
# rules (with heights, and colour only) and with the previous pixel classifier; one table each.
# Last, the registration check: each pair's DSM on the truth grid (`dsm --like`), and the rules'
# masks scored again with the truth moved by the benchmark's shift of those DSMs (--register).
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-out/jax-dev-masks}
D=${JAX_DEV:-../shared/data/dfc2019-jax068-dev}
BIN=${SEASONSTEREO:-target/release/seasonstereo}
[ -x "$BIN" ] || cargo build --release --quiet
PAIRS="014-015 013-014 003-004 004-005 013-015 006-020 012-020 006-014 012-015 006-013 004-013 022-020"
mkdir -p "$OUT"
for p in $PAIRS; do
  l=${p%-*}; r=${p#*-}
  [ -f "$OUT/pairs/rectify/JAX_068_${l}_RGB-JAX_068_${r}_RGB.json" ] && continue
  "$BIN" rectify "$D/images/JAX_068_${l}_RGB.tif" "$D/images/JAX_068_${r}_RGB.tif" \
    --rpc-left "$D/rpcs/ba/JAX_068_${l}_RGB.json" --rpc-right "$D/rpcs/ba/JAX_068_${r}_RGB.json" \
    -o "$OUT/pairs" > /dev/null
done
"$BIN" teacher --pairs "$OUT/pairs" -o "$OUT/teacher" > /dev/null
run() { # name, masks flags...
  local name=$1; shift
  local start; start=$(date +%s.%N)
  "$BIN" masks --images "$D/images" -o "$OUT/$name" "$@" > "$OUT/$name.log"
  printf '\n### %s (%.1f s for 10 images)\n' "$name" "$(echo "$(date +%s.%N) - $start" | bc)"
  "$BIN" masks-score --masks "$OUT/$name" --rpc-dir "$D/rpcs/ba" --truth "$D/truth/JAX_068_DSM.tif"
}
run rules-heights --pairs "$OUT/pairs" --disparities "$OUT/teacher"
run rules-colour
run pixel-classifier --segmenter pixel-classifier
mkdir -p "$OUT/dsm"
for f in "$OUT"/pairs/rectify/*.json; do
  s=$(basename "$f" .json); l=${s%-JAX*}; r=${s#*RGB-}
  [ -f "$OUT/dsm/$s.tif" ] || "$BIN" dsm "$OUT/teacher/$s.iio" --homography "$OUT/pairs/homography/$s.npz" \
    --rpc-left "$D/rpcs/ba/$l.json" --rpc-right "$D/rpcs/ba/$r.json" --like "$D/truth/JAX_068_DSM.tif" \
    -o "$OUT/dsm/$s.tif" > /dev/null
done
printf '\n### rules-heights, truth registered by the pairs DSMs\n'
"$BIN" masks-score --masks "$OUT/rules-heights" --rpc-dir "$D/rpcs/ba" --truth "$D/truth/JAX_068_DSM.tif" \
  --register "$OUT"/dsm/*.tif

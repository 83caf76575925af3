#!/usr/bin/env bash
# All 45 pairs of the ten DFC2019 JAX_068 development images (read in place from
# ../shared/data/dfc2019-jax068-dev): `seasonstereo reconstruct` on each, scored against the
# LiDAR truth with the benchmark's metric (MAE filtered, coverage, within 1 m / 2 m), and for the
# 12 pairs with an s2p DSM `score --against` it on the cells both cover. Each pair is tagged with
# its date gap (days), its baseline (the disparity range in pixels that the scene's altitude range
# spans, from the tile records) and the angle between the two sun directions; the pairs are binned
# near-synchronic (<= 30 days) / cross-season (> 30 days) x narrow / wide baseline (split at the
# median disparity range) and the bins' means printed as a Markdown table.
#
#   scripts/jax-dev-all-pairs.sh [OUT] [-- extra reconstruct flags, e.g. --fill-holes 0]
#
# OUT (default out/jax-all) gets <pair>.tif, its log and score JSON, pairs.tsv and bins.md.
# A pair whose <pair>.seconds exists is not reconstructed again, one whose score JSON exists not
# scored again (delete OUT, or use another, after changing flags; delete OUT/*.score.json to
# score again). SEASONSTEREO names the binary (default target/release/seasonstereo). S2P_EXTRA
# names a folder of more s2p DSMs, <pair>.tif in this script's pair order (e.g. from
# scripts/s2p_pair.py), compared like the data set's own where the set has none.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-out/jax-all}
[ $# -gt 0 ] && shift
[ "${1:-}" = "--" ] && shift
D=${JAX_DEV:-../shared/data/dfc2019-jax068-dev}
BIN=${SEASONSTEREO:-target/release/seasonstereo}
[ -x "$BIN" ] || { echo "$BIN: no binary; build it (cargo build --release) or set SEASONSTEREO"; exit 1; }
[ -d "$D/images" ] || { echo "$D: no DFC2019 JAX_068 dev data; set JAX_DEV to its folder"; exit 1; }
T="$D/truth/JAX_068_DSM.tif"
IDS="003 004 005 006 012 013 014 015 020 022"
mkdir -p "$OUT"
for a in $IDS; do
  for b in $IDS; do
    [[ "$a" < "$b" ]] || continue
    l=$a; r=$b
    # s2p's order (its first image the reference) where it made the pair.
    [ -f "$D/s2p/truth-grid/$b-$a.tif" ] && { l=$b; r=$a; }
    p="$l-$r"
    if [ ! -f "$OUT/$p.seconds" ]; then
      rm -rf "$OUT/$p.tif" "$OUT/${p}_filled.tif" "$OUT/${p}_work" "$OUT/$p.score.json"
      start=$(date +%s.%N)
      "$BIN" reconstruct "$D/images/JAX_068_${l}_RGB.tif" "$D/images/JAX_068_${r}_RGB.tif" \
        --rpc-left "$D/rpcs/ba/JAX_068_${l}_RGB.json" --rpc-right "$D/rpcs/ba/JAX_068_${r}_RGB.json" \
        --like "$T" -o "$OUT/$p.tif" "$@" > "$OUT/$p.log" 2>&1 \
        || { echo "$p failed:"; tail -3 "$OUT/$p.log"; exit 1; }
      echo "$(date +%s.%N) - $start" | bc > "$OUT/$p.seconds.tmp"
      mv "$OUT/$p.seconds.tmp" "$OUT/$p.seconds"
    fi
    if [ ! -f "$OUT/$p.score.json" ]; then
      against=()
      for s2p in "$D/s2p/truth-grid/$p.tif" ${S2P_EXTRA:+"$S2P_EXTRA/$p.tif"}; do
        [ -f "$s2p" ] && { against=(--against "$s2p"); break; }
      done
      "$BIN" score "$OUT/$p.tif" "${against[@]}" --truth "$T" --json "$OUT/$p.score.json.tmp" \
        >> "$OUT/$p.log"
      mv "$OUT/$p.score.json.tmp" "$OUT/$p.score.json"
    fi
    echo "$p $(cat "$OUT/$p.seconds") s"
  done
done
python3 scripts/jax_dev_bins.py "$D" "$OUT" | tee "$OUT/bins.md"

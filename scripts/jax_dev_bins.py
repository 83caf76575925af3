#!/usr/bin/env python3
"""Tables of scripts/jax-dev-all-pairs.sh: every pair's tags and scores (OUT/pairs.tsv) and the
means per bin (near-synchronic <= 30 days / cross-season > 30 days x narrow / wide baseline, split
at the median disparity range) as Markdown on stdout, plus a "very-narrow" row (under
VERY_NARROW_PX_PER_M pixels of disparity per metre of altitude, either date gap) where the
held-out narrow-baseline pairs live.

    python3 scripts/jax_dev_bins.py DATA_DIR OUT
"""

import glob
import json
import math
import os
import statistics
import sys
from datetime import datetime

NEAR_DAYS = 30
# Held-out pairs have disparity ranges of 45-55 px; on the dev pairs a range that narrow goes with
# 0.2-0.5 px of disparity per metre of altitude (the range is mostly the disparity's drift across
# the frame, not the relief). The dev pairs under this slope (>= 1.5 m of height per pixel) are the
# closest to them, so they get their own row on top of the four bins.
VERY_NARROW_PX_PER_M = 0.65


def camera(data, ident):
    with open(os.path.join(data, "rpcs", "ba", f"JAX_068_{ident}_RGB.json")) as f:
        d = json.load(f)
    when = datetime.strptime(d["acquisition_date"], "%Y%m%d%H%M%S")
    return when, float(d["sun_elevation"]), float(d["sun_azimuth"])


def sun_angle(a, b):
    """Angle between two sun directions (elevation, azimuth in degrees), degrees."""

    def vec(el, az):
        el, az = math.radians(el), math.radians(az)
        return (math.cos(el) * math.sin(az), math.cos(el) * math.cos(az), math.sin(el))

    u, v = vec(*a), vec(*b)
    dot = max(-1.0, min(1.0, sum(x * y for x, y in zip(u, v))))
    return math.degrees(math.acos(dot))


def baseline(work):
    """Width of the union of the tiles' disparity ranges in raw pixels (a stretched tile's range
    divided by its stretch), and the tiles' mean disparity per metre of altitude (raw pixels)."""
    lo, hi, slopes = None, None, []
    for path in glob.glob(os.path.join(work, "tiles", "*.json")):
        with open(path) as f:
            record = json.load(f)
        r, stretch = record.get("disparity_range"), record.get("stretch") or 1.0
        if r:
            lo = r[0] / stretch if lo is None else min(lo, r[0] / stretch)
            hi = r[1] / stretch if hi is None else max(hi, r[1] / stretch)
        if record.get("pixels_per_metre"):
            slopes.append(record["pixels_per_metre"])
    if lo is None or not slopes:
        sys.exit(f"{work}/tiles: no tile record with a disparity range and slope; rerun the pair")
    return round(hi - lo), sum(slopes) / len(slopes)


def pair_row(data, out, pair):
    left, right = pair.split("-")
    (t0, *sun0), (t1, *sun1) = camera(data, left), camera(data, right)
    with open(os.path.join(out, f"{pair}.score.json")) as f:
        rec = json.loads(f.readline())
    ours = rec.get("ours", rec)
    span, slope = baseline(os.path.join(out, f"{pair}_work"))
    row = {
        "pair": pair,
        "days": abs((t1 - t0).total_seconds()) / 86400.0,
        "sun_deg": sun_angle(sun0, sun1),
        "disp_px": span,
        "px_per_m": slope,
        "mae": ours["mae_filtered"],
        "coverage": ours["coverage"],
        "within_1m": ours["within_1m"],
        "within_2m": ours["within_2m"],
        "seconds": float(open(os.path.join(out, f"{pair}.seconds")).read()),
    }
    if "other" in rec:
        row.update(
            s2p_mae=rec["other"]["mae_filtered"],
            s2p_coverage=rec["other"]["coverage"],
            s2p_within_1m=rec["other"]["within_1m"],
            common_cells=rec["common_ours"]["cells"],
            common_ours=rec["common_ours"]["mae"],
            common_s2p=rec["common_other"]["mae"],
            only_ours_cells=rec["only_ours"]["cells"],
            only_ours=rec["only_ours"]["mae"],
            only_s2p_cells=rec["only_other"]["cells"],
            only_s2p=rec["only_other"]["mae"],
        )
    return row


def in_view(row, view):
    """Whether `row` belongs to `view`: a bin name, "very-narrow" or "all"."""
    if view == "all":
        return True
    if view == "very-narrow":
        return row["px_per_m"] < VERY_NARROW_PX_PER_M
    return row["bin"] == view


def mean(rows, key):
    vals = [r[key] for r in rows if r.get(key) is not None]
    return sum(vals) / len(vals) if vals else float("nan")


def main():
    data, out = sys.argv[1], sys.argv[2]
    pairs = sorted(
        os.path.basename(p)[: -len(".score.json")]
        for p in glob.glob(os.path.join(out, "*.score.json"))
    )
    if not pairs:
        sys.exit(f"{out}: no <pair>.score.json; run scripts/jax-dev-all-pairs.sh first")
    rows = [pair_row(data, out, p) for p in pairs]
    split = statistics.median(r["disp_px"] for r in rows)
    for r in rows:
        time = "near" if r["days"] <= NEAR_DAYS else "cross"
        base = "narrow" if r["disp_px"] <= split else "wide"
        r["bin"] = f"{time}-{base}"
    keys = list(rows[0].keys())
    for r in rows:
        keys += [k for k in r if k not in keys]
    with open(os.path.join(out, "pairs.tsv"), "w") as f:
        f.write("\t".join(keys) + "\n")
        for r in rows:
            f.write("\t".join(fmt(r.get(k)) for k in keys) + "\n")
    print(f"{len(rows)} pairs; baseline split at the median disparity range, {split:g} px\n")
    print("| bin | pairs | days | sun Δ° | disparity px | px per m | MAE m | coverage % | within 1 m % | within 2 m % | s per pair |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    bins = ["near-narrow", "near-wide", "cross-narrow", "cross-wide"]
    for b in bins + ["very-narrow", "all"]:
        sel = [r for r in rows if in_view(r, b)]
        if not sel:
            continue
        print(
            f"| {b} | {len(sel)} | {mean(sel, 'days'):.0f} | {mean(sel, 'sun_deg'):.1f} | "
            f"{mean(sel, 'disp_px'):.0f} | {mean(sel, 'px_per_m'):.2f} | {mean(sel, 'mae'):.3f} | {100 * mean(sel, 'coverage'):.1f} | "
            f"{100 * mean(sel, 'within_1m'):.1f} | {100 * mean(sel, 'within_2m'):.1f} | {mean(sel, 'seconds'):.1f} |"
        )
    s2p = [r for r in rows if "s2p_mae" in r]
    if not s2p:
        return
    print("\nThe pairs with an s2p DSM (`score --against`): each DSM registered on its own; common = truth cells both cover.\n")
    print("| pair | bin | ours MAE / cov % / ≤1 m % | s2p MAE / cov % / ≤1 m % | common cells | ours on common | s2p on common | only ours: cells, MAE | only s2p: cells, MAE |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in s2p:
        print(
            f"| {r['pair']} | {r['bin']} | {r['mae']:.3f} / {100 * r['coverage']:.1f} / {100 * r['within_1m']:.1f} | "
            f"{r['s2p_mae']:.3f} / {100 * r['s2p_coverage']:.1f} / {100 * r['s2p_within_1m']:.1f} | "
            f"{r['common_cells']} | {r['common_ours']:.3f} | {r['common_s2p']:.3f} | "
            f"{r['only_ours_cells']}, {fmt(r['only_ours'])} | {r['only_s2p_cells']}, {fmt(r['only_s2p'])} |"
        )
    print("\n| bin (s2p pairs) | pairs | ours MAE | s2p MAE | ours on common | s2p on common | ours within 1 m % | s2p within 1 m % | ours cov % | s2p cov % |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for b in bins + ["very-narrow", "all"]:
        sel = [r for r in s2p if in_view(r, b)]
        if not sel:
            continue
        print(
            f"| {b} | {len(sel)} | {mean(sel, 'mae'):.3f} | {mean(sel, 's2p_mae'):.3f} | "
            f"{mean(sel, 'common_ours'):.3f} | {mean(sel, 'common_s2p'):.3f} | "
            f"{100 * mean(sel, 'within_1m'):.1f} | {100 * mean(sel, 's2p_within_1m'):.1f} | "
            f"{100 * mean(sel, 'coverage'):.1f} | {100 * mean(sel, 's2p_coverage'):.1f} |"
        )


def fmt(v):
    if v is None:
        return "-"
    if isinstance(v, float):
        return f"{v:.4f}"
    return str(v)


if __name__ == "__main__":
    main()

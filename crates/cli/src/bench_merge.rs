//! `seasonstereo bench merge`: the assembly of a whole-scene DSM timed without stereo, on a work
//! folder of fabricated finished tiles (made once, then reused), to check its memory at scale.

use std::path::{Path, PathBuf};

use anyhow::Result;
use seasonstereo::bench::{peak_rss_bytes, MergeTiming};

/// Fabricates (or reuses) a `cells × cells` work folder under `work`, then merges it as
/// `reconstruct` does by default (median gridding, filling, median filter), `block_rows` rows at
/// a time, into `work/dsm.tif`.
pub fn run(
    cells: usize,
    block_rows: Option<usize>,
    work: Option<PathBuf>,
    json: bool,
) -> Result<()> {
    if cells == 0 {
        anyhow::bail!("--cells must be at least 1");
    }
    let work = work
        .unwrap_or_else(|| std::env::temp_dir().join(format!("seasonstereo-bench-merge-{cells}")));
    let timing = seasonstereo::bench::merge(&work, cells, block_rows)?;
    let peak = peak_rss_bytes().map(mib);
    if json {
        println!("{}", json_line(cells, &work, &timing, peak));
    } else {
        print_sentence(cells, &work, &timing, peak);
    }
    Ok(())
}

/// Bytes in MiB.
fn mib(bytes: u64) -> f64 {
    bytes as f64 / (1u64 << 20) as f64
}

/// `--json`: one line with every figure.
fn json_line(cells: usize, work: &Path, t: &MergeTiming, peak: Option<f64>) -> String {
    serde_json::json!({
        "workload": "merge", "cells": cells, "tiles": t.tiles,
        "block_rows": t.block_rows, "fabricate_s": t.fabricate_s, "merge_s": t.merge_s,
        "estimate_mib": mib(t.estimate_bytes), "peak_rss_mib": peak,
        "measured_cells": t.measured_cells, "filled_cells": t.filled_cells,
        "work": work,
    })
    .to_string()
}

/// The sentence: sizes, times, the estimate against the peak RSS, the cells.
fn print_sentence(cells: usize, work: &Path, t: &MergeTiming, peak: Option<f64>) {
    println!(
        "merge {cells}x{cells} cells ({} tiles, blocks of {} rows) in {}: tiles made or found in \
         {:.1} s, merged in {:.1} s (estimate {:.0} MiB), peak RSS {}; {} cells measured, {} \
         after filling",
        t.tiles,
        t.block_rows,
        work.display(),
        t.fabricate_s,
        t.merge_s,
        mib(t.estimate_bytes),
        peak.map_or("n/a".into(), |m| format!("{m:.0} MiB")),
        t.measured_cells,
        t.filled_cells
    );
}

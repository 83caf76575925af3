//! `seasonstereo bench merge`: the assembly of a whole-scene DSM timed without stereo, on a work
//! folder of fabricated finished tiles (made once, then reused), to check its memory at scale.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Result;
use reconstruct::fabricated::fabricate_tiles;
use reconstruct::folder::TileFolder;
use reconstruct::merge::{merge_memory, merge_tiles, Finishing, MERGE_BLOCK_ROWS};

/// Cells on each side of a fabricated tile (a 1024-pixel tile at about the images' resolution).
const TILE_CELLS: usize = 1024;

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
    let t = Instant::now();
    let made = fabricate_tiles(&work, (cells, cells), TILE_CELLS)?;
    let fabricated = t.elapsed().as_secs_f64();
    let finishing = Finishing::default();
    let block_rows = block_rows.unwrap_or(MERGE_BLOCK_ROWS).max(1);
    let estimate = merge_memory(&made.grid, &finishing, block_rows);
    let t = Instant::now();
    let output = work.join("dsm.tif");
    let folder = TileFolder::new(&work);
    let dsm = merge_tiles(
        &finishing,
        &made.grid,
        &folder,
        &made.records,
        &output,
        block_rows,
    )?;
    let merged = t.elapsed().as_secs_f64();
    let mib = |b: u64| b as f64 / (1u64 << 20) as f64;
    let peak = train::metrics::peak_rss_bytes().map(mib);
    if json {
        let v = serde_json::json!({
            "workload": "merge", "cells": cells, "tiles": made.records.len(),
            "block_rows": block_rows, "fabricate_s": fabricated, "merge_s": merged,
            "estimate_mib": mib(estimate), "peak_rss_mib": peak,
            "measured_cells": dsm.measured_cells, "filled_cells": dsm.filled_cells,
            "work": work,
        });
        println!("{v}");
    } else {
        println!(
            "merge {cells}x{cells} cells ({} tiles, blocks of {block_rows} rows) in {}: tiles \
             made or found in {fabricated:.1} s, merged in {merged:.1} s (estimate {:.0} MiB), \
             peak RSS {}; {} cells measured, {} after filling",
            made.records.len(),
            work.display(),
            mib(estimate),
            peak.map_or("n/a".into(), |m| format!("{m:.0} MiB")),
            dsm.measured_cells,
            dsm.filled_cells
        );
    }
    Ok(())
}

//! What `seasonstereo bench` times: the networks' passes and a training step with random
//! weights (feature `network`), and the assembly of a whole-scene DSM from fabricated finished
//! tiles ([`merge`]), with the figures they report.

use std::path::Path;
use std::time::Instant;

use reconstruct::fabricated::fabricate_tiles;
use reconstruct::finishing::Finishing;
use reconstruct::folder::TileFolder;
use reconstruct::merge::{merge_memory, merge_tiles, MERGE_BLOCK_ROWS};

use crate::Result;

pub use eval::aggregate::median;
#[cfg(feature = "network")]
pub use nn::bench::{dinov3, monster, segformer, Workload};
#[cfg(feature = "network")]
pub use nn::device::Device;
#[cfg(feature = "network")]
pub use nn::profile::{GroupTime, Recording};
#[cfg(feature = "network")]
pub use train::bench::{step_config, train_step};
#[cfg(feature = "network")]
pub use train::metrics::peak_rss_bytes;

/// Cells on each side of a fabricated tile (a 1024-pixel tile at about the images' resolution).
const TILE_CELLS: usize = 1024;

/// What a timed merge did and took.
#[derive(Clone, Debug)]
pub struct MergeTiming {
    /// Tiles of the fabricated work folder.
    pub tiles: usize,
    /// Rows of the DSM finished at once.
    pub block_rows: usize,
    /// Seconds to fabricate the tiles (or find them made).
    pub fabricate_s: f64,
    /// Seconds of the merge.
    pub merge_s: f64,
    /// The merge's memory estimate, bytes.
    pub estimate_bytes: u64,
    /// Cells with a measured height.
    pub measured_cells: usize,
    /// Cells with a height after the filling.
    pub filled_cells: usize,
}

/// Fabricates (or reuses) a `cells × cells` work folder in `work`, then merges it as
/// `reconstruct` does by default (median gridding, filling, median filter, the confidence),
/// `block_rows` rows at a time (default: the merge's own), into `work/dsm.tif`.
pub fn merge(work: &Path, cells: usize, block_rows: Option<usize>) -> Result<MergeTiming> {
    let t = Instant::now();
    let made = fabricate_tiles(work, (cells, cells), TILE_CELLS)?;
    let fabricate_s = t.elapsed().as_secs_f64();
    let finishing = Finishing::default();
    let block_rows = block_rows.unwrap_or(MERGE_BLOCK_ROWS).max(1);
    let estimate_bytes = merge_memory(&made.grid, &finishing, true, block_rows);
    let t = Instant::now();
    let output = work.join("dsm.tif");
    let folder = TileFolder::new(work);
    let dsm = merge_tiles(
        &finishing,
        true,
        &made.grid,
        &folder,
        &made.records,
        &output,
        block_rows,
    )?;
    Ok(MergeTiming {
        tiles: made.records.len(),
        block_rows,
        fabricate_s,
        merge_s: t.elapsed().as_secs_f64(),
        estimate_bytes,
        measured_cells: dsm.measured_cells,
        filled_cells: dsm.filled_cells,
    })
}

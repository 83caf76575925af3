//! A work folder of finished tiles made up without stereo, to test and time the DSM's assembly
//! at any size: ground with a gentle slope, box buildings with an occluded (empty) strip beside
//! them, scattered unmatched cells, wide voids the filling cannot close, overlapping tiles that
//! disagree a little, and one failed tile.

use std::path::Path;

use anyhow::Result;
use camera::rectify::Roi;
use camera::{DsmGrid, GridWindow};
use rayon::prelude::*;

use super::folder::TileFolder;
use super::plan::Tile;
use super::tile::{TileRecord, TileStatus};

/// Cells a fabricated tile shares with each neighbour.
const OVERLAP: usize = 8;

/// The grid and the tiles' records of a fabricated work folder.
pub struct Fabricated {
    pub grid: DsmGrid,
    pub records: Vec<TileRecord>,
}

/// Writes `tiles/` under `work` for a `width × height`-cell grid cut into tiles of `tile` cells
/// (plus the overlap), one tile at a time per thread; tiles already there are kept (the same
/// arguments make the same tiles).
pub fn fabricate_tiles(
    work: &Path,
    (width, height): (usize, usize),
    tile: usize,
) -> Result<Fabricated> {
    let grid = DsmGrid::new(500_000.0, 4_000_000.0, 0.5, width, height, 32617)?;
    let folder = TileFolder::new(work);
    std::fs::create_dir_all(folder.dir())?;
    let (across, down) = (width.div_ceil(tile), height.div_ceil(tile));
    let failed = across * down / 3;
    let records = (0..across * down)
        .into_par_iter()
        .map(|index| {
            let (tx, ty) = (index % across, index / across);
            let core = Roi::new(
                tx * tile,
                ty * tile,
                tile.min(width - tx * tile),
                tile.min(height - ty * tile),
            );
            let (x0, y0) = (
                core.x.saturating_sub(OVERLAP),
                core.y.saturating_sub(OVERLAP),
            );
            let x1 = (core.x + core.width + OVERLAP).min(width);
            let y1 = (core.y + core.height + OVERLAP).min(height);
            let extended = Roi::new(x0, y0, x1 - x0, y1 - y0);
            let t = Tile {
                index,
                id: format!("r{ty:03}_c{tx:03}"),
                core,
                extended,
            };
            if let Some(done) = folder.record(&t) {
                return Ok(done);
            }
            let mut record = TileRecord::new(&t, 0);
            if index == failed {
                record.status = TileStatus::Failed;
                record.error = Some("fabricated failure".into());
                folder.save(&t, &record, None)?;
                return Ok(record);
            }
            let cells = cells(index, extended);
            record.points = cells.counts.iter().map(|&n| n as usize).sum();
            record.cells = Some((cells.col, cells.row, cells.width, cells.height));
            record.confidence = Some(true);
            folder.save(&t, &record, Some(&cells))?;
            Ok(record)
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(Fabricated { grid, records })
}

/// The cells of tile `index` over `window`: the scene's height plus a small offset of its own,
/// 1 to 3 points a cell, and a confidence.
fn cells(index: usize, window: Roi) -> GridWindow {
    let n = window.width * window.height;
    let mut heights = Vec::with_capacity(n);
    let mut counts = Vec::with_capacity(n);
    let mut confidence = Vec::with_capacity(n);
    for y in window.y..window.y + window.height {
        for x in window.x..window.x + window.width {
            let h = height(x, y);
            let k = hash(&[x as u64, y as u64, index as u64]);
            heights.push(
                h + if h.is_nan() {
                    0.0
                } else {
                    (k % 5) as f32 * 0.01
                },
            );
            counts.push(if h.is_nan() { 0 } else { 1 + (k % 3) as u16 });
            confidence.push(if h.is_nan() {
                f32::NAN
            } else {
                (k % 100) as f32 / 100.0
            });
        }
    }
    GridWindow {
        col: window.x,
        row: window.y,
        width: window.width,
        height: window.height,
        heights,
        counts,
        confidence: Some(confidence),
    }
}

/// The made-up scene's measured height of cell `(x, y)`, NaN where nothing was measured.
fn height(x: usize, y: usize) -> f32 {
    // Voids of 128 × 128 cells (water, clouds) in some 256-cell squares.
    let (sx, sy) = (x % 256, y % 256);
    if hash(&[(x / 256) as u64, (y / 256) as u64, 7]) % 7 == 3
        && (64..192).contains(&sx)
        && (64..192).contains(&sy)
    {
        return f32::NAN;
    }
    // Scattered unmatched cells.
    if hash(&[x as u64, y as u64, 11]).is_multiple_of(17) {
        return f32::NAN;
    }
    let ground = 20.0 + 0.002 * x as f32 + 0.001 * y as f32;
    // Buildings in a third of the 48-cell blocks, an occluded strip east of each.
    let (bx, by) = ((x / 48) as u64, (y / 48) as u64);
    let (lx, ly) = (x % 48, y % 48);
    let b = hash(&[bx, by, 3]);
    if b.is_multiple_of(3) && (8..40).contains(&ly) {
        if (8..40).contains(&lx) {
            return ground + 10.0 + (b % 20) as f32;
        }
        if lx >= 40 && lx < 40 + (b % 8) as usize {
            return f32::NAN;
        }
    }
    ground
}

/// A well-mixed hash of a few integers (splitmix64 steps).
fn hash(values: &[u64]) -> u64 {
    values.iter().fold(0x9e37_79b9_7f4a_7c15, |h, &v| {
        let mut z = h ^ v.wrapping_add(0x9e37_79b9_7f4a_7c15);
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    })
}

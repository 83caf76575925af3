//! The DSM assembled from the tiles' cells one block of rows at a time, so that its memory does
//! not grow with the scene: each block is merged with a halo of rows around it (as far as the
//! hole filling and the median filter reach), finished, cropped back to the block and streamed
//! into the DSM, its filled-cell sidecar and (with the classical matcher) its confidence sidecar. The bytes are those of a merge of the whole grid at
//! once: every finished cell of a block depends only on cells inside its halo.

use std::ops::Range;
use std::path::Path;

use anyhow::Result;
use camera::{grid_writer, Band, DsmGrid, GridWindow, Heights};
use raster::formats::cog::COG_TILE;
use raster::formats::CogWriter;
use raster::Image;
use rayon::prelude::*;

use super::folder::TileFolder;
use super::mosaic::Mosaic;
use super::tile::{TileRecord, TileStatus};
use crate::dsm::{confidence_path, filled_mask, filled_path, DsmSummary};
use crate::finishing::finish_dsm;
use crate::finishing::Finishing;
use crate::flags::gib;

/// Rows of the DSM finished at once: a whole row of COG tiles (the writers then compress every
/// block as it comes); with its halo, about 180 MiB for a 16,384-cell-wide grid with the default
/// filling.
pub const MERGE_BLOCK_ROWS: usize = COG_TILE;

const BLOCK_BYTES_PER_CELL: u64 = 34;

/// What the confidence adds per cell: its mosaic, its sidecar's rows and the tiles' band.
const CONFIDENCE_BYTES_PER_CELL: u64 = 12;

/// Memory the assembly of the DSM needs, bytes: one block of `block_rows` rows with its halo
/// (the whole grid when the halo reaches past it), and the two COG writers (per level a row of
/// tiles waiting to be complete, and a block's compressed tiles and halved rows).
pub fn merge_memory(
    grid: &DsmGrid,
    finishing: &Finishing,
    confidence: bool,
    block_rows: usize,
) -> u64 {
    let width = grid.width as u64;
    let halo = finishing.halo();
    let rows = block_rows
        .saturating_add(halo.saturating_mul(2))
        .min(grid.height) as u64;
    let per_cell = BLOCK_BYTES_PER_CELL
        + if confidence {
            CONFIDENCE_BYTES_PER_CELL
        } else {
            0
        };
    let block = rows * width * per_cell;
    let written = block_rows.min(grid.height) as u64;
    // The levels' widths halve: all of them together hold at most twice level 0's rows.
    let writer = width * 4 * (2 * (COG_TILE as u64 + 1) + 2 * written);
    let writers = 2 + u64::from(confidence);
    block + writers * writer
}

/// The refusal when the assembly does not fit in `max_memory`.
pub fn check_merge_memory(grid: &DsmGrid, merge_memory: u64, max_memory: u64) -> Result<()> {
    if merge_memory > max_memory {
        anyhow::bail!(
            "assembling the {}x{}-cell DSM needs about {:.2} GiB, more than --max-memory {:.2} \
             GiB: use a coarser --resolution, a smaller --roi, or raise --max-memory",
            grid.width,
            grid.height,
            gib(merge_memory),
            gib(max_memory)
        );
    }
    Ok(())
}

/// A tile's cells on the grid: column, row, width, height.
type Cells = (usize, usize, usize, usize);

/// Merges the finished tiles' cells into the DSM at `output` (and its filled-cell sidecar, and
/// with `confidence` the measured cells' confidence, which the classical matcher's tiles
/// carry), `block_rows` rows at a time, finishing it on the way (holes, median filter).
pub fn merge_tiles(
    finishing: &Finishing,
    confidence: bool,
    grid: &DsmGrid,
    folder: &TileFolder,
    records: &[TileRecord],
    output: &Path,
    block_rows: usize,
) -> Result<DsmSummary> {
    let parts: Vec<(&TileRecord, Cells)> = records
        .iter()
        .filter_map(|r| match (r.status, r.cells) {
            (TileStatus::Done, Some(cells)) => Some((r, cells)),
            _ => None,
        })
        .collect();
    let points = parts.iter().map(|(r, _)| r.points).sum();
    let sidecar = filled_path(output);
    crate::dsm::remove_other_sidecars(
        output,
        &[crate::dsm::FILLED_SUFFIX, crate::dsm::CONFIDENCE_SUFFIX],
    )?;
    let mut dsm_out = Output::create(output, grid, Band::Heights(Heights::Ellipsoid))?;
    let mut filled_out = Output::create(&sidecar, grid, crate::dsm::bands::FILLED)?;
    // Only when every tile's cells carry it (tiles of an earlier version, resumed, do not); a
    // sidecar left by an earlier run of this output would no longer match the DSM.
    let confidence_file = confidence_path(output);
    let with_confidence = confidence && parts.iter().all(|(r, _)| r.confidence == Some(true));
    let mut confidence_out = if with_confidence {
        Some(Output::create(
            &confidence_file,
            grid,
            crate::dsm::bands::CONFIDENCE,
        )?)
    } else {
        if confidence_file.is_file() {
            std::fs::remove_file(&confidence_file).map_err(|e| failed(&confidence_file, e))?;
        }
        None
    };
    let (mut measured_cells, mut filled_cells) = (0, 0);
    let halo = finishing.halo();
    for start in (0..grid.height).step_by(block_rows.max(1)) {
        let block = start..(start + block_rows.max(1)).min(grid.height);
        let window =
            block.start.saturating_sub(halo)..block.end.saturating_add(halo).min(grid.height);
        let mut mosaic = Mosaic::new(grid, window.clone(), finishing.gridding);
        // Read in parallel, merged in the records' order (ties go to the first tile).
        let cells: Vec<Option<GridWindow>> = parts
            .par_iter()
            .filter(|(_, (_, row, _, height))| *row < window.end && row + height > window.start)
            .map(|(r, cells)| folder.cells(r, *cells, window.clone()))
            .collect::<Result<_>>()?;
        for part in cells.iter().flatten() {
            mosaic.add(part);
        }
        let (measured, confidence) = mosaic.into_images();
        let finished = finish_dsm(
            measured.clone(),
            finishing.fill_holes,
            finishing.median_filter,
        )?;
        let core = (block.start - window.start)..(block.end - window.start);
        if let Some(out) = &mut confidence_out {
            out.write(&rows_of(&confidence, core.clone()))?;
        }
        let (measured, finished) = (rows_of(&measured, core.clone()), rows_of(&finished, core));
        measured_cells += finite(&measured);
        filled_cells += finite(&finished);
        let filled = filled_mask(&measured, &finished)?;
        dsm_out.write(&finished)?;
        filled_out.write(&filled)?;
    }
    dsm_out.finish()?;
    filled_out.finish()?;
    if let Some(out) = confidence_out {
        out.finish()?;
    }
    Ok(DsmSummary {
        points,
        measured_cells,
        filled_cells,
        grid: grid.clone(),
        comparison: None,
    })
}

/// The rows `rows` of a one-band image.
fn rows_of(image: &Image, rows: Range<usize>) -> Image {
    let w = image.width();
    let data = image.data()[rows.start * w..rows.end * w].to_vec();
    Image::new(w, rows.len(), 1, data).expect("whole rows")
}

fn finite(image: &Image) -> usize {
    image.data().iter().filter(|v| v.is_finite()).count()
}

/// One of the two files the merge writes, its failures told the way a rerun fixes them.
struct Output<'a> {
    path: &'a Path,
    writer: CogWriter,
}

impl<'a> Output<'a> {
    fn create(path: &'a Path, grid: &DsmGrid, band: Band) -> Result<Self> {
        let writer = grid_writer(path, grid, band).map_err(|e| failed(path, e))?;
        Ok(Output { path, writer })
    }

    fn write(&mut self, rows: &Image) -> Result<()> {
        self.writer
            .write_rows(rows.data())
            .map_err(|e| failed(self.path, e))
    }

    fn finish(self) -> Result<()> {
        self.writer.finish().map_err(|e| failed(self.path, e))
    }
}

fn failed(path: &Path, e: impl std::fmt::Display) -> anyhow::Error {
    workflow::outputs::Incomplete::Nothing {
        message: format!(
            "writing {} failed: {e}; the tiles stay in the work folder: free space or fix the \
             folder and rerun the same command",
            path.display()
        ),
    }
    .into()
}

#[cfg(test)]
mod tests {
    use super::super::fabricated::fabricate_tiles;
    use super::*;
    use crate::finishing::{DEFAULT_FILL_CELLS, DEFAULT_MEDIAN_CELLS};
    use camera::{Gridding, HoleFill};

    /// The merge as it was before blocks: the whole grid at once, written whole.
    fn merge_whole_grid(
        (finishing, with_confidence): (&Finishing, bool),
        grid: &DsmGrid,
        folder: &TileFolder,
        records: &[TileRecord],
        output: &Path,
    ) -> (usize, usize, usize) {
        let mut mosaic = Mosaic::new(grid, 0..grid.height, finishing.gridding);
        let mut points = 0;
        for r in records {
            if let (TileStatus::Done, Some(cells)) = (r.status, r.cells) {
                mosaic.add(&folder.cells(r, cells, 0..grid.height).unwrap().unwrap());
                points += r.points;
            }
        }
        let (measured, confidence) = mosaic.into_images();
        let finished = finish_dsm(
            measured.clone(),
            finishing.fill_holes,
            finishing.median_filter,
        )
        .unwrap();
        let filled = filled_mask(&measured, &finished).unwrap();
        camera::write_dsm(output, &finished, grid).unwrap();
        let bands = (crate::dsm::bands::FILLED, crate::dsm::bands::CONFIDENCE);
        camera::write_grid_raster(filled_path(output), &filled, grid, bands.0).unwrap();
        if with_confidence {
            camera::write_grid_raster(confidence_path(output), &confidence, grid, bands.1).unwrap();
        }
        (points, finite(&measured), finite(&finished))
    }

    /// Buildings, occluded strips, voids and a failed tile across blocks of 32 rows: the DSM and
    /// its sidecars are byte for byte those of the whole-grid merge, with the same counts.
    #[test]
    fn blocks_of_rows_make_the_bytes_of_the_whole_grid_merge() {
        let dir = tempfile::tempdir().unwrap();
        let work = dir.path().join("work");
        let made = fabricate_tiles(&work, (300, 530), 64).unwrap();
        let folder = TileFolder::new(&work);
        let finishings = [
            (Finishing::default(), true),
            (
                Finishing::new(
                    Gridding::Median,
                    Some(DEFAULT_FILL_CELLS),
                    None,
                    Some(DEFAULT_MEDIAN_CELLS),
                ),
                true,
            ),
            (Finishing::new(Gridding::Max, Some(3), None, Some(5)), true),
            (Finishing::new(Gridding::Max, None, None, None), false),
        ];
        for (finishing, confidence) in finishings {
            let whole = dir.path().join("whole.tif");
            let (points, measured, filled) = merge_whole_grid(
                (&finishing, confidence),
                &made.grid,
                &folder,
                &made.records,
                &whole,
            );
            assert!(measured < filled || finishing.fill_holes.is_none());
            assert!(filled < 300 * 530, "the voids stay empty");
            for block_rows in [32, 256] {
                let out = dir.path().join(format!("blocks{block_rows}.tif"));
                let s = merge_tiles(
                    &finishing,
                    confidence,
                    &made.grid,
                    &folder,
                    &made.records,
                    &out,
                    block_rows,
                )
                .unwrap();
                assert_eq!(
                    (s.points, s.measured_cells, s.filled_cells),
                    (points, measured, filled)
                );
                assert_eq!(confidence_path(&out).is_file(), confidence);
                let mut files = vec![
                    (whole.clone(), out.clone()),
                    (filled_path(&whole), filled_path(&out)),
                ];
                if confidence {
                    files.push((confidence_path(&whole), confidence_path(&out)));
                }
                for (a, b) in &files {
                    let same = std::fs::read(a).unwrap() == std::fs::read(b).unwrap();
                    assert!(
                        same,
                        "{finishing:?}, {block_rows} rows: {} differs",
                        b.display()
                    );
                }
            }
        }
    }

    /// A work folder resumed from an earlier version has tiles without a confidence band: the
    /// DSM is merged without a confidence sidecar, and one left by an earlier run is removed
    /// rather than left beside a DSM it does not describe.
    #[test]
    fn tiles_without_confidence_give_no_sidecar() {
        let dir = tempfile::tempdir().unwrap();
        let work = dir.path().join("work");
        let made = fabricate_tiles(&work, (100, 90), 64).unwrap();
        let folder = TileFolder::new(&work);
        let finishing = Finishing::default();
        let out = dir.path().join("dsm.tif");
        merge_tiles(
            &finishing,
            true,
            &made.grid,
            &folder,
            &made.records,
            &out,
            32,
        )
        .unwrap();
        let confidence = camera::read_dsm(confidence_path(&out), None).unwrap().image;
        let dsm = camera::read_dsm(filled_path(&out), None).unwrap().image;
        // Measured cells (0 in the filled sidecar) have a confidence in [0, 1], the others none.
        for (c, f) in confidence.data().iter().zip(dsm.data()) {
            assert_eq!(*f == 0.0, c.is_finite(), "{c} {f}");
            assert!(!c.is_finite() || (0.0..=1.0).contains(c), "{c}");
        }
        let mut older = made.records.clone();
        let done = older.iter().position(|r| r.cells.is_some()).unwrap();
        older[done].confidence = None;
        merge_tiles(&finishing, true, &made.grid, &folder, &older, &out, 32).unwrap();
        assert!(out.is_file() && !confidence_path(&out).exists());
    }

    #[test]
    fn the_halo_is_the_filling_and_median_reach_and_a_huge_grid_fits_in_little_memory() {
        let default = Finishing {
            gridding: Gridding::Median,
            fill_holes: Some(HoleFill {
                span: 40,
                reach: 16,
            }),
            median_filter: Some(7),
        };
        assert_eq!(default.halo(), 43);
        let none = Finishing {
            fill_holes: None,
            median_filter: None,
            ..default
        };
        assert_eq!(none.halo(), 0);
        let grid = DsmGrid::new(0.0, 0.0, 0.5, 50_000, 50_000, 32617).unwrap();
        let bytes = merge_memory(&grid, &default, true, MERGE_BLOCK_ROWS);
        assert!(bytes < 3 << 29, "{bytes} bytes for 50,000² cells");
        let bytes = merge_memory(&grid, &default, false, MERGE_BLOCK_ROWS);
        assert!(
            bytes < 1 << 30,
            "{bytes} bytes for 50,000² cells without confidence"
        );
        // A halo reaching past the grid: the whole grid is one block.
        let small = DsmGrid::new(0.0, 0.0, 0.5, 1000, 100, 32617).unwrap();
        let whole = merge_memory(&small, &default, true, MERGE_BLOCK_ROWS);
        assert_eq!(
            whole,
            1000 * 100 * (BLOCK_BYTES_PER_CELL + CONFIDENCE_BYTES_PER_CELL)
                + 3 * 1000 * 4 * (2 * 257 + 2 * 100)
        );
    }
}

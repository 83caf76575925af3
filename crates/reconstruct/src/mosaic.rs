//! Assembling the tiles' cells into one DSM grid. Neighbouring tiles can both put points in the
//! cells along their shared edge; the merge keeps the highest of them for the benchmark's `max`
//! gridding (exactly what one untiled pass gives) and, for the median gridding, the value of the
//! tile that saw the cell with more points. A cell's confidence comes with its height, from the
//! same tile. A mosaic can hold a band of rows of the grid only, so that a DSM larger than
//! memory is assembled a block at a time.

use std::ops::Range;
use std::path::Path;

use anyhow::{bail, Context, Result};
use camera::{DsmGrid, GridWindow, Gridding};
use raster::formats::{write_geotiff, GeoTiffMeta, TiffReader};
use raster::Image;

/// The scene's DSM under construction, on the grid's rows `rows`.
pub struct Mosaic {
    width: usize,
    rows: Range<usize>,
    heights: Vec<f32>,
    counts: Vec<u16>,
    /// The confidence of the tile each height came from, NaN where it had none.
    confidence: Vec<f32>,
    gridding: Gridding,
}

impl Mosaic {
    /// An empty mosaic of the rows `rows` of `grid`.
    pub fn new(grid: &DsmGrid, rows: Range<usize>, gridding: Gridding) -> Self {
        let n = grid.width * rows.len();
        Mosaic {
            width: grid.width,
            rows,
            heights: vec![f32::NAN; n],
            counts: vec![0; n],
            confidence: vec![f32::NAN; n],
            gridding,
        }
    }

    /// Merges one tile's cells (those on the mosaic's rows).
    pub fn add(&mut self, part: &GridWindow) {
        let first = self.rows.start.saturating_sub(part.row);
        let last = self.rows.end.saturating_sub(part.row).min(part.height);
        for r in first..last {
            for c in 0..part.width {
                let k = r * part.width + c;
                let (v, n) = (part.heights[k], part.counts[k]);
                if v.is_nan() {
                    continue;
                }
                let i = (part.row + r - self.rows.start) * self.width + part.col + c;
                let (h, m) = (&mut self.heights[i], &mut self.counts[i]);
                let take = match self.gridding {
                    Gridding::Max => h.is_nan() || v > *h,
                    Gridding::Median => h.is_nan() || n > *m,
                };
                if take {
                    *h = v;
                    self.confidence[i] = part.confidence.as_ref().map_or(f32::NAN, |c| c[k]);
                }
                *m = match self.gridding {
                    Gridding::Max => m.saturating_add(n),
                    Gridding::Median => (*m).max(n),
                };
            }
        }
    }

    /// The gridded DSM of the mosaic's rows.
    pub fn into_image(self) -> Image {
        self.into_images().0
    }

    /// The gridded DSM of the mosaic's rows and the confidence of its cells.
    pub fn into_images(self) -> (Image, Image) {
        let (w, h) = (self.width, self.rows.len());
        (
            Image::new(w, h, 1, self.heights).expect("one value per cell"),
            Image::new(w, h, 1, self.confidence).expect("one value per cell"),
        )
    }
}

/// Writes a tile's cells (`tiles/<id>.tif`: band 1 heights, band 2 point counts, band 3 the
/// confidence when the matcher gives one).
pub fn write_part(path: &Path, part: &GridWindow) -> Result<()> {
    let n = part.heights.len();
    let bands = if part.confidence.is_some() { 3 } else { 2 };
    let mut data = Vec::with_capacity(n * bands);
    for k in 0..n {
        data.extend([part.heights[k], part.counts[k] as f32]);
        if let Some(c) = &part.confidence {
            data.push(c[k]);
        }
    }
    let image = Image::new(part.width, part.height, bands, data)?;
    write_geotiff(path, &image, &GeoTiffMeta::default())
        .with_context(|| format!("writing {}", path.display()))
}

/// Reads back the cells [`write_part`] wrote for the window `(col, row, width, height)`: those
/// on the grid's rows `rows` only (the file's strips elsewhere are not decoded), `None` when the
/// window has none there.
pub fn read_part(
    path: &Path,
    cells: (usize, usize, usize, usize),
    rows: Range<usize>,
) -> Result<Option<GridWindow>> {
    let context = || format!("reading the tile cells {}", path.display());
    let mut reader = TiffReader::open(path).with_context(context)?;
    let (col, row, width, height) = cells;
    let bands = reader.bands();
    if reader.size() != (width, height) || !(2..=3).contains(&bands) {
        let (w, h) = reader.size();
        bail!(
            "{}: expected {width}x{height} cells with 2 or 3 bands, found {w}x{h}x{}; delete \
             the tile's record to recompute it",
            path.display(),
            reader.bands()
        );
    }
    let (first, last) = (rows.start.max(row), rows.end.min(row + height));
    if first >= last {
        return Ok(None);
    }
    let image = reader
        .read_window(0, first - row, width, last - first)
        .with_context(context)?;
    let d = image.data();
    Ok(Some(GridWindow {
        col,
        row: first,
        width,
        height: last - first,
        heights: d.iter().step_by(bands).copied().collect(),
        counts: d.iter().skip(1).step_by(bands).map(|&n| n as u16).collect(),
        confidence: (bands == 3).then(|| d.iter().skip(2).step_by(3).copied().collect()),
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn part(col: usize, heights: Vec<f32>, counts: Vec<u16>) -> GridWindow {
        GridWindow {
            col,
            row: 0,
            width: heights.len(),
            height: 1,
            heights,
            counts,
            confidence: None,
        }
    }

    #[test]
    fn overlapping_tiles_merge_by_max_or_by_the_better_sampled_tile() {
        let grid = DsmGrid::new(0.0, 10.0, 1.0, 4, 1, 32617).unwrap();
        let a = part(0, vec![1.0, 5.0, 2.0], vec![1, 1, 3]);
        let b = part(1, vec![7.0, 1.0, f32::NAN], vec![1, 2, 0]);
        let mut max = Mosaic::new(&grid, 0..1, Gridding::Max);
        max.add(&a);
        max.add(&b);
        let m = max.into_image();
        assert_eq!(&m.data()[..3], &[1.0, 7.0, 2.0]);
        assert!(m.data()[3].is_nan());
        let mut med = Mosaic::new(&grid, 0..1, Gridding::Median);
        med.add(&a);
        med.add(&b);
        // Cell 1: a tie (1 point each) keeps the first tile; cell 2: a has 3 points to b's 2.
        assert_eq!(&med.into_image().data()[..3], &[1.0, 5.0, 2.0]);
        // The confidence comes from the tile whose height is kept.
        let a = GridWindow {
            confidence: Some(vec![0.1, 0.2, 0.3]),
            ..a
        };
        let mut max = Mosaic::new(&grid, 0..1, Gridding::Max);
        max.add(&a);
        max.add(&b);
        let (h, c) = max.into_images();
        assert_eq!(&h.data()[..3], &[1.0, 7.0, 2.0]);
        assert_eq!(c.data()[0], 0.1);
        assert!(c.data()[1].is_nan(), "b, which has none, won cell 1");
        assert_eq!(c.data()[2], 0.3);
    }

    #[test]
    fn parts_round_trip_and_a_wrong_size_names_the_fix() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("r000_c000.tif");
        let a = GridWindow {
            col: 3,
            row: 4,
            width: 2,
            height: 2,
            heights: vec![1.5, f32::NAN, 3.0, 4.0],
            counts: vec![2, 0, 1, 7],
            confidence: None,
        };
        write_part(&p, &a).unwrap();
        let b = read_part(&p, (3, 4, 2, 2), 0..10).unwrap().unwrap();
        assert_eq!(b.counts, a.counts);
        assert_eq!(b.confidence, None);
        // With a confidence band, it comes back with the heights.
        let q = dir.path().join("r000_c001.tif");
        let c = GridWindow {
            confidence: Some(vec![0.5, f32::NAN, 0.25, 1.0]),
            ..a.clone()
        };
        write_part(&q, &c).unwrap();
        let d = read_part(&q, (3, 4, 2, 2), 5..9).unwrap().unwrap();
        assert_eq!((d.heights, d.counts), (vec![3.0, 4.0], vec![1, 7]));
        assert_eq!(d.confidence, Some(vec![0.25, 1.0]));
        assert_eq!(b.heights[0], 1.5);
        assert!(b.heights[1].is_nan());
        // Only the grid's row 5 (the window's second row); nothing on rows 6 and after.
        let lower = read_part(&p, (3, 4, 2, 2), 5..9).unwrap().unwrap();
        assert_eq!((lower.row, lower.height), (5, 1));
        assert_eq!((lower.heights, lower.counts), (vec![3.0, 4.0], vec![1, 7]));
        assert!(read_part(&p, (3, 4, 2, 2), 6..9).unwrap().is_none());
        let msg = format!("{:#}", read_part(&p, (3, 4, 3, 2), 0..10).unwrap_err());
        assert!(msg.contains("delete the tile's record"), "{msg}");
    }
}

//! Which DSM cells a view sees: a cell is hidden when the line of sight from its top towards the
//! satellite passes below the DSM somewhere (by more than [`TOLERANCE_M`], so that the cell's
//! neighbours on the same flat roof do not hide it).
//!
//! The line of sight is followed through a pyramid of block maxima of the DSM (the "maximum
//! mipmap" of height-field ray casting): a block whose highest cell is below the ray where the ray
//! enters it cannot hide the cell (the ray only rises), so it is crossed in one step, and the
//! ray climbs to coarser blocks while it can. Open ground costs a few steps per cell whatever the
//! view's obliquity and the city's height.

use camera::{DsmGrid, RpcModel};
use raster::{Image, Mask};
use rayon::prelude::*;

use super::directions::{BlockHeights, ViewDirections};
use crate::{ProductsError, Result};

/// How much higher than the line of sight the DSM must be to hide a cell, metres.
pub const TOLERANCE_M: f64 = 0.5;

/// The DSM's maxima over blocks of 2^k × 2^k cells, k = 0 (the DSM) up to one block covering it
/// all; cells without height count as −∞ (they hide nothing).
pub(super) struct MaxPyramid {
    width: usize,
    height: usize,
    /// (width of the level, maxima), finest first.
    levels: Vec<(usize, Vec<f32>)>,
}

impl MaxPyramid {
    pub(super) fn new(dsm: &Image) -> Self {
        let (width, height) = dsm.size();
        let base: Vec<f32> = dsm
            .data()
            .iter()
            .map(|&z| if z.is_nan() { f32::NEG_INFINITY } else { z })
            .collect();
        let mut levels = vec![(width, base)];
        let (mut w, mut h) = (width, height);
        while w > 1 || h > 1 {
            let (pw, prev) = levels.last().expect("the base level");
            let (nw, nh) = (w.div_ceil(2), h.div_ceil(2));
            let at = |x: usize, y: usize| prev[y.min(h - 1) * pw + x.min(w - 1)];
            let next = (0..nw * nh)
                .map(|i| {
                    let (x, y) = (2 * (i % nw), 2 * (i / nw));
                    at(x, y)
                        .max(at(x + 1, y))
                        .max(at(x, y + 1))
                        .max(at(x + 1, y + 1))
                })
                .collect();
            levels.push((nw, next));
            (w, h) = (nw, nh);
        }
        MaxPyramid {
            width,
            height,
            levels,
        }
    }

    /// The highest cell of the DSM.
    fn top(&self) -> f32 {
        self.levels.last().expect("one level at least").1[0]
    }

    /// Whether the line of sight from the top of cell (col, row), at height `z`, rising by
    /// `dir` = (columns, rows) per metre, passes more than [`TOLERANCE_M`] below the DSM before
    /// it rises above the highest cell or leaves the grid.
    pub(super) fn occluded(&self, col: usize, row: usize, z: f32, dir: (f64, f64)) -> bool {
        let (dc, dr) = dir;
        let reach = dc.abs().max(dr.abs());
        // A vertical (or unknown) line of sight is hidden by nothing.
        if reach.is_nan() || reach <= 1e-9 || !z.is_finite() {
            return false;
        }
        // The ray's height plus the tolerance: a cell hides it when it is higher than this.
        let base = z as f64 + TOLERANCE_M;
        let top = self.top() as f64;
        let (x0, y0) = (col as f64 + 0.5, row as f64 + 0.5);
        let (w, h) = (self.width as f64, self.height as f64);
        // Steps land this far (in cells) past a block's edge, inside the next block.
        let nudge = 1e-6 / reach;
        let mut t = exit(x0, y0, dir, (col, row), 1) + nudge;
        let mut level = 0;
        loop {
            let ray = base + t;
            if ray >= top {
                return false;
            }
            let (x, y) = (x0 + dc * t, y0 + dr * t);
            if !(x >= 0.0 && y >= 0.0 && x < w && y < h) {
                return false;
            }
            let (bx, by) = ((x as usize) >> level, (y as usize) >> level);
            let (lw, maxima) = &self.levels[level];
            if ray >= maxima[by * lw + bx] as f64 {
                t = exit(x0, y0, dir, (bx, by), 1 << level) + nudge;
                level = (level + 1).min(self.levels.len() - 1);
            } else if level == 0 {
                return true;
            } else {
                level -= 1;
            }
        }
    }
}

/// The ray parameter at which the ray from (x0, y0) along `dir` leaves block (bx, by) of `size`
/// cells.
#[inline]
fn exit(x0: f64, y0: f64, (dc, dr): (f64, f64), (bx, by): (usize, usize), size: usize) -> f64 {
    let s = size as f64;
    let edge = |p0: f64, d: f64, b: usize| {
        if d > 0.0 {
            ((b + 1) as f64 * s - p0) / d
        } else if d < 0.0 {
            (b as f64 * s - p0) / d
        } else {
            f64::INFINITY
        }
    };
    edge(x0, dc, bx).min(edge(y0, dr, by))
}

/// The cells of `dsm` (on `grid`) that the view of `rpc` sees: true where the cell has a height
/// and the line of sight from its top towards the satellite does not pass below the DSM by more
/// than [`TOLERANCE_M`]. Lines of sight leaving the grid are taken as clear.
pub fn visibility(dsm: &Image, grid: &DsmGrid, rpc: &RpcModel) -> Result<Mask> {
    grid.check_heights(dsm, "visibility")?;
    let (w, h) = dsm.size();
    let Some(heights) = BlockHeights::new(dsm) else {
        return Ok(Mask::filled(w, h, false));
    };
    let directions = ViewDirections::new(rpc, grid, &heights);
    let pyramid = MaxPyramid::new(dsm);
    let seen: Vec<bool> = (0..h)
        .into_par_iter()
        .flat_map_iter(|row| {
            let (pyramid, directions) = (&pyramid, &directions);
            (0..w).map(move |col| {
                let z = dsm.get(col, row, 0);
                z.is_finite() && !pyramid.occluded(col, row, z, directions.at(col, row))
            })
        })
        .collect();
    Mask::new(w, h, seen).map_err(|e| ProductsError::Input(e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A flat DSM at 0 m with a `height` m box over columns and rows [lo, hi).
    fn boxed(size: usize, lo: usize, hi: usize, height: f32) -> Image {
        Image::from_fn(size, size, |x, y| {
            if (lo..hi).contains(&x) && (lo..hi).contains(&y) {
                height
            } else {
                0.0
            }
        })
    }

    /// The occlusion of every cell by brute force: steps of a hundredth of a cell.
    fn brute_force(dsm: &Image, col: usize, row: usize, dir: (f64, f64)) -> bool {
        let z = dsm.get(col, row, 0) as f64;
        let reach = dir.0.abs().max(dir.1.abs());
        let (w, h) = dsm.size();
        let mut t = 0.0;
        loop {
            t += (0.01 / reach).min(0.01);
            let (x, y) = (col as f64 + 0.5 + dir.0 * t, row as f64 + 0.5 + dir.1 * t);
            if x < 0.0 || y < 0.0 || x >= w as f64 || y >= h as f64 || z + t > 100.0 {
                return false;
            }
            let (cx, cy) = (x as usize, y as usize);
            if (cx, cy) != (col, row) && dsm.get(cx, cy, 0) as f64 > z + TOLERANCE_M + t {
                return true;
            }
        }
    }

    #[test]
    fn the_pyramid_agrees_with_brute_force() {
        let mut dsm = boxed(70, 20, 32, 15.0);
        for (x, y, z) in [
            (50, 50, 30.0),
            (51, 50, 25.0),
            (10, 60, 8.0),
            (40, 8, f32::NAN),
        ] {
            dsm.set(x, y, 0, z);
        }
        let pyramid = MaxPyramid::new(&dsm);
        for dir in [(-1.0, 0.0), (0.7, 0.45), (-0.2, -0.9), (0.05, 0.0)] {
            let mut disagree = 0;
            let mut hidden = 0;
            for row in 0..70 {
                for col in 0..70 {
                    let z = dsm.get(col, row, 0);
                    let fast = pyramid.occluded(col, row, z, dir);
                    hidden += fast as usize;
                    // Rays grazing an edge may differ by the brute force's step.
                    disagree +=
                        (z.is_finite() && fast != brute_force(&dsm, col, row, dir)) as usize;
                }
            }
            assert!(hidden > 5, "{dir:?}: {hidden} hidden");
            assert!(
                disagree <= 2,
                "{dir:?}: {disagree} cells disagree of {hidden} hidden"
            );
        }
    }

    #[test]
    fn a_box_hides_the_cells_behind_it() {
        let dsm = boxed(100, 40, 50, 20.0);
        let pyramid = MaxPyramid::new(&dsm);
        // The satellite in the west, one cell per metre: 20 cells east of the box are hidden.
        let dir = (-1.0, 0.0);
        for col in 0..100 {
            let hidden = pyramid.occluded(col, 45, dsm.get(col, 45, 0), dir);
            let expected = (50..69).contains(&col);
            assert_eq!(hidden, expected, "column {col}");
        }
        // Nadir hides nothing.
        assert!(!pyramid.occluded(55, 45, 0.0, (0.0, 0.0)));
    }
}

//! Registration of a predicted DSM to the ground-truth DSM: an integer horizontal shift found by
//! multiscale normalised cross-correlation (NCC), then a vertical offset.
//!
//! Convention: the returned shift `(dx, dy)` is applied to the PREDICTION,
//! `aligned(x, y) = pred(x − dx, y − dy) + offset` ([`apply`]), i.e. the predicted surface moves by
//! `+dx` columns and `+dy` rows. The released evaluator's `dsmr.compute_shift` returns the opposite
//! sign (it samples `pred(x + dx, y + dy)`). NaN cells (no data) are ignored everywhere.
//!
//! Two schemes ([`Scheme`]):
//! - [`Scheme::Release`] (the default) is the released evaluator's (`utils/dsmr.py`
//!   `recursive_ncc`, `compute_ncc`, `mean_std`, `downsample2x_`) to the last rounding: the
//!   pyramid halves while the smaller side exceeds 100 cells (512 → 256 → 128 → 64); a coarse
//!   cell is the mean of the finite cells of the 2×2 block starting ONE cell down and right of
//!   its own (`downsample2x_` writes every fine cell's block into `out[j // 2, i // 2]` and the
//!   last write wins), clipped at the far edges; the estimate is floor-halved going down and
//!   doubled going up; each level searches ±radius rows (outer) and columns (inner) in increasing
//!   order of the release's shift and keeps the FIRST strict maximum; any overlap counts; the
//!   moments are two-pass (means, then centred sums) in float64 in row-major order, as numba
//!   computes them. The offset is `mean(gt) − mean(shifted pred)` over the common cells.
//! - [`Scheme::Robust`], seasonstereo's earlier variant: aligned 2×2 blocks down to a smaller side
//!   of `min_level_size`, a minimum overlap, and ties broken towards the level's centre.

use raster::resize::block_mean_finite;
use raster::Image;

/// The release's pyramid: halve while the smaller side exceeds this many cells.
pub const RELEASE_PYRAMID_STOP: usize = 100;

/// How the shift is searched.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Scheme {
    /// The released evaluator's multiscale NCC, bit for bit (see the module doc).
    Release,
    /// Aligned 2×2 pyramid, minimum overlap, ties towards the centre.
    Robust {
        /// The coarsest pyramid level has its smaller side at least this many cells.
        min_level_size: usize,
        /// A shift is scored only when at least this share of the cells finite in both rasters
        /// at zero shift (and at least 16 cells) overlap.
        min_overlap: f64,
    },
}

/// How the shift is searched.
#[derive(Clone, Debug, PartialEq)]
pub struct AlignParams {
    /// Search radius at every pyramid level, cells (the shift tried is within ±radius of the
    /// estimate brought from the coarser level).
    pub radius: i32,
    pub scheme: Scheme,
}

impl Default for AlignParams {
    /// The released evaluator's registration.
    fn default() -> Self {
        AlignParams::release()
    }
}

impl AlignParams {
    /// The released evaluator's registration: ±5 cells per level, [`Scheme::Release`].
    pub fn release() -> Self {
        AlignParams {
            radius: 5,
            scheme: Scheme::Release,
        }
    }

    /// seasonstereo's earlier registration: ±5 cells per level down to 32 cells, 25 % overlap.
    pub fn robust() -> Self {
        AlignParams {
            radius: 5,
            scheme: Scheme::Robust {
                min_level_size: 32,
                min_overlap: 0.25,
            },
        }
    }
}

/// The registration of a prediction onto the ground truth.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Alignment {
    /// Horizontal shift applied to the prediction, cells (columns, rows).
    pub dx: i32,
    pub dy: i32,
    /// Vertical offset added to the shifted prediction, metres: mean(gt) − mean(shifted pred) over
    /// the cells finite in both.
    pub offset: f64,
    /// NCC at the chosen shift (at full resolution), when defined (both rasters vary).
    pub ncc: Option<f64>,
    /// Cells finite in both rasters after the shift.
    pub overlap: usize,
}

/// `pred` shifted by `(dx, dy)` and raised by `offset`: `out(x, y) = pred(x − dx, y − dy) + offset`,
/// NaN where that falls outside `pred`.
pub fn apply(pred: &Image, dx: i32, dy: i32, offset: f64) -> Image {
    let (w, h) = pred.size();
    let p = pred.channel(0);
    Image::from_fn(w, h, |x, y| {
        let (sx, sy) = (x as i64 - dx as i64, y as i64 - dy as i64);
        if sx < 0 || sy < 0 || sx >= w as i64 || sy >= h as i64 {
            f32::NAN
        } else {
            (p.get(sx as usize, sy as usize, 0) as f64 + offset) as f32
        }
    })
}

/// Sums over the overlap of `gt(x, y)` and `pred(x − dx, y − dy)`.
#[derive(Default)]
struct Moments {
    n: usize,
    sg: f64,
    sp: f64,
    sgg: f64,
    spp: f64,
    sgp: f64,
}

impl Moments {
    fn of(gt: &Image, pred: &Image, dx: i32, dy: i32) -> Moments {
        let (w, h) = gt.size();
        let mut m = Moments::default();
        let (g, p) = (gt.data(), pred.data());
        let x0 = dx.max(0) as usize;
        let x1 = (w as i64 + (dx as i64).min(0)).max(0) as usize;
        let y0 = dy.max(0) as usize;
        let y1 = (h as i64 + (dy as i64).min(0)).max(0) as usize;
        for y in y0..y1 {
            let sy = (y as i64 - dy as i64) as usize;
            for x in x0..x1 {
                let sx = (x as i64 - dx as i64) as usize;
                let (a, b) = (g[y * w + x], p[sy * w + sx]);
                if a.is_finite() && b.is_finite() {
                    let (a, b) = (a as f64, b as f64);
                    m.n += 1;
                    m.sg += a;
                    m.sp += b;
                    m.sgg += a * a;
                    m.spp += b * b;
                    m.sgp += a * b;
                }
            }
        }
        m
    }

    fn ncc(&self) -> Option<f64> {
        if self.n < 2 {
            return None;
        }
        let n = self.n as f64;
        let cov = self.sgp - self.sg * self.sp / n;
        let vg = self.sgg - self.sg * self.sg / n;
        let vp = self.spp - self.sp * self.sp / n;
        // Relative tolerance: a flat raster has no defined correlation.
        let tiny = |v: f64, s2: f64| v <= 1e-12 * (1.0 + s2);
        if tiny(vg, self.sgg) || tiny(vp, self.spp) {
            return None;
        }
        Some(cov / (vg * vp).sqrt())
    }
}

/// The best shift within `radius` of `centre` at one level, by NCC; `None` when no shift has a
/// defined NCC over enough cells.
fn search(
    gt: &Image,
    pred: &Image,
    centre: (i32, i32),
    radius: i32,
    min_cells: usize,
) -> Option<(i32, i32)> {
    let mut best: Option<((i32, i32), f64, i32)> = None;
    for dy in centre.1 - radius..=centre.1 + radius {
        for dx in centre.0 - radius..=centre.0 + radius {
            let m = Moments::of(gt, pred, dx, dy);
            if m.n < min_cells {
                continue;
            }
            let Some(c) = m.ncc() else { continue };
            let dist = (dx - centre.0).abs() + (dy - centre.1).abs();
            // Strictly better NCC wins; on a tie the shift nearer the centre wins.
            let better = match best {
                None => true,
                Some((_, bc, bd)) => c > bc + 1e-12 || ((c - bc).abs() <= 1e-12 && dist < bd),
            };
            if better {
                best = Some(((dx, dy), c, dist));
            }
        }
    }
    best.map(|(s, _, _)| s)
}

/// Registers `pred` onto `gt` (same grid, single channel) by the integer shift maximising the NCC,
/// searched coarse to fine (±`radius` at each level), then the vertical offset, by
/// `params.scheme`. Returns `None` when the two rasters share no finite cell at the shift found
/// (no overlap): there is nothing to align or to score. When the NCC is undefined everywhere (a
/// flat surface), the shift stays (0, 0) and only the offset is estimated.
pub fn align(gt: &Image, pred: &Image, params: &AlignParams) -> Option<Alignment> {
    assert_eq!(gt.size(), pred.size(), "align: rasters on different grids");
    match params.scheme {
        Scheme::Release => release::align(gt, pred, params.radius),
        Scheme::Robust {
            min_level_size,
            min_overlap,
        } => align_robust(gt, pred, params.radius, min_level_size, min_overlap),
    }
}

fn align_robust(
    gt: &Image,
    pred: &Image,
    radius: i32,
    min_level_size: usize,
    min_overlap: f64,
) -> Option<Alignment> {
    let gt = gt.channel(0);
    let pred = pred.channel(0);
    let mut levels = vec![(gt.clone(), pred.clone())];
    loop {
        let (g, p) = levels.last().expect("one level at least");
        if g.width().min(g.height()) / 2 < min_level_size.max(1) {
            break;
        }
        let next = (block_mean_finite(g, 2), block_mean_finite(p, 2));
        levels.push(next);
    }
    let mut shift = (0i32, 0i32);
    for (i, (g, p)) in levels.iter().enumerate().rev() {
        if i + 1 < levels.len() {
            shift = (shift.0 * 2, shift.1 * 2);
        }
        let base = Moments::of(g, p, 0, 0).n;
        let min_cells = ((base as f64 * min_overlap) as usize).max(16);
        if let Some(s) = search(g, p, shift, radius, min_cells) {
            shift = s;
        }
    }
    let m = Moments::of(&gt, &pred, shift.0, shift.1);
    if m.n == 0 {
        // The estimate may have drifted off a tiny overlap: fall back to no shift.
        let m0 = Moments::of(&gt, &pred, 0, 0);
        if m0.n == 0 {
            return None;
        }
        shift = (0, 0);
        return Some(finish(shift, &m0));
    }
    Some(finish(shift, &m))
}

fn finish(shift: (i32, i32), m: &Moments) -> Alignment {
    let n = m.n as f64;
    Alignment {
        dx: shift.0,
        dy: shift.1,
        offset: (m.sg - m.sp) / n,
        ncc: m.ncc(),
        overlap: m.n,
    }
}

/// The released evaluator's registration (`utils/dsmr.py`), in its own sign convention: the
/// shift `(sx, sy)` compares `gt(i, j)` with `pred(i + sx, j + sy)`.
mod release {
    use super::{Alignment, RELEASE_PYRAMID_STOP};
    use raster::Image;

    /// A single-channel raster in float64 (row-major), as numba sees the arrays.
    struct Grid {
        w: usize,
        h: usize,
        v: Vec<f64>,
    }

    impl Grid {
        fn of(image: &Image) -> Grid {
            let c = image.channel(0);
            Grid {
                w: c.width(),
                h: c.height(),
                v: c.data().iter().map(|&x| x as f64).collect(),
            }
        }

        /// `valnan`: the cell (column i, row j) or NaN outside.
        #[inline(always)]
        fn at(&self, i: i64, j: i64) -> f64 {
            if i >= 0 && j >= 0 && (i as usize) < self.w && (j as usize) < self.h {
                self.v[j as usize * self.w + i as usize]
            } else {
                f64::NAN
            }
        }

        /// `downsample2x_`: cell (I, J) of the result holds the NaN-aware mean of the block of
        /// rows j..j+1 and columns i..i+1 (clipped), with j = min(2J + 1, h − 1) and
        /// i = min(2I + 1, w − 1): the last fine cell written into it.
        fn downsample(&self) -> Grid {
            let (nw, nh) = (self.w.div_ceil(2), self.h.div_ceil(2));
            let mut v = vec![f64::NAN; nw * nh];
            for jj in 0..nh {
                let j = (2 * jj + 1).min(self.h - 1) as i64;
                for ii in 0..nw {
                    let i = (2 * ii + 1).min(self.w - 1) as i64;
                    let (mut s, mut n) = (0.0f64, 0usize);
                    for k in 0..2 {
                        for l in 0..2 {
                            let t = self.at(i + k, j + l);
                            if t.is_finite() {
                                s += t;
                                n += 1;
                            }
                        }
                    }
                    if n > 0 {
                        v[jj * nw + ii] = s / n as f64;
                    }
                }
            }
            Grid { w: nw, h: nh, v }
        }
    }

    /// `mean_std(u, v, sx, sy)`: (mean u, mean v, std u, std v, covariance, count) over the
    /// cells finite in both, in two passes. `None` when no cell is common (the release divides
    /// by zero there).
    fn mean_std(u: &Grid, v: &Grid, sx: i64, sy: i64) -> Option<(f64, f64, f64, f64, f64, usize)> {
        // Cells outside the overlap window read NaN from `v` and are skipped: the window keeps
        // the row-major order of the sums, hence the roundings.
        let (w, h) = (u.w as i64, u.h as i64);
        let (i0, i1) = ((-sx).max(0), (v.w as i64 - sx).min(w));
        let (j0, j1) = ((-sy).max(0), (v.h as i64 - sy).min(h));
        if i0 >= i1 || j0 >= j1 {
            return None;
        }
        let (mut mu, mut mv, mut count) = (0.0f64, 0.0f64, 0usize);
        for j in j0..j1 {
            let ur = &u.v[j as usize * u.w..];
            let vr = &v.v[(j + sy) as usize * v.w..];
            for i in i0..i1 {
                let (a, b) = (ur[i as usize], vr[(i + sx) as usize]);
                if a.is_finite() && b.is_finite() {
                    mu += a;
                    mv += b;
                    count += 1;
                }
            }
        }
        if count == 0 {
            return None;
        }
        let n = count as f64;
        let (mu, mv) = (mu / n, mv / n);
        let (mut su, mut sv, mut xc) = (0.0f64, 0.0f64, 0.0f64);
        for j in j0..j1 {
            let ur = &u.v[j as usize * u.w..];
            let vr = &v.v[(j + sy) as usize * v.w..];
            for i in i0..i1 {
                let (a, b) = (ur[i as usize] - mu, vr[(i + sx) as usize] - mv);
                if a.is_finite() && b.is_finite() {
                    su += a * a;
                    sv += b * b;
                    xc += a * b;
                }
            }
        }
        Some((mu, mv, (su / n).sqrt(), (sv / n).sqrt(), xc / n, count))
    }

    /// `ncc`: NaN where undefined (no common cell, or a flat raster).
    fn ncc(u: &Grid, v: &Grid, sx: i64, sy: i64) -> f64 {
        match mean_std(u, v, sx, sy) {
            Some((_, _, su, sv, xc, _)) => xc / (su * sv),
            None => f64::NAN,
        }
    }

    /// `compute_ncc`: rows outer, columns inner, the first strict maximum; the start when no
    /// shift has a (non-NaN) NCC.
    fn search(u: &Grid, v: &Grid, radius: i64, start: (i64, i64)) -> (i64, i64) {
        let mut best = start;
        let mut max = f64::NEG_INFINITY;
        for sy in start.1 - radius..=start.1 + radius {
            for sx in start.0 - radius..=start.0 + radius {
                let c = ncc(u, v, sx, sy);
                if c > max {
                    best = (sx, sy);
                    max = c;
                }
            }
        }
        best
    }

    /// `recursive_ncc` then `compute_shift(scaling=False)`, returned in seasonstereo's
    /// convention (the shift negated).
    pub(super) fn align(gt: &Image, pred: &Image, radius: i32) -> Option<Alignment> {
        let mut levels = vec![(Grid::of(gt), Grid::of(pred))];
        loop {
            let (u, v) = levels.last().expect("one level at least");
            if u.w.min(u.h) <= RELEASE_PYRAMID_STOP {
                break;
            }
            let next = (u.downsample(), v.downsample());
            levels.push(next);
        }
        // Going down the estimate is floor-halved from (0, 0), so the coarsest level starts at
        // (0, 0); going up it is doubled.
        let mut shift = (0i64, 0i64);
        for (k, (u, v)) in levels.iter().enumerate().rev() {
            if k + 1 < levels.len() {
                shift = (shift.0 * 2, shift.1 * 2);
            }
            shift = search(u, v, radius as i64, shift);
        }
        let (u, v) = &levels[0];
        let (mu, mv, su, sv, xc, count) = mean_std(u, v, shift.0, shift.1)?;
        let ncc = xc / (su * sv);
        Some(Alignment {
            dx: -shift.0 as i32,
            dy: -shift.1 as i32,
            offset: mu - mv,
            ncc: ncc.is_finite().then_some(ncc),
            overlap: count,
        })
    }

    #[cfg(test)]
    mod tests {
        use super::*;

        #[test]
        fn downsample_averages_the_block_one_cell_further() {
            // 5×3: coarse (0, 0) averages rows 1..2, columns 1..2; coarse (2, 1) the last
            // column and row alone; NaN cells are left out.
            let mut img = Image::from_fn(5, 3, |x, y| (10 * y + x) as f32);
            img.set(2, 2, 0, f32::NAN);
            let g = Grid::of(&img).downsample();
            assert_eq!((g.w, g.h), (3, 2));
            assert_eq!(g.v[0], (11.0 + 12.0 + 21.0) / 3.0);
            assert_eq!(g.v[2], (14.0 + 24.0) / 2.0);
            assert_eq!(g.v[5], 24.0);
        }

        #[test]
        fn ties_keep_the_first_shift_in_scan_order() {
            // Rows alternate 2, 0: every shift with an even row shift correlates exactly (NCC
            // 1.0 to the last bit: the sums are of integers). The release keeps the first in
            // its scan order (rows outer, columns inner, increasing): its (-5, -4), i.e. (5, 4)
            // here; the robust scheme prefers the centre.
            let gt = Image::from_fn(20, 20, |_, y| if y % 2 == 0 { 2.0 } else { 0.0 });
            let a = super::super::align(&gt, &gt, &super::super::AlignParams::release()).unwrap();
            assert_eq!((a.dx, a.dy), (5, 4), "{a:?}");
            let r = super::super::align(&gt, &gt, &super::super::AlignParams::robust()).unwrap();
            assert_eq!((r.dx, r.dy), (0, 0), "{r:?}");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn apply_moves_content_by_the_shift() {
        let p = Image::from_fn(4, 3, |x, y| (10 * y + x) as f32);
        let a = apply(&p, 1, -1, 0.5);
        assert_eq!(a.get(1, 0, 0), p.get(0, 1, 0) + 0.5);
        assert!(a.get(0, 0, 0).is_nan() && a.get(3, 2, 0).is_nan());
    }

    #[test]
    fn flat_rasters_keep_zero_shift() {
        let g = Image::filled(40, 40, 1, 3.0);
        let p = Image::filled(40, 40, 1, 1.0);
        let a = align(&g, &p, &AlignParams::default()).unwrap();
        assert_eq!((a.dx, a.dy), (0, 0));
        assert!((a.offset - 2.0).abs() < 1e-12 && a.ncc.is_none());
    }
}

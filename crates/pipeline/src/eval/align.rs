//! Registration of a predicted DSM to the ground-truth DSM: an integer horizontal shift found by
//! multiscale normalised cross-correlation (NCC), then a vertical offset.
//!
//! Convention: the returned shift `(dx, dy)` is applied to the PREDICTION,
//! `aligned(x, y) = pred(x − dx, y − dy) + offset` ([`apply`]), i.e. the predicted surface moves by
//! `+dx` columns and `+dy` rows. NaN cells (no data) are ignored everywhere: the NCC of a shift is
//! computed over the cells finite in both rasters, and a shift with too small an overlap is not
//! considered.

use raster::Image;

/// How the shift is searched.
#[derive(Clone, Debug, PartialEq)]
pub struct AlignParams {
    /// Search radius at every pyramid level, cells (the shift tried is within ±radius of the
    /// estimate brought from the coarser level).
    pub radius: i32,
    /// The coarsest pyramid level has its smaller side at least this many cells.
    pub min_level_size: usize,
    /// A shift is scored only when at least this share of the cells finite in both rasters at
    /// zero shift (and at least 16 cells) overlap.
    pub min_overlap: f64,
}

impl Default for AlignParams {
    fn default() -> Self {
        AlignParams {
            radius: 5,
            min_level_size: 32,
            min_overlap: 0.25,
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

/// Halves a raster: each cell is the mean of the finite cells of its 2×2 block (NaN when none).
fn downsample(image: &Image) -> Image {
    let (w, h) = image.size();
    let (nw, nh) = (w.div_ceil(2), h.div_ceil(2));
    Image::from_fn(nw, nh, |x, y| {
        let (mut s, mut n) = (0.0f64, 0usize);
        for yy in 2 * y..(2 * y + 2).min(h) {
            for xx in 2 * x..(2 * x + 2).min(w) {
                let v = image.get(xx, yy, 0);
                if v.is_finite() {
                    s += v as f64;
                    n += 1;
                }
            }
        }
        if n == 0 {
            f32::NAN
        } else {
            (s / n as f64) as f32
        }
    })
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

/// Registers `pred` onto `gt` (same grid, single channel): the integer shift maximising the NCC,
/// searched coarse to fine over a pyramid of 2×2 NaN-aware means (±`radius` at each level), then
/// the vertical offset. Returns `None` when the two rasters share no finite cell at any shift
/// tried (no overlap): there is nothing to align or to score. When the NCC is undefined (a flat
/// surface), the shift stays (0, 0) and only the offset is estimated.
pub fn align(gt: &Image, pred: &Image, params: &AlignParams) -> Option<Alignment> {
    assert_eq!(gt.size(), pred.size(), "align: rasters on different grids");
    let gt = gt.channel(0);
    let pred = pred.channel(0);
    let mut levels = vec![(gt.clone(), pred.clone())];
    loop {
        let (g, p) = levels.last().expect("one level at least");
        if g.width().min(g.height()) / 2 < params.min_level_size.max(1) {
            break;
        }
        let next = (downsample(g), downsample(p));
        levels.push(next);
    }
    let mut shift = (0i32, 0i32);
    for (i, (g, p)) in levels.iter().enumerate().rev() {
        if i + 1 < levels.len() {
            shift = (shift.0 * 2, shift.1 * 2);
        }
        let base = Moments::of(g, p, 0, 0).n;
        let min_cells = ((base as f64 * params.min_overlap) as usize).max(16);
        if let Some(s) = search(g, p, shift, params.radius, min_cells) {
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

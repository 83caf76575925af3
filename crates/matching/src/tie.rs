//! Sparse tie points between two images brought into one geometry (the second resampled onto
//! the first through the cameras at one altitude): what is left between them is the cameras'
//! pointing error, nearly one translation over the scene, and each point's parallax, along one
//! known direction. The search is 2-D, by zero-mean normalised cross-correlation (ZNCC: blind to
//! a change of gain and offset of the grey levels, so it holds across seasons), coarse to fine:
//!
//! 1. [`global_shift`]: the translation that best superposes the two images at a coarse level
//!    (the ground dominates, so this is the pointing error plus the ground's parallax);
//! 2. [`TieSearch::band`]: each textured point ([`keypoints`]) searched in a band around it,
//!    long along the parallax direction (buildings), narrow across it;
//! 3. [`TieSearch::refine`]: the match refined at full resolution to a fraction of a pixel.
//!
//! Images are grey, NaN outside their data; a patch that meets NaN is not compared.

use raster::Image;
use rayon::prelude::*;

/// Mean of each `factor`×`factor` block (NaN when fewer than half of its pixels are valid).
pub fn downsample(image: &Image, factor: usize) -> Image {
    let factor = factor.max(1);
    let (w, h) = (
        (image.width() / factor).max(1),
        (image.height() / factor).max(1),
    );
    Image::from_fn(w, h, |x, y| {
        let (mut sum, mut n) = (0.0f64, 0usize);
        for yy in y * factor..((y + 1) * factor).min(image.height()) {
            for xx in x * factor..((x + 1) * factor).min(image.width()) {
                let v = image.get(xx, yy, 0);
                if v.is_finite() {
                    sum += v as f64;
                    n += 1;
                }
            }
        }
        if 2 * n >= factor * factor {
            (sum / n as f64) as f32
        } else {
            f32::NAN
        }
    })
}

/// Each pixel minus the mean of its `(2r+1)²` window, over the window's standard deviation: NaN
/// where the window meets NaN or is flat. Correlating two such images is a local ZNCC.
pub fn normalise_locally(image: &Image, r: usize) -> Image {
    let (w, h) = image.size();
    Image::from_fn(w, h, |x, y| {
        if x < r || y < r || x + r >= w || y + r >= h {
            return f32::NAN;
        }
        let (mut s, mut s2) = (0.0f64, 0.0f64);
        for yy in y - r..=y + r {
            for xx in x - r..=x + r {
                let v = image.get(xx, yy, 0) as f64;
                s += v;
                s2 += v * v;
            }
        }
        let n = ((2 * r + 1) * (2 * r + 1)) as f64;
        let mean = s / n;
        let var = s2 / n - mean * mean;
        if var.is_nan() || var <= 1e-6 {
            return f32::NAN;
        }
        ((image.get(x, y, 0) as f64 - mean) / var.sqrt()) as f32
    })
}

/// Share of the best score within which a smaller shift is preferred ([`global_shift`]).
const NEAR_BEST: f32 = 0.85;

/// The integer shift `(dx, dy)`, `|dx|, |dy| ≤ radius`, such that `b(x + dx, y + dy)` best
/// matches `a(x, y)` (mean product of the locally normalised images over their common valid
/// pixels, at least a quarter of `a`'s), with its score; `None` when no shift overlaps enough.
/// A regular street grid scores a peak at every period: of the peaks that score within
/// [`NEAR_BEST`] of the best, the smallest shift is taken (pointing errors are mostly small).
pub fn global_shift(a: &Image, b: &Image, radius: usize) -> Option<(i32, i32, f32)> {
    let (na, nb) = (normalise_locally(a, 4), normalise_locally(b, 4));
    let valid = na.data().iter().filter(|v| v.is_finite()).count();
    let r = radius as i32;
    let side = 2 * r + 1;
    let shifts: Vec<(i32, i32)> = (-r..=r)
        .flat_map(|dy| (-r..=r).map(move |dx| (dx, dy)))
        .collect();
    let (w, h) = (na.width() as i32, na.height() as i32);
    let (bw, bh) = (nb.width() as i32, nb.height() as i32);
    let scores: Vec<Option<f32>> = shifts
        .par_iter()
        .map(|&(dx, dy)| {
            let (mut sum, mut n) = (0.0f64, 0usize);
            for y in 0..h {
                let by = y + dy;
                if by < 0 || by >= bh {
                    continue;
                }
                let (ra, rb) = (na.row(y as usize), nb.row(by as usize));
                let x0 = 0.max(-dx);
                let x1 = w.min(bw - dx);
                for x in x0..x1 {
                    let p = ra[x as usize] * rb[(x + dx) as usize];
                    if p.is_finite() {
                        sum += p as f64;
                        n += 1;
                    }
                }
            }
            (n > 0 && 4 * n >= valid).then(|| (sum / n as f64) as f32)
        })
        .collect();
    let best = scores
        .iter()
        .flatten()
        .copied()
        .fold(f32::NEG_INFINITY, f32::max);
    if best.is_nan() || best <= 0.0 {
        return None;
    }
    let at = |dx: i32, dy: i32| -> Option<f32> {
        (dx.abs() <= r && dy.abs() <= r)
            .then(|| scores[((dy + r) * side + dx + r) as usize])
            .flatten()
    };
    let peak = |dx: i32, dy: i32, s: f32| {
        (-1..=1).all(|v| (-1..=1).all(|u| at(dx + u, dy + v).is_none_or(|o| o <= s)))
    };
    shifts
        .iter()
        .zip(&scores)
        .filter_map(|(&(dx, dy), s)| s.map(|s| (dx, dy, s)))
        .filter(|&(dx, dy, s)| s >= NEAR_BEST * best && peak(dx, dy, s))
        .min_by_key(|&(dx, dy, _)| dx * dx + dy * dy)
}

/// The most textured pixel of each `spacing`-pixel cell (largest smaller eigenvalue of the
/// structure tensor over 5×5 pixels, as Shi–Tomasi), at least `margin` pixels from the border;
/// cells whose best is flat (below a tenth of the median cell's) give none.
pub fn keypoints(image: &Image, spacing: usize, margin: usize) -> Vec<(usize, usize)> {
    let (w, h) = image.size();
    let spacing = spacing.max(4);
    let margin = margin.max(3);
    if w <= 2 * margin || h <= 2 * margin {
        return Vec::new();
    }
    let strength = |x: usize, y: usize| -> f32 {
        let (mut xx, mut yy, mut xy) = (0.0f32, 0.0f32, 0.0f32);
        for v in y - 2..=y + 2 {
            for u in x - 2..=x + 2 {
                let gx = image.get(u + 1, v, 0) - image.get(u - 1, v, 0);
                let gy = image.get(u, v + 1, 0) - image.get(u, v - 1, 0);
                xx += gx * gx;
                yy += gy * gy;
                xy += gx * gy;
            }
        }
        let tr = 0.5 * (xx + yy);
        let det = xx * yy - xy * xy;
        let e = tr - (tr * tr - det).max(0.0).sqrt();
        if e.is_finite() {
            e
        } else {
            0.0
        }
    };
    let cells: Vec<(usize, usize)> = (margin..h - margin)
        .step_by(spacing)
        .flat_map(|y| (margin..w - margin).step_by(spacing).map(move |x| (x, y)))
        .collect();
    let best: Vec<(usize, usize, f32)> = cells
        .par_iter()
        .map(|&(x0, y0)| {
            let mut best = (x0, y0, 0.0f32);
            for y in y0..(y0 + spacing).min(h - margin) {
                for x in x0..(x0 + spacing).min(w - margin) {
                    let s = strength(x, y);
                    if s > best.2 {
                        best = (x, y, s);
                    }
                }
            }
            best
        })
        .collect();
    let mut strengths: Vec<f32> = best.iter().map(|b| b.2).filter(|s| *s > 0.0).collect();
    if strengths.is_empty() {
        return Vec::new();
    }
    strengths.sort_by(f32::total_cmp);
    let floor = 0.1 * strengths[strengths.len() / 2];
    best.into_iter()
        .filter(|b| b.2 > floor)
        .map(|b| (b.0, b.1))
        .collect()
}

/// A match of a point of `a`: its offset into `b`, the ZNCC there, and the best ZNCC at least
/// two pixels away (how unique the match is).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TieMatch {
    pub dx: f64,
    pub dy: f64,
    pub score: f32,
    pub runner_up: f32,
}

/// Patch comparisons between `a` and `b` (grey, same geometry) with square patches of
/// `(2·radius+1)²` pixels.
pub struct TieSearch<'a> {
    pub a: &'a Image,
    pub b: &'a Image,
    pub radius: usize,
}

impl TieSearch<'_> {
    /// ZNCC of the patch of `a` at `(x, y)` and of `b` at `(x + dx, y + dy)`; `None` outside
    /// either image, on NaN, or on a flat patch.
    pub fn zncc(&self, x: usize, y: usize, dx: i32, dy: i32) -> Option<f32> {
        let r = self.radius as i64;
        let (bx, by) = (x as i64 + dx as i64, y as i64 + dy as i64);
        let inside = |img: &Image, cx: i64, cy: i64| {
            cx >= r && cy >= r && cx + r < img.width() as i64 && cy + r < img.height() as i64
        };
        if !inside(self.a, x as i64, y as i64) || !inside(self.b, bx, by) {
            return None;
        }
        let (mut sa, mut sb, mut saa, mut sbb, mut sab) = (0.0f64, 0.0f64, 0.0f64, 0.0f64, 0.0f64);
        for v in -r..=r {
            let ra = self.a.row((y as i64 + v) as usize);
            let rb = self.b.row((by + v) as usize);
            for u in -r..=r {
                let p = ra[(x as i64 + u) as usize] as f64;
                let q = rb[(bx + u) as usize] as f64;
                sa += p;
                sb += q;
                saa += p * p;
                sbb += q * q;
                sab += p * q;
            }
        }
        let n = ((2 * r + 1) * (2 * r + 1)) as f64;
        let va = saa - sa * sa / n;
        let vb = sbb - sb * sb / n;
        let z = (sab - sa * sb / n) / (va * vb).sqrt();
        (va > 1e-6 && vb > 1e-6 && z.is_finite()).then_some(z as f32)
    }

    /// The best of the integer offsets `around + s·along + u·across` (`s` in `along_range`,
    /// `|u| ≤ across_radius`; `along` is a direction of unit length, `across` its normal).
    pub fn band(
        &self,
        (x, y): (usize, usize),
        around: (f64, f64),
        along: (f64, f64),
        along_range: (f64, f64),
        across_radius: f64,
    ) -> Option<TieMatch> {
        let norm = along.0.hypot(along.1);
        if norm.is_nan() || norm <= 0.0 {
            return None;
        }
        let e = (along.0 / norm, along.1 / norm);
        let ends = [
            (
                around.0 + along_range.0 * e.0,
                around.1 + along_range.0 * e.1,
            ),
            (
                around.0 + along_range.1 * e.0,
                around.1 + along_range.1 * e.1,
            ),
        ];
        let pad = across_radius.ceil() + 1.0;
        let xs = (ends[0].0.min(ends[1].0) - pad).floor() as i32
            ..=(ends[0].0.max(ends[1].0) + pad).ceil() as i32;
        let ys = (ends[0].1.min(ends[1].1) - pad).floor() as i32
            ..=(ends[0].1.max(ends[1].1) + pad).ceil() as i32;
        let mut scored = Vec::new();
        for dy in ys {
            for dx in xs.clone() {
                let (px, py) = (dx as f64 - around.0, dy as f64 - around.1);
                let s = px * e.0 + py * e.1;
                let u = -px * e.1 + py * e.0;
                if s < along_range.0 - 0.5 || s > along_range.1 + 0.5 || u.abs() > across_radius {
                    continue;
                }
                if let Some(z) = self.zncc(x, y, dx, dy) {
                    scored.push((dx, dy, z));
                }
            }
        }
        best_of(&scored)
    }

    /// The best offset within `radius` pixels of `(dx, dy)`, to a fraction of a pixel (a
    /// parabola through the scores on each axis).
    pub fn refine(
        &self,
        (x, y): (usize, usize),
        (dx, dy): (i32, i32),
        radius: i32,
    ) -> Option<TieMatch> {
        let mut scored = Vec::new();
        for v in -radius..=radius {
            for u in -radius..=radius {
                if let Some(z) = self.zncc(x, y, dx + u, dy + v) {
                    scored.push((dx + u, dy + v, z));
                }
            }
        }
        let best = best_of(&scored)?;
        let (bx, by) = (best.dx as i32, best.dy as i32);
        let at = |u: i32, v: i32| self.zncc(x, y, bx + u, by + v);
        let vertex = |m: f32, c: f32, p: f32| {
            let d = m - 2.0 * c + p;
            if d < 0.0 {
                (0.5 * (m - p) / d).clamp(-0.5, 0.5) as f64
            } else {
                0.0
            }
        };
        let c = best.score;
        let (Some(l), Some(r), Some(t), Some(b)) = (at(-1, 0), at(1, 0), at(0, -1), at(0, 1))
        else {
            return None;
        };
        Some(TieMatch {
            dx: bx as f64 + vertex(l, c, r),
            dy: by as f64 + vertex(t, c, b),
            ..best
        })
    }
}

/// The highest score and the highest at least two pixels away from it.
fn best_of(scored: &[(i32, i32, f32)]) -> Option<TieMatch> {
    let &(bx, by, score) = scored.iter().max_by(|p, q| p.2.total_cmp(&q.2))?;
    let runner_up = scored
        .iter()
        .filter(|p| (p.0 - bx).abs() >= 2 || (p.1 - by).abs() >= 2)
        .map(|p| p.2)
        .fold(-1.0f32, f32::max);
    Some(TieMatch {
        dx: bx as f64,
        dy: by as f64,
        score,
        runner_up,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A textured image and the same shifted by (dx, dy) with another gain and offset.
    fn pair(dx: f64, dy: f64) -> (Image, Image) {
        let f = |x: f64, y: f64| {
            let v = (x * 0.31).sin() * (y * 0.23).cos()
                + (0.11 * x + 0.07 * y).sin()
                + ((x * y) * 0.003).sin();
            v as f32
        };
        let a = Image::from_fn(160, 140, |x, y| f(x as f64, y as f64));
        let b = Image::from_fn(160, 140, |x, y| 3.0 * f(x as f64 - dx, y as f64 - dy) + 7.0);
        (a, b)
    }

    #[test]
    fn the_global_shift_and_a_refined_match_find_the_translation() {
        let (a, b) = pair(6.0, -4.0);
        let (dx, dy, s) = global_shift(&a, &b, 10).unwrap();
        assert_eq!((dx, dy), (6, -4));
        assert!(s > 0.3, "{s}");
        let (a, b) = pair(6.3, -4.6);
        let search = TieSearch {
            a: &a,
            b: &b,
            radius: 7,
        };
        let m = search.refine((70, 60), (6, -5), 2).unwrap();
        assert!(
            (m.dx - 6.3).abs() < 0.15 && (m.dy + 4.6).abs() < 0.15,
            "{m:?}"
        );
        assert!(m.score > 0.95 && m.runner_up < m.score);
    }

    #[test]
    fn a_street_grid_gives_the_smallest_of_its_equal_shifts() {
        // Periodic in x (period 16), textured in y: shifts 3, 3 ± 16 score alike.
        let f = |x: f64, y: f64| {
            ((x * std::f64::consts::TAU / 16.0).sin() * (1.0 + (y * 0.37).sin() + (y * 0.11).cos()))
                as f32
        };
        let a = Image::from_fn(200, 120, |x, y| f(x as f64, y as f64));
        let b = Image::from_fn(200, 120, |x, y| f(x as f64 - 3.0, y as f64));
        let (dx, dy, _) = global_shift(&a, &b, 24).unwrap();
        assert_eq!((dx, dy), (3, 0));
        let b = Image::from_fn(200, 120, |x, y| f(x as f64 + 5.0, y as f64));
        assert_eq!(global_shift(&a, &b, 24).map(|g| (g.0, g.1)), Some((-5, 0)));
    }

    #[test]
    fn a_band_search_follows_its_direction_only() {
        let (a, b) = pair(9.0, 3.0);
        let search = TieSearch {
            a: &a,
            b: &b,
            radius: 6,
        };
        // Along x from 0 to 12 around (0, 3): finds (9, 3).
        let m = search
            .band((60, 60), (0.0, 3.0), (1.0, 0.0), (0.0, 12.0), 1.0)
            .unwrap();
        assert_eq!((m.dx, m.dy), (9.0, 3.0));
        // A band that misses the true offset does not find it.
        let m = search
            .band((60, 60), (0.0, -3.0), (1.0, 0.0), (0.0, 12.0), 1.0)
            .unwrap();
        assert!(m.dy != 3.0);
    }

    #[test]
    fn keypoints_avoid_flat_cells_and_nan() {
        let mut img = Image::from_fn(100, 100, |x, y| {
            if x < 50 {
                ((x * 7 + y * 13) % 17) as f32
            } else {
                1.0
            }
        });
        img.set(20, 20, 0, f32::NAN);
        let k = keypoints(&img, 16, 8);
        assert!(!k.is_empty());
        assert!(k.iter().all(|&(x, _)| x < 52), "{k:?}");
        let d = downsample(&img, 4);
        assert_eq!(d.size(), (25, 25));
    }
}

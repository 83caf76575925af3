//! Deterministic synthetic rectified pairs with exact ground truth, shared by the tests and the
//! benchmark (`#[path]`-included there).
//!
//! Each surface carries its own band-limited value-noise texture, attached to the surface in
//! left-image coordinates; the right image is rendered by sampling each surface's texture where it
//! projects (`x_R = x − d(x, y)`), painting surfaces far to near so that occlusions are exact.
#![allow(dead_code)]

use raster::Image;

/// A planar patch of disparity `d = a + bx · x + by · y` over a rectangle of the left image
/// (`None`: everywhere, the background).
#[derive(Clone, Copy, Debug)]
pub struct Surface {
    pub rect: Option<(f64, f64, f64, f64)>,
    pub a: f64,
    pub bx: f64,
    pub by: f64,
    pub seed: u64,
}

impl Surface {
    fn d(&self, x: f64, y: f64) -> f64 {
        self.a + self.bx * x + self.by * y
    }

    fn contains(&self, x: f64, y: f64) -> bool {
        match self.rect {
            None => true,
            Some((x0, y0, x1, y1)) => x >= x0 && x < x1 && y >= y0 && y < y1,
        }
    }

    /// Left abscissa of the surface point seen at right abscissa `xr` on row `y`.
    fn source_x(&self, xr: f64, y: f64) -> f64 {
        (xr + self.a + self.by * y) / (1.0 - self.bx)
    }
}

pub struct Pair {
    pub left: Image,
    pub right: Image,
    /// Ground-truth disparity of the left view.
    pub disp: Vec<f32>,
    /// Ground-truth disparity of the right view, for the swapped pair (`−d`).
    pub disp_right: Vec<f32>,
    /// Left pixels not visible in the right image (hidden by a nearer surface or out of frame).
    pub occluded: Vec<bool>,
    pub width: usize,
    pub height: usize,
}

fn hash(ix: i64, iy: i64, seed: u64) -> f64 {
    let mut h = (ix as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (iy as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
        ^ seed.wrapping_mul(0x1656_67B1_9E37_79F9);
    h ^= h >> 31;
    h = h.wrapping_mul(0xBF58_476D_1CE4_E5B9);
    h ^= h >> 29;
    h = h.wrapping_mul(0x94D0_49BB_1331_11EB);
    h ^= h >> 32;
    (h >> 11) as f64 / (1u64 << 53) as f64
}

fn value_noise(x: f64, y: f64, cell: f64, seed: u64) -> f64 {
    let (u, v) = (x / cell, y / cell);
    let (iu, iv) = (u.floor(), v.floor());
    let (fu, fv) = (u - iu, v - iv);
    let s = |t: f64| t * t * (3.0 - 2.0 * t);
    let (su, sv) = (s(fu), s(fv));
    let (i, j) = (iu as i64, iv as i64);
    let a = hash(i, j, seed) * (1.0 - su) + hash(i + 1, j, seed) * su;
    let b = hash(i, j + 1, seed) * (1.0 - su) + hash(i + 1, j + 1, seed) * su;
    a * (1.0 - sv) + b * sv
}

/// A texture in `[0, 1]` with structure from 2 to 12 pixels.
pub fn texture(x: f64, y: f64, seed: u64) -> f64 {
    0.45 * value_noise(x, y, 12.0, seed)
        + 0.35 * value_noise(x, y, 4.5, seed + 1)
        + 0.20 * value_noise(x, y, 2.2, seed + 2)
}

/// Renders surfaces (listed far to near: each must be nearer, i.e. of larger disparity, than
/// the ones before it wherever they overlap) into a `w × h` pair of uint16-like values.
pub fn render(w: usize, h: usize, surfaces: &[Surface]) -> Pair {
    let scale = |t: f64| (1000.0 + 3000.0 * t) as f32;
    let mut left = vec![0f32; w * h];
    let mut right = vec![0f32; w * h];
    let mut disp = vec![0f32; w * h];
    let mut disp_right = vec![0f32; w * h];
    let mut occluded = vec![false; w * h];
    for y in 0..h {
        let yf = y as f64;
        for x in 0..w {
            let xf = x as f64;
            let s = surfaces.iter().rposition(|s| s.contains(xf, yf)).unwrap();
            let d = surfaces[s].d(xf, yf);
            left[y * w + x] = scale(texture(xf, yf, surfaces[s].seed));
            disp[y * w + x] = d as f32;
            let xr = xf - d;
            occluded[y * w + x] = xr < 0.0
                || xr > (w - 1) as f64
                || surfaces[s + 1..].iter().any(|n| {
                    let sx = n.source_x(xr, yf);
                    n.contains(sx, yf) && n.d(sx, yf) > d + 1e-9
                });
            // Right image: the nearest surface whose footprint projects here.
            let xr = xf;
            let mut painted = None;
            for s in surfaces {
                let sx = s.source_x(xr, yf);
                if s.contains(sx, yf) {
                    painted = Some((s, sx));
                }
            }
            let (s, sx) = painted.expect("the background covers everything");
            right[y * w + x] = scale(texture(sx, yf, s.seed));
            disp_right[y * w + x] = -(s.d(sx, yf) as f32);
        }
    }
    Pair {
        left: Image::new(w, h, 1, left).unwrap(),
        right: Image::new(w, h, 1, right).unwrap(),
        disp,
        disp_right,
        occluded,
        width: w,
        height: h,
    }
}

/// The standard test scene on `w × h`: a background plane slanted from 3 to 8 px across the
/// image, a raised block at 20 px and a second block at 12 px.
pub fn standard_pair(w: usize, h: usize) -> Pair {
    let (wf, hf) = (w as f64, h as f64);
    render(
        w,
        h,
        &[
            Surface {
                rect: None,
                a: 3.0,
                bx: 4.0 / wf,
                by: 1.0 / hf,
                seed: 11,
            },
            Surface {
                rect: Some((0.62 * wf, 0.58 * hf, 0.86 * wf, 0.82 * hf)),
                a: 12.0,
                bx: 0.0,
                by: 0.0,
                seed: 23,
            },
            Surface {
                rect: Some((0.23 * wf, 0.2 * hf, 0.55 * wf, 0.52 * hf)),
                a: 20.0,
                bx: 0.0,
                by: 0.0,
                seed: 37,
            },
        ],
    )
}

/// Error statistics of `est` against `truth` over the pixels where `mask` holds.
#[derive(Debug)]
pub struct Stats {
    /// Fraction of masked pixels with a finite estimate.
    pub coverage: f64,
    /// Mean absolute error over the masked, finite pixels.
    pub mae: f64,
    /// Fraction of masked, finite pixels with an error above 1 px.
    pub bad1: f64,
    pub bad2: f64,
}

pub fn stats(est: &[f32], truth: &[f32], mask: impl Fn(usize) -> bool) -> Stats {
    let (mut n, mut valid, mut sum, mut bad1, mut bad2) = (0usize, 0usize, 0f64, 0usize, 0usize);
    for i in 0..est.len() {
        if !mask(i) {
            continue;
        }
        n += 1;
        if est[i].is_finite() {
            valid += 1;
            let e = f64::from((est[i] - truth[i]).abs());
            sum += e;
            bad1 += usize::from(e > 1.0);
            bad2 += usize::from(e > 2.0);
        }
    }
    let v = valid.max(1) as f64;
    Stats {
        coverage: valid as f64 / n.max(1) as f64,
        mae: sum / v,
        bad1: bad1 as f64 / v,
        bad2: bad2 as f64 / v,
    }
}

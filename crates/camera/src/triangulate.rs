//! From a rectified disparity to ground points: the benchmark's (s2p's) iterative altitude of a
//! correspondence between raw image points, applied to every valid pixel.
//!
//! Convention (the public release's): the homographies map raw → rectified coordinates and the
//! left rectified pixel (x, y) matches the right rectified pixel (x − d, y).

use raster::{Homography, Image, Mask};
use rayon::prelude::*;

use crate::{CameraError, Result, RpcModel};

/// s2p's stopping rule on the altitude increment, metres.
const ALT_TOLERANCE: f64 = 1e-7;
/// s2p's iteration cap.
const ALT_MAX_ITERATIONS: usize = 100;
/// Border trimmed by the benchmark before computing altitudes, pixels.
pub const EVALUATION_BORDER: usize = 32;

/// One (lon, lat, alt) per pixel of a disparity map, NaN where there is no point.
#[derive(Clone, Debug, PartialEq)]
pub struct Points {
    pub width: usize,
    pub height: usize,
    /// Row-major `[lon°, lat°, alt m]`.
    pub lonlatalt: Vec<[f64; 3]>,
}

impl Points {
    /// The point of pixel (x, y).
    pub fn get(&self, x: usize, y: usize) -> [f64; 3] {
        self.lonlatalt[y * self.width + x]
    }

    /// Number of pixels with a point.
    pub fn valid_count(&self) -> usize {
        self.lonlatalt.iter().filter(|p| p[2].is_finite()).count()
    }

    /// The altitudes as a single-channel image in the disparity's geometry.
    pub fn altitude_image(&self) -> Image {
        let data = self.lonlatalt.iter().map(|p| p[2] as f32).collect();
        Image::new(self.width, self.height, 1, data).expect("size matches")
    }
}

/// Altitude (metres) of the ground point seen at raw `x_left` in the left image and raw `x_right`
/// in the right one, by s2p's iteration: start at h = 0; p0 = RPC_R(RPC_L⁻¹(x_L, h), h), p1 the
/// same at h + 1; h += ⟨p1 − p0, x_R − p0⟩ / |p1 − p0|², until the increment is below 1e-7 m or
/// after 100 iterations. `None` when a localisation fails or the iteration leaves the reals.
///
/// This is the plain scheme, one cold rpcm localisation per step; [`triangulate_disparity`]
/// reaches the same numbers much faster.
pub fn altitude(
    rpc_left: &RpcModel,
    rpc_right: &RpcModel,
    x_left: (f64, f64),
    x_right: (f64, f64),
) -> Option<f64> {
    let mut h = 0.0;
    for _ in 0..ALT_MAX_ITERATIONS {
        let (lon0, lat0) = rpc_left.localization(x_left.0, x_left.1, h).ok()?;
        let (lon1, lat1) = rpc_left.localization(x_left.0, x_left.1, h + 1.0).ok()?;
        let p0 = rpc_right.projection(lon0, lat0, h);
        let p1 = rpc_right.projection(lon1, lat1, h + 1.0);
        let increment = step(p0, p1, x_right);
        if !increment.is_finite() {
            return None;
        }
        h += increment;
        if increment.abs() < ALT_TOLERANCE {
            break;
        }
    }
    Some(h)
}

/// s2p's altitude increment: the position of `x_right` along the local epipolar segment p0→p1.
#[inline(always)]
fn step(p0: (f64, f64), p1: (f64, f64), x_right: (f64, f64)) -> f64 {
    let (ax, ay) = (p1.0 - p0.0, p1.1 - p0.1);
    let (bx, by) = (x_right.0 - p0.0, x_right.1 - p0.1);
    (ax * bx + ay * by) / (ax * ax + ay * ay)
}

/// What a pixel's solution tells its right-hand neighbour: the normalised ground point of the
/// left ray at the solved altitude, how it moves per metre, and the altitude.
#[derive(Clone, Copy)]
struct WarmStart {
    l: f64,
    p: f64,
    dl: f64,
    dp: f64,
    h: f64,
}

/// Localisation in the left camera's normalised coordinates, from a guess (Newton) or, without
/// one or when Newton fails, by rpcm's scheme.
#[inline]
fn localise(
    rpc: &RpcModel,
    x: (f64, f64),
    alt: f64,
    guess: Option<(f64, f64)>,
) -> Option<(f64, f64)> {
    let (tc, tr, hn) = rpc.normalise_image(x.0, x.1, alt);
    if let Some((l, p)) = guess {
        if let Some(lp) = rpc.newton_normalised(tc, tr, hn, l, p) {
            return Some(lp);
        }
    }
    let (lon, lat) = rpc.localization(x.0, x.1, alt).ok()?;
    Some(rpc.normalise_ground(lon, lat))
}

/// The s2p iteration of [`altitude`], with every localisation started from the best available
/// guess: the neighbouring pixel's solution, then the previous step's ray. The fixed point (and
/// the stopping rule) are unchanged, so the altitude agrees with the plain scheme far below a
/// micrometre. Returns (lon, lat, alt) and updates `warm`.
#[inline]
fn solve_pixel(
    left: &RpcModel,
    right: &RpcModel,
    x_left: (f64, f64),
    x_right: (f64, f64),
    warm: &mut Option<WarmStart>,
) -> Option<[f64; 3]> {
    let (mut h, mut guess, mut per_metre) = match *warm {
        Some(w) => (w.h, Some((w.l, w.p)), Some((w.dl, w.dp))),
        None => (0.0, None, None),
    };
    for _ in 0..ALT_MAX_ITERATIONS {
        let g0 = localise(left, x_left, h, guess)?;
        let g1_guess = per_metre
            .map(|(dl, dp)| (g0.0 + dl, g0.1 + dp))
            .or(Some(g0));
        let g1 = localise(left, x_left, h + 1.0, g1_guess)?;
        let (dl, dp) = (g1.0 - g0.0, g1.1 - g0.1);
        let (lon0, lat0) = left.ground_from_normalised(g0.0, g0.1);
        let (lon1, lat1) = left.ground_from_normalised(g1.0, g1.1);
        let p0 = right.projection(lon0, lat0, h);
        let p1 = right.projection(lon1, lat1, h + 1.0);
        let increment = step(p0, p1, x_right);
        if !increment.is_finite() {
            *warm = None;
            return None;
        }
        h += increment;
        // The left ray at the new altitude: linear along the (locally straight) ray.
        let (l, p) = (g0.0 + increment * dl, g0.1 + increment * dp);
        guess = Some((l, p));
        per_metre = Some((dl, dp));
        if increment.abs() < ALT_TOLERANCE {
            break;
        }
    }
    let (l, p) = guess?;
    let (dl, dp) = per_metre?;
    *warm = Some(WarmStart { l, p, dl, dp, h });
    let (lon, lat) = left.ground_from_normalised(l, p);
    Some([lon, lat, h])
}

/// Ground points of a rectified pair's disparity: for every pixel of `mask` with a finite
/// disparity, the left rectified pixel (x, y) and the right one (x − d, y) are mapped back to raw
/// coordinates with the inverse homographies (`h_left`, `h_right`: raw → rectified) and
/// triangulated with [`altitude`]'s scheme; (lon, lat) is the left ray at that altitude.
///
/// Rows run in parallel and each pixel starts from its left neighbour's solution, which makes the
/// per-pixel cost a few polynomial evaluations; results do not depend on the thread count.
pub fn triangulate_disparity(
    disparity: &Image,
    h_left: &Homography,
    h_right: &Homography,
    rpc_left: &RpcModel,
    rpc_right: &RpcModel,
    mask: &Mask,
) -> Result<Points> {
    if disparity.channels() != 1 {
        return Err(CameraError::Input(format!(
            "a disparity map has one channel, got {}",
            disparity.channels()
        )));
    }
    if mask.size() != disparity.size() {
        return Err(CameraError::Input(format!(
            "mask is {}x{} but the disparity is {}x{}",
            mask.width(),
            mask.height(),
            disparity.width(),
            disparity.height()
        )));
    }
    let invert = |h: &Homography, which: &str| {
        h.is_finite().then(|| h.inverse()).flatten().ok_or_else(|| {
            CameraError::Input(format!("the {which} homography is singular: {:?}", h.0))
        })
    };
    let inv_left = invert(h_left, "left")?;
    let inv_right = invert(h_right, "right")?;
    let (w, h) = disparity.size();
    let mut out = vec![[f64::NAN; 3]; w * h];
    if w > 0 {
        out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            let d_row = disparity.row(y);
            let mut warm = None;
            for (x, cell) in row.iter_mut().enumerate() {
                let d = d_row[x] as f64;
                if !mask.get(x, y) || !d.is_finite() {
                    continue;
                }
                let (xf, yf) = (x as f64, y as f64);
                let xl = inv_left.apply(xf, yf);
                let xr = inv_right.apply(xf - d, yf);
                if let Some(p) = solve_pixel(rpc_left, rpc_right, xl, xr, &mut warm) {
                    *cell = p;
                }
            }
        });
    }
    Ok(Points {
        width: w,
        height: h,
        lonlatalt: out,
    })
}

/// The pixels the benchmark triangulates: finite d > 0 whose match 0 ≤ x − d < W lies in the
/// right image, with a 32-pixel border trimmed on every side.
pub fn evaluation_mask(disparity: &Image) -> Mask {
    let (w, h) = disparity.size();
    let b = EVALUATION_BORDER;
    Mask::from_fn(w, h, |x, y| {
        if x < b || y < b || x + b >= w || y + b >= h {
            return false;
        }
        let d = disparity.get(x, y, 0) as f64;
        let xr = x as f64 - d;
        d.is_finite() && d > 0.0 && xr >= 0.0 && xr < w as f64
    })
}

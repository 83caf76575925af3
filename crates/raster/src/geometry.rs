//! Rectified-pair geometry on rasters: bilinear sampling, homography warps, centre crops and
//! horizontal disparity warps (x_R = x_L − d).

use rayon::prelude::*;

use crate::{Image, Mask, RasterError, Result};

/// The 8 neighbour steps `(dx, dy)` of a pixel, opposite steps side by side (E, W, S, N, SE, NW,
/// NE, SW): the directions of MGM's paths and of the DSM hole filling's rays.
pub const EIGHT_DIRECTIONS: [(i64, i64); 8] = [
    (1, 0),
    (-1, 0),
    (0, 1),
    (0, -1),
    (1, 1),
    (-1, -1),
    (1, -1),
    (-1, 1),
];

/// A 3×3 projective transform of pixel coordinates, row-major, `f64`. In the public release,
/// `Hleft`/`Hright` map raw image coordinates to rectified coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Homography(pub [[f64; 3]; 3]);

impl Homography {
    pub const IDENTITY: Homography =
        Homography([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]);

    /// A pure translation by `(tx, ty)`.
    pub fn translation(tx: f64, ty: f64) -> Self {
        Homography([[1.0, 0.0, tx], [0.0, 1.0, ty], [0.0, 0.0, 1.0]])
    }

    /// Maps the point `(x, y)`.
    #[inline]
    pub fn apply(&self, x: f64, y: f64) -> (f64, f64) {
        let m = &self.0;
        let w = m[2][0] * x + m[2][1] * y + m[2][2];
        (
            (m[0][0] * x + m[0][1] * y + m[0][2]) / w,
            (m[1][0] * x + m[1][1] * y + m[1][2]) / w,
        )
    }

    /// `self ∘ other`: first `other`, then `self`.
    pub fn compose(&self, other: &Homography) -> Homography {
        let (a, b) = (&self.0, &other.0);
        let mut m = [[0.0; 3]; 3];
        for (i, row) in m.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = (0..3).map(|k| a[i][k] * b[k][j]).sum();
            }
        }
        Homography(m)
    }

    /// The inverse transform, or `None` when the matrix is singular.
    pub fn inverse(&self) -> Option<Homography> {
        let m = &self.0;
        let cof = |r0: usize, r1: usize, c0: usize, c1: usize| {
            m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0]
        };
        let det = m[0][0] * cof(1, 2, 1, 2) - m[0][1] * cof(1, 2, 0, 2) + m[0][2] * cof(1, 2, 0, 1);
        if !det.is_finite() || det.abs() < 1e-300 {
            return None;
        }
        let inv = [
            [cof(1, 2, 1, 2), -cof(0, 2, 1, 2), cof(0, 1, 1, 2)],
            [-cof(1, 2, 0, 2), cof(0, 2, 0, 2), -cof(0, 1, 0, 2)],
            [cof(1, 2, 0, 1), -cof(0, 2, 0, 1), cof(0, 1, 0, 1)],
        ];
        Some(Homography(inv.map(|row| row.map(|v| v / det))))
    }

    /// True when every entry is finite.
    pub fn is_finite(&self) -> bool {
        self.0.iter().flatten().all(|v| v.is_finite())
    }
}

/// Slack allowed when deciding whether a sample point lies inside `[0, W−1]×[0, H−1]`: points
/// produced by homographies that should land exactly on the border (e.g. 0 or W−1) come out
/// a few ulps off, and rejecting them would erode the valid region by one pixel.
pub const BORDER_EPS: f64 = 1e-6;

/// Integer base index and fractional weight of coordinate `t` on an axis of `n` samples, or
/// `None` when `t` is outside `[−ε, n−1+ε]`. The base is clamped so that `base + 1 < n` (when
/// `n ≥ 2`), so the last sample is reached with weight 1 rather than by reading past the end.
#[inline]
fn axis(t: f64, n: usize) -> Option<(usize, f64)> {
    if n == 0 || !t.is_finite() {
        return None;
    }
    let max = (n - 1) as f64;
    if !(-BORDER_EPS..=max + BORDER_EPS).contains(&t) {
        return None;
    }
    let t = t.clamp(0.0, max);
    if n == 1 {
        return Some((0, 0.0));
    }
    let base = (t.floor() as usize).min(n - 2);
    Some((base, t - base as f64))
}

/// Bilinear interpolation of every channel of `image` at `(x, y)` (pixel centres at integer
/// coordinates), written to `out` (length = channels). Returns false, leaving `out` untouched,
/// when the point is outside `[0, W−1]×[0, H−1]` (up to [`BORDER_EPS`]); no extrapolation, so
/// callers can build an honest validity mask. A neighbour that enters with zero weight is not
/// read, so sampling exactly at a valid pixel next to a NaN returns that pixel; any NaN among
/// the neighbours with nonzero weight makes the result NaN (invalid stays invalid).
pub fn sample_bilinear(image: &Image, x: f64, y: f64, out: &mut [f32]) -> bool {
    let c = image.channels();
    assert_eq!(
        out.len(),
        c,
        "output buffer must hold one value per channel"
    );
    let (Some((x0, fx)), Some((y0, fy))) = (axis(x, image.width()), axis(y, image.height())) else {
        return false;
    };
    let taps = [
        (x0, y0, (1.0 - fx) * (1.0 - fy)),
        (x0 + 1, y0, fx * (1.0 - fy)),
        (x0, y0 + 1, (1.0 - fx) * fy),
        (x0 + 1, y0 + 1, fx * fy),
    ];
    for (ch, o) in out.iter_mut().enumerate() {
        let mut acc = 0.0f64;
        for &(tx, ty, w) in &taps {
            if w != 0.0 {
                acc += w * image.get(tx, ty, ch) as f64;
            }
        }
        *o = acc as f32;
    }
    true
}

/// Resamples `image` through `h`, which maps INPUT coordinates to OUTPUT coordinates (like the
/// release's raw→rectified `Hleft`/`Hright`): output pixel `p` takes the bilinear sample of the
/// input at `h⁻¹(p)`. Returns the `out_width × out_height` image and a mask that is true where
/// `h⁻¹(p)` fell inside the input. Pixels outside are set to 0 (the black border of rectified
/// crops), so always use the mask, not the value, to tell them apart; NaN input samples still
/// propagate as NaN inside the mask. A singular or non-finite `h` is an error.
pub fn warp_homography(
    image: &Image,
    h: &Homography,
    out_width: usize,
    out_height: usize,
) -> Result<(Image, Mask)> {
    let inv = h
        .inverse()
        .filter(Homography::is_finite)
        .ok_or_else(|| RasterError::Shape(format!("homography is not invertible: {h:?}")))?;
    let c = image.channels();
    let mut data = vec![0.0f32; out_width * out_height * c];
    let mut valid = vec![false; out_width * out_height];
    if out_width > 0 {
        data.par_chunks_mut(out_width * c)
            .zip(valid.par_chunks_mut(out_width))
            .enumerate()
            .for_each(|(y, (row, vrow))| {
                for (x, (px, v)) in row.chunks_exact_mut(c).zip(vrow.iter_mut()).enumerate() {
                    let (sx, sy) = inv.apply(x as f64, y as f64);
                    *v = sample_bilinear(image, sx, sy, px);
                }
            });
    }
    Ok((
        Image::new(out_width, out_height, c, data)?,
        Mask::new(out_width, out_height, valid)?,
    ))
}

/// The `width × height` window of `image` whose top-left pixel is `(x0, y0)`. A window that does
/// not fit inside the image is an error (no implicit padding).
pub fn crop(image: &Image, x0: usize, y0: usize, width: usize, height: usize) -> Result<Image> {
    if x0 + width > image.width() || y0 + height > image.height() {
        return Err(RasterError::Shape(format!(
            "crop {width}x{height} at ({x0}, {y0}) does not fit in a {}x{} image",
            image.width(),
            image.height()
        )));
    }
    let c = image.channels();
    let mut data = Vec::with_capacity(width * height * c);
    for y in y0..y0 + height {
        data.extend_from_slice(&image.row(y)[x0 * c..(x0 + width) * c]);
    }
    Image::new(width, height, c, data)
}

/// The central `width × height` window, at offset `((W−w)/2, (H−h)/2)` (integer division, so an
/// odd margin leaves the extra pixel on the right/bottom), and the translation that maps
/// original pixel coordinates to crop coordinates, so geometry can follow the crop (see
/// [`crop_homography`]). A crop larger than the image is an error.
pub fn centre_crop(image: &Image, width: usize, height: usize) -> Result<(Image, Homography)> {
    if width > image.width() || height > image.height() {
        return Err(RasterError::Shape(format!(
            "centre crop {width}x{height} is larger than the {}x{} image",
            image.width(),
            image.height()
        )));
    }
    let (x0, y0, _, _) = centre_window(image.width(), image.height(), width, height);
    let cropped = crop(image, x0, y0, width, height)?;
    Ok((cropped, Homography::translation(-(x0 as f64), -(y0 as f64))))
}

/// The central window of at most `max_width × max_height` pixels of a `width × height` image:
/// `(x0, y0, w, h)` with `(x0, y0) = ((width − w)/2, (height − h)/2)`, as [`centre_crop`] cuts it.
pub fn centre_window(
    width: usize,
    height: usize,
    max_width: usize,
    max_height: usize,
) -> (usize, usize, usize, usize) {
    let (w, h) = (width.min(max_width), height.min(max_height));
    ((width - w) / 2, (height - h) / 2, w, h)
}

/// Updates a raw→rectified homography when the rectified image is cropped with its top-left
/// corner at `(x0, y0)`: `translation(−x0, −y0) ∘ h`, so the result maps raw coordinates
/// straight to crop coordinates.
pub fn crop_homography(h: &Homography, x0: f64, y0: f64) -> Homography {
    Homography::translation(-x0, -y0).compose(h)
}

/// Resamples the RIGHT image of a rectified pair into the LEFT view using the left disparity
/// (x_R = x_L − d): `out(x, y) = right(x − d(x, y), y)`, linear interpolation along x (rows are
/// epipolar lines, so y is never interpolated). This is the reconstruction `Î_L` of photometric
/// losses. The mask is true where `d` is finite and `0 ≤ x − d ≤ W−1` (up to [`BORDER_EPS`]);
/// elsewhere the output is 0. NaN samples of `right` propagate as NaN inside the mask (as in
/// [`sample_bilinear`]). The disparity must be single-channel and the same size as `right`.
pub fn warp_by_disparity(right: &Image, disparity: &Image) -> Result<(Image, Mask)> {
    right.check_same_size(disparity, "warp_by_disparity")?;
    if disparity.channels() != 1 {
        return Err(RasterError::Shape(format!(
            "warp_by_disparity: disparity must have 1 channel, got {}",
            disparity.channels()
        )));
    }
    let (w, h) = right.size();
    let c = right.channels();
    let mut data = vec![0.0f32; w * h * c];
    let mut valid = vec![false; w * h];
    if w > 0 {
        data.par_chunks_mut(w * c)
            .zip(valid.par_chunks_mut(w))
            .enumerate()
            .for_each(|(y, (row, vrow))| {
                let src = right.row(y);
                let drow = disparity.row(y);
                for (x, (px, v)) in row.chunks_exact_mut(c).zip(vrow.iter_mut()).enumerate() {
                    let Some((x0, fx)) = axis(x as f64 - drow[x] as f64, w) else {
                        continue;
                    };
                    *v = true;
                    let a = &src[x0 * c..(x0 + 1) * c];
                    if fx == 0.0 {
                        px.copy_from_slice(a);
                    } else {
                        let b = &src[(x0 + 1) * c..(x0 + 2) * c];
                        for ((o, &va), &vb) in px.iter_mut().zip(a).zip(b) {
                            *o = ((1.0 - fx) * va as f64 + fx * vb as f64) as f32;
                        }
                    }
                }
            });
    }
    Ok((Image::new(w, h, c, data)?, Mask::new(w, h, valid)?))
}

/// The warp of the reference similarity metrics (`warp_right_to_left` in SeasonStereo's
/// `metrics_common.py`), reproduced operation by operation in f32: non-finite disparities are
/// replaced by 0, `x_R = x − d`, the grid is normalised as `2·(x_R/(W−1)) − 1` (rows likewise) and
/// sampled by torch `grid_sample(bilinear, zeros padding, align_corners=True)` (unnormalise
/// `(g + 1)·(W−1)/2`, floor, four taps, out-of-image taps read 0, summed in torch's order with
/// fused multiply-adds as its AVX2 kernel is compiled: bit-exact with torch 2.4 on the parity
/// fixture). Unlike [`warp_by_disparity`] every pixel gets a value (partial taps at the border,
/// `right(x)` where `d` was not finite), and the mask is torch's `0 ≤ x − d ≤ W−1` on the cleaned
/// disparity with no slack; the metrics' final mask is that ∧ `d` finite (∧ the ground truth
/// finite). NaN samples of `right` spread to the taps that touch them, as in torch.
pub fn warp_by_disparity_grid_sample(right: &Image, disparity: &Image) -> Result<(Image, Mask)> {
    right.check_same_size(disparity, "warp_by_disparity_grid_sample")?;
    if disparity.channels() != 1 {
        return Err(RasterError::Shape(format!(
            "warp_by_disparity_grid_sample: disparity must have 1 channel, got {}",
            disparity.channels()
        )));
    }
    let (w, h) = right.size();
    let c = right.channels();
    let mut data = vec![0.0f32; w * h * c];
    let mut valid = vec![false; w * h];
    if w == 0 || h == 0 {
        return Ok((Image::new(w, h, c, data)?, Mask::new(w, h, valid)?));
    }
    let normalise = |t: f32, n: usize| {
        if n == 1 {
            0.0
        } else {
            2.0 * (t / (n - 1) as f32) - 1.0
        }
    };
    // grid_sample's align_corners=True unnormalisation, `(g + 1) · ((n − 1)/2)` in f32.
    let unnormalise = |g: f32, n: usize| (g + 1.0) * ((n - 1) as f32 / 2.0);
    let tap = |x: i64, y: i64, ch: usize| {
        if (0..w as i64).contains(&x) && (0..h as i64).contains(&y) {
            right.get(x as usize, y as usize, ch)
        } else {
            0.0
        }
    };
    data.par_chunks_mut(w * c)
        .zip(valid.par_chunks_mut(w))
        .enumerate()
        .for_each(|(y, (row, vrow))| {
            let drow = disparity.row(y);
            let iy = unnormalise(normalise(y as f32, h), h);
            let y_n = iy.floor();
            let n = iy - y_n;
            let s = 1.0 - n;
            let y0 = y_n as i64;
            for (x, (px, v)) in row.chunks_exact_mut(c).zip(vrow.iter_mut()).enumerate() {
                let d = if drow[x].is_finite() { drow[x] } else { 0.0 };
                let x_r = x as f32 - d;
                *v = x_r >= 0.0 && x_r <= (w - 1) as f32;
                let ix = unnormalise(normalise(x_r, w), w);
                let x_w = ix.floor();
                let we = ix - x_w;
                let e = 1.0 - we;
                let x0 = x_w as i64;
                let (nw, ne, sw, se) = (s * e, s * we, n * e, n * we);
                for (ch, o) in px.iter_mut().enumerate() {
                    let acc = tap(x0 + 1, y0, ch).mul_add(ne, tap(x0, y0, ch) * nw);
                    let acc = tap(x0, y0 + 1, ch).mul_add(sw, acc);
                    *o = tap(x0 + 1, y0 + 1, ch).mul_add(se, acc);
                }
            }
        });
    Ok((Image::new(w, h, c, data)?, Mask::new(w, h, valid)?))
}

/// Per-pixel Euclidean distance over channels, `‖a(x, y) − b(x, y)‖₂`, as a single-channel
/// image: the colour distance of dataset curation (`d_color` is its [`masked_mean`] over the
/// valid pixels). Sizes and channel counts must match; NaN samples give NaN.
pub fn rgb_distance(a: &Image, b: &Image) -> Result<Image> {
    a.check_same_size(b, "rgb_distance")?;
    if a.channels() != b.channels() {
        return Err(RasterError::Shape(format!(
            "rgb_distance: channel counts differ ({} vs {})",
            a.channels(),
            b.channels()
        )));
    }
    let c = a.channels();
    let data = a
        .data()
        .par_chunks(c)
        .zip(b.data().par_chunks(c))
        .map(|(pa, pb)| {
            let s: f64 = pa
                .iter()
                .zip(pb)
                .map(|(&u, &v)| {
                    let d = u as f64 - v as f64;
                    d * d
                })
                .sum();
            s.sqrt() as f32
        })
        .collect();
    Image::new(a.width(), a.height(), 1, data)
}

/// Mean of all samples (every channel) of the pixels where `mask` is true, accumulated in f64.
/// `Ok(None)` for an empty mask, so callers cannot divide by zero by accident; NaN samples under
/// the mask make the mean NaN (mask them out first). Sizes must match.
pub fn masked_mean(image: &Image, mask: &Mask) -> Result<Option<f64>> {
    image.check_mask(mask, "masked_mean")?;
    let c = image.channels();
    let (sum, n) = image
        .data()
        .par_chunks(c)
        .zip(mask.data().par_iter())
        .filter(|(_, &m)| m)
        .map(|(p, _)| (p.iter().map(|&v| v as f64).sum::<f64>(), p.len()))
        .reduce(|| (0.0, 0), |(s1, n1), (s2, n2)| (s1 + s2, n1 + n2));
    Ok((n > 0).then(|| sum / n as f64))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inverse_and_compose() {
        let h = Homography([[1.2, 0.1, 5.0], [-0.2, 0.9, -3.0], [1e-4, 2e-4, 1.0]]);
        let id = h.compose(&h.inverse().unwrap());
        for i in 0..3 {
            for j in 0..3 {
                assert!((id.0[i][j] - Homography::IDENTITY.0[i][j]).abs() < 1e-12);
            }
        }
        let (x, y) = h.apply(10.0, 20.0);
        let (bx, by) = h.inverse().unwrap().apply(x, y);
        assert!((bx - 10.0).abs() < 1e-9 && (by - 20.0).abs() < 1e-9);
        assert!(Homography([[0.0; 3]; 3]).inverse().is_none());
    }

    /// 5×4 ramp with two channels: c0 = x + 10 y, c1 = 2x − y. Bilinear is exact on affine data.
    fn ramp() -> Image {
        let (w, h) = (5, 4);
        let mut data = Vec::new();
        for y in 0..h {
            for x in 0..w {
                data.push((x + 10 * y) as f32);
                data.push(2.0 * x as f32 - y as f32);
            }
        }
        Image::new(w, h, 2, data).unwrap()
    }

    #[test]
    fn bilinear_on_ramp() {
        let img = ramp();
        let mut out = [0.0f32; 2];
        assert!(sample_bilinear(&img, 1.25, 2.5, &mut out));
        assert!((out[0] - 26.25).abs() < 1e-5, "{out:?}");
        assert!((out[1] - 0.0).abs() < 1e-5, "{out:?}");
        // Exactly on the far corner (clamped base, weight 1 on the last sample).
        assert!(sample_bilinear(&img, 4.0, 3.0, &mut out));
        assert_eq!(out, [34.0, 5.0]);
        // A tiny overshoot from round-off is accepted at the border.
        assert!(sample_bilinear(&img, 4.0 + 1e-9, -1e-9, &mut out));
        assert!((out[0] - 4.0).abs() < 1e-5);
        // Outside: false, buffer untouched.
        let mut out = [7.0f32; 2];
        assert!(!sample_bilinear(&img, 4.01, 1.0, &mut out));
        assert!(!sample_bilinear(&img, 1.0, -0.01, &mut out));
        assert!(!sample_bilinear(&img, f64::NAN, 1.0, &mut out));
        assert_eq!(out, [7.0, 7.0]);
    }

    #[test]
    fn bilinear_nan_propagation() {
        let mut img = Image::from_fn(3, 3, |x, y| (x + 3 * y) as f32);
        img.set(1, 1, 0, f32::NAN);
        let mut out = [0.0f32];
        // Nonzero weight on the NaN pixel → NaN.
        assert!(sample_bilinear(&img, 0.5, 0.5, &mut out));
        assert!(out[0].is_nan());
        assert!(sample_bilinear(&img, 1.0, 0.25, &mut out));
        assert!(out[0].is_nan());
        // Zero weight on it → the neighbours' interpolation, not NaN.
        assert!(sample_bilinear(&img, 0.5, 0.0, &mut out));
        assert_eq!(out[0], 0.5);
        assert!(sample_bilinear(&img, 2.0, 1.0, &mut out));
        assert_eq!(out[0], 5.0);
    }

    #[test]
    fn warp_translation_equals_shift() {
        let (w, h) = (12, 6);
        let img = Image::from_fn(w, h, |x, y| ((x * 7 + y * 3) % 11) as f32 + 0.5 * y as f32);
        // Output = input moved right by 2.5 px: out(x, y) = in(x − 2.5, y).
        let (out, mask) = warp_homography(&img, &Homography::translation(2.5, 0.0), w, h).unwrap();
        for y in 0..h {
            for x in 0..w {
                if x < 3 {
                    // x − 2.5 < 0: the uncovered strip.
                    assert!(!mask.get(x, y));
                    assert_eq!(out.get(x, y, 0), 0.0);
                } else {
                    assert!(mask.get(x, y));
                    let expected = 0.5 * img.get(x - 3, y, 0) + 0.5 * img.get(x - 2, y, 0);
                    assert!((out.get(x, y, 0) - expected).abs() < 1e-5, "({x}, {y})");
                }
            }
        }
        assert_eq!(mask.count(), (w - 3) * h);
    }

    #[test]
    fn warp_there_and_back() {
        let (w, h) = (40, 30);
        let img = Image::from_fn(w, h, |x, y| {
            (0.15 * x as f32).sin() + (0.1 * y as f32).cos()
        });
        let hm = Homography([[1.02, 0.03, 1.5], [-0.02, 0.98, 0.7], [1e-4, -5e-5, 1.0]]);
        let (fwd, m1) = warp_homography(&img, &hm, w, h).unwrap();
        let (back, m2) = warp_homography(&fwd, &hm.inverse().unwrap(), w, h).unwrap();
        let valid = m1.and(&m2).unwrap();
        let mut checked = 0;
        // Away from the mask edges, two bilinear resamplings of a smooth image stay close.
        for y in 4..h - 4 {
            for x in 4..w - 4 {
                if (y - 1..=y + 1).all(|yy| (x - 1..=x + 1).all(|xx| m2.get(xx, yy)))
                    && valid.get(x, y)
                {
                    assert!(
                        (back.get(x, y, 0) - img.get(x, y, 0)).abs() < 0.02,
                        "({x}, {y})"
                    );
                    checked += 1;
                }
            }
        }
        assert!(checked > 400, "only {checked} pixels checked");
        assert!(warp_homography(&img, &Homography([[0.0; 3]; 3]), w, h).is_err());
    }

    #[test]
    fn centre_crop_offsets() {
        let img = Image::from_fn(7, 6, |x, y| (10 * y + x) as f32);
        let (c, t) = centre_crop(&img, 4, 3).unwrap();
        // Offset ((7−4)/2, (6−3)/2) = (1, 1).
        assert_eq!(c.size(), (4, 3));
        assert_eq!(c.get(0, 0, 0), 11.0);
        assert_eq!(c.get(3, 2, 0), 34.0);
        assert_eq!(t, Homography::translation(-1.0, -1.0));
        assert_eq!(t.apply(1.0, 1.0), (0.0, 0.0));
        assert!(centre_crop(&img, 8, 3).is_err());
        assert!(centre_crop(&img, 7, 7).is_err());
        let (full, t) = centre_crop(&img, 7, 6).unwrap();
        assert_eq!(full, img);
        assert_eq!(t, Homography::translation(0.0, 0.0));
    }

    #[test]
    fn crop_homography_composes() {
        let h = Homography([[2.0, 0.0, 3.0], [0.0, 0.5, -1.0], [0.0, 0.0, 1.0]]);
        let hc = crop_homography(&h, 10.0, 4.0);
        // raw (8, 20) → rectified (19, 9) → crop (9, 5).
        assert_eq!(h.apply(8.0, 20.0), (19.0, 9.0));
        assert_eq!(hc.apply(8.0, 20.0), (9.0, 5.0));
    }

    #[test]
    fn disparity_warp_constant_shift() {
        let (w, h, d) = (10, 3, 3usize);
        let left = Image::from_fn(w, h, |x, y| (x * x + 5 * y) as f32);
        // x_R = x_L − d: right(x) = left(x + d); beyond the left image use a junk value.
        let right = Image::from_fn(w, h, |x, y| {
            if x + d < w {
                left.get(x + d, y, 0)
            } else {
                -100.0
            }
        });
        let mut disp = Image::filled(w, h, 1, d as f32);
        disp.set(7, 1, 0, f32::NAN);
        let (out, mask) = warp_by_disparity(&right, &disp).unwrap();
        for y in 0..h {
            for x in 0..w {
                let valid = x >= d && !(x == 7 && y == 1);
                assert_eq!(mask.get(x, y), valid, "({x}, {y})");
                if valid {
                    assert_eq!(out.get(x, y, 0), left.get(x, y, 0));
                } else {
                    assert_eq!(out.get(x, y, 0), 0.0);
                }
            }
        }
    }

    #[test]
    fn disparity_warp_fractional_and_errors() {
        let right = Image::new(4, 1, 2, vec![0., 1., 10., 11., 20., 21., 30., 31.]).unwrap();
        let disp = Image::new(4, 1, 1, vec![-0.5, 0.25, 1.0, -0.1]).unwrap();
        let (out, mask) = warp_by_disparity(&right, &disp).unwrap();
        // x − d = 0.5, 0.75, 1.0, 3.1 (outside).
        assert_eq!(mask.data(), &[true, true, true, false]);
        assert_eq!(out.data(), &[5., 6., 7.5, 8.5, 10., 11., 0., 0.]);
        assert!(warp_by_disparity(&right, &Image::filled(3, 1, 1, 0.0)).is_err());
        assert!(warp_by_disparity(&right, &Image::filled(4, 1, 2, 0.0)).is_err());
    }

    #[test]
    fn grid_sample_warp_reference_semantics() {
        let right = Image::new(4, 1, 2, vec![0., 1., 10., 11., 20., 21., 30., 31.]).unwrap();
        // x − d = 0.5, 0.75, −0.5 (outside: half of tap 0 with the zero padding), x = 3 (d = NaN → 0).
        let disp = Image::new(4, 1, 1, vec![-0.5, 0.25, 2.5, f32::NAN]).unwrap();
        let (out, mask) = warp_by_disparity_grid_sample(&right, &disp).unwrap();
        assert_eq!(mask.data(), &[true, true, false, true]);
        // Grid normalisation round trips cost an ulp, as in torch.
        let want = [5., 6., 7.5, 8.5, 0., 0.5, 30., 31.];
        for (got, want) in out.data().iter().zip(want) {
            assert!((got - want).abs() < 1e-5, "{:?}", out.data());
        }
        // Exactly on the last column is valid (no slack needed, no slack given).
        let edge = Image::new(4, 1, 1, vec![-3.0, 0.0, 0.0, 3.0000002]).unwrap();
        let (_, mask) = warp_by_disparity_grid_sample(&right, &edge).unwrap();
        assert_eq!(mask.data(), &[true, true, true, false]);
        assert!(warp_by_disparity_grid_sample(&right, &Image::filled(3, 1, 1, 0.0)).is_err());
        assert!(warp_by_disparity_grid_sample(&right, &Image::filled(4, 1, 2, 0.0)).is_err());
    }

    #[test]
    fn rgb_distance_and_mean() {
        let a = Image::new(2, 1, 3, vec![0., 0., 0., 1., 1., 1.]).unwrap();
        let b = Image::new(2, 1, 3, vec![3., 4., 0., 1., 3., 1.]).unwrap();
        let d = rgb_distance(&a, &b).unwrap();
        assert_eq!(d.data(), &[5.0, 2.0]);
        let m = Mask::new(2, 1, vec![true, true]).unwrap();
        assert_eq!(masked_mean(&d, &m).unwrap(), Some(3.5));
        let m = Mask::new(2, 1, vec![false, true]).unwrap();
        assert_eq!(masked_mean(&d, &m).unwrap(), Some(2.0));
        assert_eq!(masked_mean(&d, &Mask::filled(2, 1, false)).unwrap(), None);
        assert!(masked_mean(&d, &Mask::filled(1, 1, true)).is_err());
        assert!(rgb_distance(&a, &Image::filled(2, 1, 1, 0.0)).is_err());
    }
}

//! The SSIM of the release's pair scoring: scikit-image's `structural_similarity` with its
//! defaults (`compute_metrics.py` passes only `full=True, channel_axis=-1, data_range=255`):
//! a 7×7 **uniform** window (`scipy.ndimage.uniform_filter`, `mode='reflect'`: edge sample
//! repeated), sample covariances (`N/(N−1)` with N = 49), `K1 = 0.01`, `K2 = 0.03`, each channel
//! on its own. The score is the mean of the full map over the valid pixels and all channels
//! (`reduce_metric_map`). `raster::ssim` holds the Gaussian-window variant (`gaussian_weights=True`),
//! which is a different number, hence this one.

use anyhow::{bail, Result};
use raster::{Image, Mask};
use rayon::prelude::*;

/// Side of the uniform window (scikit-image's default `win_size`).
pub const WINDOW: usize = 7;
const K1: f64 = 0.01;
const K2: f64 = 0.03;

/// scipy `mode='reflect'`: `d c b a | a b c d | d c b a`, for any offset.
#[inline]
fn reflect(i: isize, n: usize) -> usize {
    let n = n as isize;
    let m = i.rem_euclid(2 * n);
    (if m < n { m } else { 2 * n - 1 - m }) as usize
}

/// Per-pixel, per-channel SSIM map (same shape as the inputs). Both images need the same size
/// and channels, at least 7×7, and finite samples.
pub fn ssim_uniform_map(a: &Image, b: &Image, data_range: f64) -> Result<Image> {
    let (w, h) = a.size();
    if b.size() != (w, h) || a.channels() != b.channels() {
        bail!(
            "SSIM: the images differ in shape ({}x{}x{} vs {}x{}x{})",
            w,
            h,
            a.channels(),
            b.width(),
            b.height(),
            b.channels()
        );
    }
    if w < WINDOW || h < WINDOW {
        bail!("SSIM: a {w}x{h} image is smaller than the {WINDOW}x{WINDOW} window");
    }
    let c = a.channels();
    let r = (WINDOW / 2) as isize;
    let np = (WINDOW * WINDOW) as f64;
    let cov_norm = np / (np - 1.0);
    let (c1, c2) = ((K1 * data_range).powi(2), (K2 * data_range).powi(2));
    let inv = 1.0 / WINDOW as f64;
    // Horizontal window means of the five moments, per (pixel, channel).
    let mut horiz = vec![[0.0f64; 5]; w * h * c];
    horiz
        .par_chunks_mut(w * c)
        .enumerate()
        .for_each(|(y, out)| {
            let (ra, rb) = (a.row(y), b.row(y));
            for x in 0..w {
                for ch in 0..c {
                    let mut m = [0.0f64; 5];
                    for j in -r..=r {
                        let xx = reflect(x as isize + j, w);
                        let (va, vb) = (ra[xx * c + ch] as f64, rb[xx * c + ch] as f64);
                        m[0] += va;
                        m[1] += vb;
                        m[2] += va * va;
                        m[3] += vb * vb;
                        m[4] += va * vb;
                    }
                    out[x * c + ch] = m.map(|v| v * inv);
                }
            }
        });
    let mut data = vec![0.0f32; w * h * c];
    data.par_chunks_mut(w * c).enumerate().for_each(|(y, out)| {
        for (i, o) in out.iter_mut().enumerate() {
            let mut m = [0.0f64; 5];
            for j in -r..=r {
                let yy = reflect(y as isize + j, h);
                let s = &horiz[yy * w * c + i];
                for (mq, sq) in m.iter_mut().zip(s) {
                    *mq += sq;
                }
            }
            let [ux, uy, uxx, uyy, uxy] = m.map(|v| v * inv);
            let vx = cov_norm * (uxx - ux * ux);
            let vy = cov_norm * (uyy - uy * uy);
            let vxy = cov_norm * (uxy - ux * uy);
            let num = (2.0 * ux * uy + c1) * (2.0 * vxy + c2);
            let den = (ux * ux + uy * uy + c1) * (vx + vy + c2);
            *o = (num / den) as f32;
        }
    });
    Ok(Image::new(w, h, c, data)?)
}

/// Mean of [`ssim_uniform_map`] over the pixels of `mask` and every channel; `None` for an
/// empty mask.
pub fn ssim_uniform_masked(
    a: &Image,
    b: &Image,
    mask: &Mask,
    data_range: f64,
) -> Result<Option<f64>> {
    let map = ssim_uniform_map(a, b, data_range)?;
    Ok(raster::geometry::masked_mean(&map, mask)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Naive SSIM at one pixel, straight from the definition (sample covariance, reflected
    /// window).
    fn naive(a: &Image, b: &Image, x: usize, y: usize, l: f64) -> f64 {
        let (w, h) = a.size();
        let mut va = Vec::new();
        let mut vb = Vec::new();
        for dy in -3..=3isize {
            for dx in -3..=3isize {
                let (xx, yy) = (reflect(x as isize + dx, w), reflect(y as isize + dy, h));
                va.push(a.get(xx, yy, 0) as f64);
                vb.push(b.get(xx, yy, 0) as f64);
            }
        }
        let n = va.len() as f64;
        let ma = va.iter().sum::<f64>() / n;
        let mb = vb.iter().sum::<f64>() / n;
        let sa = va.iter().map(|v| (v - ma).powi(2)).sum::<f64>() / (n - 1.0);
        let sb = vb.iter().map(|v| (v - mb).powi(2)).sum::<f64>() / (n - 1.0);
        let sab = va
            .iter()
            .zip(&vb)
            .map(|(p, q)| (p - ma) * (q - mb))
            .sum::<f64>()
            / (n - 1.0);
        let (c1, c2) = ((0.01 * l).powi(2), (0.03 * l).powi(2));
        ((2.0 * ma * mb + c1) * (2.0 * sab + c2)) / ((ma * ma + mb * mb + c1) * (sa + sb + c2))
    }

    #[test]
    fn matches_the_definition_everywhere_including_borders() {
        let a = Image::from_fn(11, 9, |x, y| ((x * 37 + y * 91) % 255) as f32);
        let b = Image::from_fn(11, 9, |x, y| ((x * 13 + y * 7 + 40) % 200) as f32);
        let map = ssim_uniform_map(&a, &b, 255.0).unwrap();
        for y in 0..9 {
            for x in 0..11 {
                let want = naive(&a, &b, x, y, 255.0);
                assert!((map.get(x, y, 0) as f64 - want).abs() < 1e-5, "({x},{y})");
            }
        }
        let same = ssim_uniform_map(&a, &a, 255.0).unwrap();
        assert!(same.data().iter().all(|&v| (v - 1.0).abs() < 1e-6));
        let mask = Mask::from_fn(11, 9, |x, _| x < 3);
        let m = ssim_uniform_masked(&a, &b, &mask, 255.0).unwrap().unwrap();
        let want: f64 = (0..9)
            .flat_map(|y| (0..3).map(move |x| (x, y)))
            .map(|(x, y)| naive(&a, &b, x, y, 255.0))
            .sum::<f64>()
            / 27.0;
        assert!((m - want).abs() < 1e-5);
        assert!(
            ssim_uniform_masked(&a, &b, &Mask::filled(11, 9, false), 255.0)
                .unwrap()
                .is_none()
        );
        assert!(ssim_uniform_map(
            &Image::filled(6, 9, 1, 0.0),
            &Image::filled(6, 9, 1, 0.0),
            255.0
        )
        .is_err());
    }
}

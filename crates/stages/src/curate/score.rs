//! The photometric scores of one pair, as the release's `compute_metrics.py` computes them
//! (`--warp_source pred`, the teacher's disparity): the right image resampled into the left view
//! (`raster::geometry::warp_by_disparity_grid_sample`, the release's `grid_sample` warp),
//! the valid-pixel mask, the colour distance statistics and the SSIM.

use anyhow::{bail, Result};
use raster::ssim::ssim_uniform_masked;
use raster::{Image, Mask};

/// The release reads images with values 0–255 and scores SSIM with this data range.
pub const DATA_RANGE: f32 = 255.0;

/// The inputs of every score of one pair: the left image, its reconstruction from the right
/// image and the pixels where the reconstruction is meaningful.
pub struct WarpedPair {
    /// Left image, 3 channels, NaN samples replaced by 0.
    pub left: Image,
    /// Right image warped into the left view, 3 channels, NaN samples replaced by 0.
    pub left_hat: Image,
    /// Release's `final_mask` (finite teacher disparity ∧ inside the right image), and both
    /// samples finite (images with no-data NaN borders, which the release never has).
    pub valid: Mask,
}

impl WarpedPair {
    pub fn new(left: &Image, right: &Image, disparity: &Image) -> Result<Self> {
        if left.size() != right.size() {
            bail!("the left and right images differ in size");
        }
        if disparity.size() != left.size() || disparity.channels() != 1 {
            bail!(
                "the disparity is {}x{}x{}, the pair is {}x{}: the teacher's disparity must be \
                 single-channel and the size of the pair",
                disparity.width(),
                disparity.height(),
                disparity.channels(),
                left.width(),
                left.height()
            );
        }
        let left = left.to_rgb();
        let right = right.to_rgb();
        // The release's warp: grid_sample(bilinear, zeros, align_corners=True) along x.
        let (left_hat, inside) =
            raster::geometry::warp_by_disparity_grid_sample(&right, disparity)?;
        let finite =
            |img: &Image, i: usize| img.data()[i * 3..i * 3 + 3].iter().all(|v| v.is_finite());
        let (w, h) = left.size();
        let valid: Vec<bool> = (0..w * h)
            .map(|i| {
                inside.data()[i]
                    && disparity.data()[i].is_finite()
                    && finite(&left, i)
                    && finite(&left_hat, i)
            })
            .collect();
        let zero_nan = |img: Image| -> Result<Image> {
            let (w, h, c) = (img.width(), img.height(), img.channels());
            let data = img
                .into_data()
                .into_iter()
                .map(|v| if v.is_finite() { v } else { 0.0 })
                .collect();
            Ok(Image::new(w, h, c, data)?)
        };
        Ok(WarpedPair {
            left: zero_nan(left)?,
            left_hat: zero_nan(left_hat)?,
            valid: Mask::new(w, h, valid)?,
        })
    }

    /// The two images as the release feeds them to the feature network: 0 outside the valid
    /// mask in every channel, then truncated to integers 0–255 (numpy `astype(uint8)` on the
    /// release's 0–255 data; values outside are clamped here rather than wrapped).
    pub fn masked_u8(&self) -> (Image, Image) {
        let m = |img: &Image| -> Image {
            let mut out = img.clone();
            for (p, &v) in out.data_mut().chunks_exact_mut(3).zip(self.valid.data()) {
                for s in p {
                    *s = if v { s.clamp(0.0, 255.0).trunc() } else { 0.0 };
                }
            }
            out
        };
        (m(&self.left), m(&self.left_hat))
    }
}

/// The photometric statistics of one pair, before the dataset-wide normalisation.
#[derive(Clone, Debug, PartialEq)]
pub struct Photometric {
    /// Share of valid pixels.
    pub valid_ratio: f64,
    pub valid_pixels: usize,
    /// Mean and 95th percentile (numpy linear) of the per-pixel RGB distance ‖L − L̂‖₂.
    pub d_color_mean: f64,
    pub d_color_p95: f64,
    /// Mean of the SSIM map over the valid pixels and channels (raw, in [−1, 1]).
    pub ssim: f64,
}

/// Colour distances and SSIM over the valid pixels; `None` when no pixel is valid.
pub fn photometric(pair: &WarpedPair) -> Result<Option<Photometric>> {
    let n = pair.valid.count();
    let total = pair.valid.data().len();
    if n == 0 {
        return Ok(None);
    }
    let dist = raster::geometry::rgb_distance(&pair.left, &pair.left_hat)?;
    let mut values: Vec<f64> = dist
        .data()
        .iter()
        .zip(pair.valid.data())
        .filter(|(_, &v)| v)
        .map(|(&d, _)| d as f64)
        .collect();
    let mean = values.iter().sum::<f64>() / n as f64;
    let p95 = super::select::percentile_linear(&mut values, 95.0).unwrap_or(f64::NAN);
    let ssim = ssim_uniform_masked(&pair.left, &pair.left_hat, &pair.valid, DATA_RANGE)?
        .unwrap_or(f64::NAN);
    Ok(Some(Photometric {
        valid_ratio: n as f64 / total as f64,
        valid_pixels: n,
        d_color_mean: mean,
        d_color_p95: p95,
        ssim,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identical_views_score_perfectly_and_nan_is_excluded() {
        let img = Image::from_fn(16, 12, |x, y| ((x * 17 + y * 5) % 256) as f32);
        let zero = Image::filled(16, 12, 1, 0.0);
        let mut d = zero.clone();
        d.set(3, 3, 0, f32::NAN);
        let pair = WarpedPair::new(&img, &img, &d).unwrap();
        assert_eq!(pair.valid.count(), 16 * 12 - 1);
        let p = photometric(&pair).unwrap().unwrap();
        // The release's f32 grid normalisation round trip leaves ~1e-6 px of interpolation.
        assert!(p.d_color_mean < 1e-4, "{}", p.d_color_mean);
        assert!((p.ssim - 1.0).abs() < 1e-6);
        let all_nan = Image::filled(16, 12, 1, f32::NAN);
        let pair = WarpedPair::new(&img, &img, &all_nan).unwrap();
        assert!(photometric(&pair).unwrap().is_none());
        assert!(WarpedPair::new(&img, &img, &Image::filled(15, 12, 1, 0.0)).is_err());
    }
}

//! Colour maps for disparity and height rasters: a perceptual map (turbo) so that equal steps in
//! value look like equal steps in colour, with invalid (NaN/inf) pixels black.

use std::path::Path;

use crate::formats::{write_png, PngDepth};
use crate::{Image, Result};

/// Maps channel 0 of `image` through the turbo colour map to an RGB image with values 0–255.
/// `range` defaults to the 2nd–98th percentile of the finite values, so a few outliers do not
/// wash out the picture. NaN and infinite values are black.
pub fn colorize(image: &Image, range: Option<(f32, f32)>) -> Image {
    let (lo, hi) = range.or_else(|| robust_range(image)).unwrap_or((0.0, 1.0));
    map(image, |v| {
        let t = if hi > lo {
            ((v - lo) / (hi - lo)) as f64
        } else {
            0.5
        };
        colorous::TURBO.eval_continuous(t.clamp(0.0, 1.0))
    })
}

/// Maps channel 0 of an error map (absolute errors) through the inferno colour map: 0 dark,
/// `max` and above bright yellow, NaN/inf black.
pub fn colorize_error(image: &Image, max: f32) -> Image {
    map(image, |v| {
        let t = if max > 0.0 {
            (v.abs() / max) as f64
        } else {
            1.0
        };
        colorous::INFERNO.eval_continuous(t.clamp(0.0, 1.0))
    })
}

/// [`colorize`] then write as an 8-bit RGB PNG.
pub fn write_colorized_png(
    path: impl AsRef<Path>,
    image: &Image,
    range: Option<(f32, f32)>,
) -> Result<()> {
    write_png(path, &colorize(image, range), PngDepth::Eight)
}

/// The 2nd and 98th percentiles of the finite values of channel 0.
pub fn robust_range(image: &Image) -> Option<(f32, f32)> {
    let mut v: Vec<f32> = image
        .data()
        .iter()
        .step_by(image.channels())
        .copied()
        .filter(|v| v.is_finite())
        .collect();
    if v.is_empty() {
        return None;
    }
    let n = v.len();
    let (i_lo, i_hi) = ((n - 1) * 2 / 100, (n - 1) * 98 / 100);
    let hi = *v.select_nth_unstable_by(i_hi, f32::total_cmp).1;
    let lo = *v[..=i_hi].select_nth_unstable_by(i_lo, f32::total_cmp).1;
    Some((lo, hi))
}

fn map(image: &Image, colour: impl Fn(f32) -> colorous::Color) -> Image {
    let mut data = Vec::with_capacity(image.width() * image.height() * 3);
    for v in image.data().iter().step_by(image.channels()) {
        if v.is_finite() {
            let c = colour(*v);
            data.extend_from_slice(&[c.r as f32, c.g as f32, c.b as f32]);
        } else {
            data.extend_from_slice(&[0.0; 3]);
        }
    }
    Image::new(image.width(), image.height(), 3, data).expect("3 samples per pixel")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nan_is_black_and_endpoints_differ() {
        let img = Image::new(3, 1, 1, vec![f32::NAN, 0.0, 10.0]).unwrap();
        let c = colorize(&img, Some((0.0, 10.0)));
        assert_eq!(c.pixel(0, 0), &[0.0, 0.0, 0.0]);
        assert_ne!(c.pixel(1, 0), c.pixel(2, 0));
        assert!(c.data().iter().all(|v| (0.0..=255.0).contains(v)));
    }

    #[test]
    fn constant_image_is_fine() {
        let c = colorize(&Image::filled(4, 4, 1, 7.0), None);
        assert!(c.data().iter().all(|v| v.is_finite()));
        assert!(c.pixel(0, 0).iter().any(|&v| v > 0.0));
    }

    #[test]
    fn robust_range_ignores_outliers() {
        let mut v: Vec<f32> = (0..1000).map(|i| i as f32).collect();
        v[0] = -1e9;
        v[999] = 1e9;
        v.push(f32::NAN);
        let img = Image::new(v.len(), 1, 1, v).unwrap();
        let (lo, hi) = robust_range(&img).unwrap();
        assert!(
            (15.0..25.0).contains(&lo) && (975.0..985.0).contains(&hi),
            "{lo} {hi}"
        );
    }

    #[test]
    fn error_map_brightens() {
        let img = Image::new(3, 1, 1, vec![0.0, 5.0, f32::NAN]).unwrap();
        let c = colorize_error(&img, 5.0);
        let sum = |p: &[f32]| p.iter().sum::<f32>();
        assert!(sum(c.pixel(1, 0)) > sum(c.pixel(0, 0)) + 300.0);
        assert_eq!(c.pixel(2, 0), &[0.0; 3]);
    }
}

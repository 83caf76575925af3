//! Disparity prediction for one rectified pair, and writing it in the format the user asked for.

use std::path::Path;

use anyhow::{bail, Context, Result};
use matching::SgmParams;
use raster::{colormap, Image};

use crate::progress::{track, Progress};

/// Reads a rectified pair; both images must have the same size.
pub fn read_pair(left: &Path, right: &Path) -> Result<(Image, Image)> {
    let l = raster::read_image(left)
        .with_context(|| format!("reading the left image {}", left.display()))?;
    let r = raster::read_image(right)
        .with_context(|| format!("reading the right image {}", right.display()))?;
    if l.size() != r.size() {
        bail!(
            "the pair is not rectified to one size: {} is {}x{} but {} is {}x{}",
            left.display(),
            l.width(),
            l.height(),
            right.display(),
            r.width(),
            r.height()
        );
    }
    Ok((l, r))
}

/// Matches a pair with census + SGM over `range` (estimated from the images when `None`; prefer a
/// range from the cameras when you have them). Returns the disparity and the range used.
pub fn predict_sgm(
    left: &Image,
    right: &Image,
    range: Option<(i32, i32)>,
    params: &SgmParams,
    progress: &dyn Progress,
) -> Result<(Image, (i32, i32))> {
    let (d_min, d_max) = match range {
        Some(r) => r,
        None => matching::estimate_range(left, right)
            .context("estimating the disparity range (give one with --range)")?,
    };
    let params = SgmParams {
        d_min,
        d_max,
        ..params.clone()
    };
    let total = 5 * left.height();
    let disparity = track(progress, "matching (census + SGM)", total, |cb| {
        matching::match_pair_with_progress(left, right, &params, Some(cb))
    })?;
    Ok((disparity, (d_min, d_max)))
}

/// Writes a disparity map; the extension picks the format: `.iio`/`.npy` (NPY float32),
/// `.tif`/`.tiff` (float32 TIFF), `.pfm` keep the values with NaN for invalid pixels; `.png`
/// writes a colour-mapped picture for viewing (turbo, invalid black), not the values.
pub fn write_disparity(path: &Path, disparity: &Image) -> Result<()> {
    let is_png = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("png"));
    if is_png {
        colormap::write_colorized_png(path, disparity, None)?;
    } else {
        raster::write_image(path, disparity)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mismatched_pair_names_both_files() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a.iio"), dir.path().join("b.iio"));
        raster::write_image(&a, &Image::filled(8, 8, 1, 1.0)).unwrap();
        raster::write_image(&b, &Image::filled(8, 9, 1, 1.0)).unwrap();
        let msg = format!("{:#}", read_pair(&a, &b).unwrap_err());
        assert!(
            msg.contains("a.iio") && msg.contains("b.iio") && msg.contains("8x9"),
            "{msg}"
        );
        let missing = format!(
            "{:#}",
            read_pair(&dir.path().join("none.iio"), &b).unwrap_err()
        );
        assert!(missing.contains("none.iio"), "{missing}");
    }

    #[test]
    fn writes_values_or_pictures_by_extension() {
        let dir = tempfile::tempdir().unwrap();
        let d = Image::new(2, 1, 1, vec![3.5, f32::NAN]).unwrap();
        for ext in ["iio", "tif", "pfm"] {
            let p = dir.path().join(format!("d.{ext}"));
            write_disparity(&p, &d).unwrap();
            let back = raster::read_image(&p).unwrap();
            assert_eq!(back.data()[0], 3.5);
            assert!(back.data()[1].is_nan());
        }
        let p = dir.path().join("d.png");
        write_disparity(&p, &d).unwrap();
        let png = raster::read_image(&p).unwrap();
        assert_eq!(png.channels(), 3);
        assert_eq!(
            png.pixel(1, 0),
            &[0.0, 0.0, 0.0],
            "invalid pixels are black"
        );
    }
}

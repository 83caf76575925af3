//! Reading a rectified pair to match, and writing its disparity in the format the user asked
//! for (the matching itself is [`crate::matcher::Matcher`]'s).

use std::path::Path;

use anyhow::{bail, Context, Result};
use raster::{colormap, Image};

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

//! Mask files: the split's uint8 `.npy` masks and the segmentation stage's per-image
//! `<id>_mask.png`, with the release's polarities.
//!
//! In a `<id>_mask.png` the CLASS is 0 for all three classes (water files use 0/255, tree and
//! building files 0/1). The release reads them as: keep mask = value > 0 (0/1 files) or > 127
//! (0/255 files); building = value == 0 (0/1) or ≤ 127 (0/255). The split stores water/tree as
//! KEEP masks (1 = not the class) and buildings as 1 = building.

use std::io::Write;
use std::path::Path;

use raster::{Image, Mask};

use crate::{DatasetError, Result};

/// Writes `mask` as an NPY uint8 (H, W) array of 0/1, atomically (the release's mask files).
pub fn write_mask_npy(path: &Path, mask: &Mask) -> Result<()> {
    let (w, h) = mask.size();
    let dict = format!("{{'descr': '|u1', 'fortran_order': False, 'shape': ({h}, {w}), }}");
    let mut header = dict.into_bytes();
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(b' ');
    }
    header.push(b'\n');
    let bytes: Vec<u8> = mask.data().iter().map(|&v| v as u8).collect();
    raster::formats::write_atomically(path, |f| {
        f.write_all(b"\x93NUMPY\x01\x00")?;
        f.write_all(&(header.len() as u16).to_le_bytes())?;
        f.write_all(&header)?;
        f.write_all(&bytes)
    })?;
    Ok(())
}

/// Reads a split mask (any raster format): true where the first channel is > 0 (the release's
/// `_to_bool_mask`; NaN counts as false).
pub fn read_mask(path: &Path, hint: &str) -> Result<Mask> {
    if !path.exists() {
        return Err(DatasetError::missing(path, hint));
    }
    let image = raster::read_image(path)?;
    Ok(positive(&image))
}

/// True where the first channel is > 0.
pub fn positive(image: &Image) -> Mask {
    let c = image.channels();
    let data = image.data().chunks(c).map(|p| p[0] > 0.0).collect();
    Mask::new(image.width(), image.height(), data).expect("sizes match")
}

fn first_channel_max(image: &Image) -> f32 {
    let c = image.channels();
    image
        .data()
        .chunks(c)
        .map(|p| p[0])
        .filter(|v| v.is_finite())
        .fold(f32::NEG_INFINITY, f32::max)
}

/// Polarity of a `<id>_mask.png` file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MaskFile {
    /// Water or tree: the result is a KEEP mask (true = not the class).
    Keep,
    /// Building: the result is true ON buildings.
    Building,
}

/// Interprets a segmentation mask picture with the release's rules (see the module docs).
pub fn from_segmentation(image: &Image, kind: MaskFile) -> Mask {
    let binary = first_channel_max(image) <= 1.0;
    let c = image.channels();
    let data = image
        .data()
        .chunks(c)
        .map(|p| {
            let v = p[0];
            match (kind, binary) {
                (MaskFile::Keep, true) => v > 0.0,
                (MaskFile::Keep, false) => v > 127.0,
                (MaskFile::Building, true) => v == 0.0,
                (MaskFile::Building, false) => v <= 127.0,
            }
        })
        .collect();
    Mask::new(image.width(), image.height(), data).expect("sizes match")
}

/// The segmentation file of image `id` in `dir`: `<dir>/<id>_mask.png`.
pub fn segmentation_path(dir: &Path, id: &str) -> std::path::PathBuf {
    dir.join(format!("{id}_mask.png"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn npy_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("m.npy");
        let m = Mask::from_fn(5, 3, |x, y| (x + y) % 2 == 0);
        write_mask_npy(&p, &m).unwrap();
        assert_eq!(std::fs::metadata(&p).unwrap().len(), 128 + 15);
        assert_eq!(read_mask(&p, "").unwrap(), m);
        let err = read_mask(&dir.path().join("x.npy"), "run `masks`").unwrap_err();
        assert!(err.to_string().contains("run `masks`"));
    }

    #[test]
    fn release_polarities() {
        let px = |v: &[f32]| Image::new(v.len(), 1, 1, v.to_vec()).unwrap();
        let keep = |v: &[f32]| from_segmentation(&px(v), MaskFile::Keep).data().to_vec();
        let building = |v: &[f32]| {
            from_segmentation(&px(v), MaskFile::Building)
                .data()
                .to_vec()
        };
        // Water file 0/255: class = 0 → not kept.
        assert_eq!(keep(&[0.0, 255.0]), [false, true]);
        // Tree file 0/1.
        assert_eq!(keep(&[0.0, 1.0]), [false, true]);
        // All-class tree file (max 0): nothing kept.
        assert_eq!(keep(&[0.0, 0.0]), [false, false]);
        // Building 0/1: 0 = building.
        assert_eq!(building(&[0.0, 1.0]), [true, false]);
        assert_eq!(building(&[0.0, 255.0, 100.0]), [true, false, true]);
    }
}

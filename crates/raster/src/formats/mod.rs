//! Reading and writing the raster formats users already have.
//!
//! Every reader names the file in its errors and never panics on a malformed input (decoders from
//! other crates are run under [`std::panic::catch_unwind`]); every writer goes through
//! [`write_atomically`] so that a killed process never leaves a half-written output behind.

pub mod cog;
pub mod npy;
pub mod npz;
pub mod pfm;
pub mod png;
mod support;
pub mod tiff;

use std::path::Path;

use crate::{Image, RasterError, Result};

pub use self::cog::{write_cog, write_tiled_u8, CogWriter};
pub use self::npy::{read_npy, write_npy};
pub use self::npz::{read_homographies, write_homographies};
pub use self::pfm::{read_pfm, write_pfm};
pub use self::png::{decode_png, encode_png, read_png, write_png, PngDepth};
pub use self::support::write_atomically;
pub use self::tiff::{
    read_tiff, write_geotiff, GeoRaster, GeoReference, GeoTiffMeta, RpcTag, TiffReader,
};

/// The extensions [`read_image`] and [`write_image`] understand.
pub const SUPPORTED_EXTENSIONS: &[&str] = &["npy", "iio", "tif", "tiff", "png", "pfm"];

/// The format a path's extension selects.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    Npy,
    Tiff,
    Png,
    Pfm,
}

/// The extension of `path` in lower case (empty when it has none): what the formats are told
/// apart by, whatever the case of the file name.
pub fn extension_of(path: &Path) -> String {
    path.extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default()
}

fn kind_of(path: &Path) -> Result<Kind> {
    let ext = extension_of(path);
    match ext.as_str() {
        "npy" | "iio" => Ok(Kind::Npy),
        "tif" | "tiff" => Ok(Kind::Tiff),
        "png" => Ok(Kind::Png),
        "pfm" => Ok(Kind::Pfm),
        _ => Err(RasterError::format(
            path,
            format!(
                "unsupported image extension {:?} (supported: {})",
                ext,
                SUPPORTED_EXTENSIONS.join(", ")
            ),
        )),
    }
}

/// Reads an image of any supported format, chosen by the (case-insensitive) extension. For
/// GeoTIFFs only the pixels are kept; use [`read_tiff`] for the georeferencing.
pub fn read_image(path: impl AsRef<Path>) -> Result<Image> {
    let path = path.as_ref();
    match kind_of(path)? {
        Kind::Npy => read_npy(path),
        Kind::Tiff => read_tiff(path).map(|r| r.image),
        Kind::Png => read_png(path),
        Kind::Pfm => read_pfm(path),
    }
}

/// Writes an image in the format chosen by the extension: NPY float32, float32 TIFF without
/// georeferencing, 8-bit PNG or little-endian PFM.
pub fn write_image(path: impl AsRef<Path>, image: &Image) -> Result<()> {
    let path = path.as_ref();
    match kind_of(path)? {
        Kind::Npy => write_npy(path, image),
        Kind::Tiff => write_geotiff(path, image, &GeoTiffMeta::default()),
        Kind::Png => write_png(path, image, PngDepth::Eight),
        Kind::Pfm => write_pfm(path, image),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn extension_dispatch_is_case_insensitive() {
        assert_eq!(kind_of(Path::new("a/b.TIF")).unwrap(), Kind::Tiff);
        assert_eq!(kind_of(Path::new("x.iio")).unwrap(), Kind::Npy);
        let e = kind_of(Path::new("x.jpg")).unwrap_err().to_string();
        assert!(e.contains("x.jpg") && e.contains("pfm"), "{e}");
    }
}

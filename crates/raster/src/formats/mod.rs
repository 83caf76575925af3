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
pub mod tiff;

use std::fs::{self, File, OpenOptions};
use std::io::{self, BufWriter, Write};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};

use crate::{Image, RasterError, Result};

pub use self::cog::{write_cog, write_tiled_u8};
pub use self::npy::{read_npy, write_npy};
pub use self::npz::{read_homographies, write_homographies};
pub use self::pfm::{read_pfm, write_pfm};
pub use self::png::{decode_png, encode_png, read_png, write_png, PngDepth};
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

fn kind_of(path: &Path) -> Result<Kind> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default();
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

/// Writes `path` by filling a temporary file in the same directory and renaming it into place, so
/// readers (and a process killed half-way) only ever see the old file or the complete new one.
/// Missing parent directories are created.
pub fn write_atomically(
    path: impl AsRef<Path>,
    write: impl FnOnce(&mut BufWriter<File>) -> io::Result<()>,
) -> Result<()> {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let path = path.as_ref();
    let err = |e| RasterError::io(path, e);
    let name = path.file_name().ok_or_else(|| {
        RasterError::io(
            path,
            io::Error::new(io::ErrorKind::InvalidInput, "not a file path"),
        )
    })?;
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    fs::create_dir_all(dir).map_err(err)?;
    let (tmp, file) = loop {
        let mut tmp_name = std::ffi::OsString::from(".");
        tmp_name.push(name);
        tmp_name.push(format!(
            ".tmp{}-{}",
            std::process::id(),
            COUNTER.fetch_add(1, Ordering::Relaxed)
        ));
        let tmp = dir.join(tmp_name);
        match OpenOptions::new().write(true).create_new(true).open(&tmp) {
            Ok(f) => break (tmp, f),
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(err(e)),
        }
    };
    let result = (|| {
        let mut w = BufWriter::new(file);
        write(&mut w)?;
        w.flush()?;
        let file = w.into_inner().map_err(|e| e.into_error())?;
        drop(file);
        fs::rename(&tmp, path)
    })();
    if let Err(e) = result {
        let _ = fs::remove_file(&tmp);
        return Err(err(e));
    }
    Ok(())
}

/// Reads a whole file, as an I/O error naming it.
pub(crate) fn read_bytes(path: &Path) -> Result<Vec<u8>> {
    fs::read(path).map_err(|e| RasterError::io(path, e))
}

/// Runs a decoder from another crate, turning a panic into a format error naming the file.
pub(crate) fn no_panic<T>(path: &Path, what: &str, f: impl FnOnce() -> Result<T>) -> Result<T> {
    catch_unwind(AssertUnwindSafe(f)).unwrap_or_else(|_| {
        Err(RasterError::format(
            path,
            format!("malformed {what} file (the decoder gave up)"),
        ))
    })
}

/// A zero-filled sample buffer of `len` values, or a format error instead of an abort when a
/// header asks for more memory than there is.
pub(crate) fn alloc_samples(path: &Path, len: usize, value: f32) -> Result<Vec<f32>> {
    let mut v = Vec::new();
    v.try_reserve_exact(len).map_err(|_| {
        RasterError::format(path, format!("cannot allocate {len} samples for the image"))
    })?;
    v.resize(len, value);
    Ok(v)
}

/// `width * height * channels`, or a format error when it overflows or exceeds `max`.
pub(crate) fn checked_samples(
    path: &Path,
    width: u64,
    height: u64,
    channels: u64,
    max: u64,
) -> Result<usize> {
    width
        .checked_mul(height)
        .and_then(|n| n.checked_mul(channels))
        .filter(|&n| n <= max)
        .and_then(|n| usize::try_from(n).ok())
        .ok_or_else(|| {
            RasterError::format(
                path,
                format!("implausible image size {width}x{height}x{channels} for this file"),
            )
        })
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

    #[test]
    fn atomic_write_leaves_no_temp_on_error() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("sub/out.bin");
        assert!(write_atomically(&p, |w| {
            w.write_all(b"partial")?;
            Err(io::Error::other("boom"))
        })
        .is_err());
        assert!(!p.exists());
        assert_eq!(fs::read_dir(p.parent().unwrap()).unwrap().count(), 0);
        write_atomically(&p, |w| w.write_all(b"ok")).unwrap();
        assert_eq!(fs::read(&p).unwrap(), b"ok");
    }
}

//! What the codecs share: atomic writes, whole-file reads, and a decoder's panic or an
//! implausible size turned into an error naming the file.

use std::ffi::{OsStr, OsString};
use std::fs::{self, File, OpenOptions};
use std::io::{self, BufWriter, Write};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use crate::{RasterError, Result};

/// Writes `path` by filling a temporary file in the same directory and renaming it into place, so
/// readers (and a process killed half-way) only ever see the old file or the complete new one.
/// Missing parent directories are created.
pub fn write_atomically(
    path: impl AsRef<Path>,
    write: impl FnOnce(&mut BufWriter<File>) -> io::Result<()>,
) -> Result<()> {
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
    let (tmp, file) = create_hidden_beside(dir, name, "tmp").map_err(err)?;
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

/// A new file `.<name>.<kind><pid>-<n>` in `dir`, open for reading and writing, never one that
/// exists: the hidden scratch files written beside an output (`tmp` for the atomic writes,
/// `spool` for a COG's parked tiles), unique across threads and processes.
pub(crate) fn create_hidden_beside(
    dir: &Path,
    name: &OsStr,
    kind: &str,
) -> io::Result<(PathBuf, File)> {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    loop {
        let mut hidden = OsString::from(".");
        hidden.push(name);
        hidden.push(format!(
            ".{kind}{}-{}",
            std::process::id(),
            COUNTER.fetch_add(1, Ordering::Relaxed)
        ));
        let path = dir.join(hidden);
        let open = OpenOptions::new()
            .read(true)
            .write(true)
            .create_new(true)
            .open(&path);
        match open {
            Ok(file) => return Ok((path, file)),
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(e),
        }
    }
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

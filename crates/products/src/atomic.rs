//! Atomic writes for writers that must own their file: the `las` crate's writer seeks back to
//! fill its header and wants a `'static` stream, so [`raster::formats::write_atomically`]'s
//! borrowed buffer does not fit it.

use std::ffi::OsString;
use std::fs::{File, OpenOptions};
use std::io;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use raster::RasterError;

use crate::{ProductsError, Result};

/// Writes `path` by handing `write` a hidden temporary file in the same directory and renaming
/// it into place once `write` returns it: readers, and a process killed half-way, see the old
/// file or the complete new one. The temporary file is removed on error. Missing parent
/// directories are created.
pub(crate) fn write_owned_atomically(
    path: &Path,
    write: impl FnOnce(File) -> Result<File>,
) -> Result<()> {
    let io_err = |e: io::Error| ProductsError::from(RasterError::io(path, e));
    let name = path
        .file_name()
        .ok_or_else(|| io_err(io::Error::other("not a file path")))?;
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    std::fs::create_dir_all(dir).map_err(io_err)?;
    let (tmp, file) = create_beside(dir, name).map_err(io_err)?;
    let result = write(file).and_then(|file| {
        drop(file);
        std::fs::rename(&tmp, path).map_err(io_err)
    });
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// A new file `.<name>.tmp<pid>-<n>` in `dir`, never one that exists (unique across threads and
/// processes), as the raster crate names its own temporary files.
fn create_beside(dir: &Path, name: &std::ffi::OsStr) -> io::Result<(PathBuf, File)> {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    loop {
        let mut hidden = OsString::from(".");
        hidden.push(name);
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        hidden.push(format!(".tmp{}-{n}", std::process::id()));
        let tmp = dir.join(hidden);
        match OpenOptions::new()
            .read(true)
            .write(true)
            .create_new(true)
            .open(&tmp)
        {
            Ok(file) => return Ok((tmp, file)),
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(e),
        }
    }
}

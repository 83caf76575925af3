//! A level's compressed tiles parked on disk beside the output until the file is assembled: the
//! directories that come first in a COG need every tile's length, and holding the tiles of a
//! whole-scene DSM in memory would cost as much as the DSM.

use std::fs::{self, File};
use std::io::{self, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use crate::formats::support::create_hidden_beside;

/// A temporary file, removed when dropped.
pub(super) struct Spool {
    path: PathBuf,
    file: File,
}

impl Spool {
    /// A new empty spool in `dir`, named after the output `name` (hidden, like the atomic
    /// writer's temporary file).
    pub fn create(dir: &Path, name: &std::ffi::OsStr) -> io::Result<Self> {
        let (path, file) = create_hidden_beside(dir, name, "spool")?;
        Ok(Spool { path, file })
    }

    pub fn append(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.file.write_all(bytes)
    }

    /// Copies everything appended into `out`.
    pub fn copy_into(&mut self, out: &mut impl Write) -> io::Result<()> {
        self.file.seek(SeekFrom::Start(0))?;
        io::copy(&mut self.file, out)?;
        Ok(())
    }
}

impl Drop for Spool {
    fn drop(&mut self) {
        let _ = fs::remove_file(&self.path);
    }
}

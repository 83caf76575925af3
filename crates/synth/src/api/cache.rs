//! On-disk cache of API answers, keyed by a hash of everything that determines the answer
//! (model, prompt, generation settings, input image bytes), so a rerun never pays twice.
//! Entries are the returned image bytes, written atomically: a crash leaves no half entry.

use std::io::Write;
use std::path::PathBuf;

use sha2::{Digest, Sha256};

use crate::SynthError;

pub(crate) struct ResponseCache {
    dir: PathBuf,
}

/// Extensions tried on lookup, by returned MIME type.
const EXTENSIONS: [&str; 2] = ["png", "jpg"];

impl ResponseCache {
    pub(crate) fn new(dir: impl Into<PathBuf>) -> Self {
        Self { dir: dir.into() }
    }

    /// Hex SHA-256 of the length-prefixed parts.
    pub(crate) fn key(parts: &[&[u8]]) -> String {
        let mut hasher = Sha256::new();
        hasher.update(b"seasonstereo-synth-cache-v1");
        for part in parts {
            hasher.update((part.len() as u64).to_le_bytes());
            hasher.update(part);
        }
        hasher
            .finalize()
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect()
    }

    /// The cached bytes for `key`, if any.
    pub(crate) fn get(&self, key: &str) -> Result<Option<(PathBuf, Vec<u8>)>, SynthError> {
        for ext in EXTENSIONS {
            let path = self.path(key, ext);
            match std::fs::read(&path) {
                Ok(bytes) => return Ok(Some((path, bytes))),
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(e) => return Err(SynthError::Cache { path, source: e }),
            }
        }
        Ok(None)
    }

    /// Stores `bytes` (an image of `mime` type) under `key`.
    pub(crate) fn put(&self, key: &str, mime: &str, bytes: &[u8]) -> Result<PathBuf, SynthError> {
        let ext =
            if mime.contains("jpeg") || mime.contains("jpg") || bytes.starts_with(&[0xff, 0xd8]) {
                "jpg"
            } else {
                "png"
            };
        let path = self.path(key, ext);
        raster::formats::write_atomically(&path, |f| f.write_all(bytes))?;
        Ok(path)
    }

    fn path(&self, key: &str, ext: &str) -> PathBuf {
        // Two-level fan-out keeps directories small on big datasets.
        self.dir.join(&key[..2]).join(format!("{key}.{ext}"))
    }
}

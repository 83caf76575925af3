use std::path::{Path, PathBuf};

/// What went wrong with a raster, always naming the file when one is involved.
#[derive(Debug, thiserror::Error)]
pub enum RasterError {
    /// The file could not be opened, read or written.
    // The I/O error is in the message, not also a `source`: an anyhow chain (`{:#}`) would
    // print it twice.
    #[error("{}: {error}", path.display())]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    /// The file exists but its content is not what the format or the caller requires.
    #[error("{}: {message}", path.display())]
    Format { path: PathBuf, message: String },
    /// Two rasters (or a raster and a parameter) do not fit together.
    #[error("{0}")]
    Shape(String),
}

impl RasterError {
    /// A format error for `path`.
    pub fn format(path: &Path, message: impl Into<String>) -> Self {
        Self::Format {
            path: path.to_path_buf(),
            message: message.into(),
        }
    }

    /// An I/O error for `path`.
    pub fn io(path: &Path, source: std::io::Error) -> Self {
        Self::Io {
            path: path.to_path_buf(),
            error: source,
        }
    }
}

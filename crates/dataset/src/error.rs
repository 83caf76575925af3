//! Errors that name the file and the stage that produces it.

use std::path::PathBuf;

/// What went wrong with a training set.
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    /// A file the set needs is absent; `hint` says which stage or command writes it.
    #[error("{} is missing ({hint})", path.display())]
    Missing { path: PathBuf, hint: String },
    /// A raster could not be read or written, or has the wrong size.
    #[error(transparent)]
    Raster(#[from] raster::RasterError),
    /// A text file (CSV, JSON) is malformed.
    #[error("{}: {message}", path.display())]
    Format { path: PathBuf, message: String },
    /// A name or an argument is malformed.
    #[error("{0}")]
    Invalid(String),
    /// Any other I/O error, with its file.
    // The I/O error is in the message, not also a `source`: an anyhow chain (`{:#}`) would
    // print it twice.
    #[error("{}: {error}", path.display())]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
}

impl DatasetError {
    pub fn missing(path: impl Into<PathBuf>, hint: impl Into<String>) -> Self {
        Self::Missing {
            path: path.into(),
            hint: hint.into(),
        }
    }

    pub fn format(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        Self::Format {
            path: path.into(),
            message: message.into(),
        }
    }

    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self::Io {
            path: path.into(),
            error: source,
        }
    }
}

use std::path::PathBuf;

use camera::CameraError;
use raster::RasterError;

/// What went wrong while making a product. Errors about a file name the file.
#[derive(Debug, thiserror::Error)]
pub enum ProductsError {
    /// A raster (a DSM, an image of a view, an output picture) could not be read or written.
    #[error(transparent)]
    Raster(#[from] RasterError),
    /// A camera model or a grid could not be used.
    #[error(transparent)]
    Camera(#[from] CameraError),
    /// A point cloud could not be written: the message says why.
    // The underlying error is in the message, not also a `source`, so an anyhow chain (`{:#}`)
    // prints it once.
    #[error("{}: {message}", path.display())]
    PointCloud { path: PathBuf, message: String },
    /// Inputs that do not fit together (sizes, channels), or an output the crate cannot write.
    #[error("{0}")]
    Input(String),
}

impl ProductsError {
    /// A point-cloud error for `path`.
    pub(crate) fn point_cloud(path: &std::path::Path, message: impl ToString) -> Self {
        Self::PointCloud {
            path: path.to_path_buf(),
            message: message.to_string(),
        }
    }
}

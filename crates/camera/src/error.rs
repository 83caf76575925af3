use raster::RasterError;

/// What went wrong with a camera model, a grid or the inputs of a triangulation. Errors about a
/// file name the file; errors about a malformed RPC name the offending key.
#[derive(Debug, thiserror::Error)]
pub enum CameraError {
    /// An RPC model could not be read: `origin` is the file (or `<json>` for an in-memory value).
    #[error("{origin}: RPC key {key:?}: {message}")]
    Rpc {
        origin: String,
        key: String,
        message: String,
    },
    /// Acquisition metadata (an `.IMD`, a DIMAP `DIM_*.XML`, a TIFF's GDAL metadata) that could
    /// not be read: `origin` is the file, `key` the offending entry.
    #[error("{origin}: metadata key {key:?}: {message}")]
    Metadata {
        origin: String,
        key: String,
        message: String,
    },
    /// A raster could not be read or written.
    #[error(transparent)]
    Raster(#[from] RasterError),
    /// A georeference the DSM code cannot use (missing, rotated, not UTM).
    #[error("{0}")]
    Georeference(String),
    /// Inputs that do not fit together (sizes, singular homographies, bad parameters).
    #[error("{0}")]
    Input(String),
    /// An iterative solver did not converge.
    #[error("{0}")]
    NoConvergence(String),
}

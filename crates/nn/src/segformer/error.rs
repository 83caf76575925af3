//! What can go wrong in segmentation, shared by the pre- and post-processing and the
//! [`Segmenter`](super::Segmenter).

use crate::weights::WeightsError;

/// Errors of segmentation.
#[derive(Debug, thiserror::Error)]
pub enum SegformerError {
    /// The checkpoint could not be read or does not fit the model.
    #[error(transparent)]
    Weights(#[from] WeightsError),
    /// A raster operation failed (sizes).
    #[error(transparent)]
    Raster(#[from] raster::RasterError),
    /// The masks could not be made from the scores.
    #[error(transparent)]
    Masks(#[from] dataset::DatasetError),
    /// Bad input (not 8-bit, empty, bad configuration).
    #[error("segmentation: {0}")]
    Input(String),
}

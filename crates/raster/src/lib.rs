//! Images and rasters for satellite stereo: one in-memory type, the file formats users already have
//! (NPY `.iio`, NPZ homographies, TIFF/GeoTIFF with RPCs, PNG, PFM) and the resampling kernels that
//! rectified-pair geometry is built from (bilinear sampling, homography and disparity warps, SSIM).
//!
//! Everything here is plain CPU code with no deep-learning dependency, so it builds and tests in seconds.

mod error;
mod image;

pub mod colormap;
pub mod formats;
pub mod geometry;
pub mod morphology;
pub mod resize;
pub mod ssim;

pub use error::RasterError;
pub use formats::{read_image, write_image};
pub use geometry::Homography;
pub use image::{Image, Mask};

/// Result type of this crate.
pub type Result<T, E = RasterError> = std::result::Result<T, E>;

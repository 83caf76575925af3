//! The products written beside a DSM: the true orthoimage (the views' colours draped on the DSM's
//! grid, each cell taken from a view that sees it), the coloured point cloud (LAS, LAZ or PLY, one
//! point per measured cell) and the quicklook (a PNG of the heights in colour over a hillshade).
//!
//! # What this crate does not do
//!
//! It makes no DSM and matches no pixels: it takes a finished DSM on its [`camera::DsmGrid`] and
//! the RPC cameras of the views. The orthoimage's geometry is only as good as the DSM's: a
//! misplaced wall in the DSM moves the roof's colours with it.
//!
//! # Conventions
//!
//! * Images are [`raster::Image`]s (f32, row-major, channels interleaved); the orthoimage is RGB
//!   with values 0–255, `(0, 0, 0)` meaning "no data" and nothing else.
//! * Image coordinates of an RPC are pixel centres: pixel `(i, j)` is at `(i, j)`, as GDAL's RPC
//!   transformer and rpcm have it.
//! * Every file is written atomically: a hidden temporary file beside the output, renamed into
//!   place once complete.

mod atomic;
mod error;

pub mod ortho;
pub mod outputs;
pub mod points;
pub mod preview;

pub use error::ProductsError;
pub use ortho::{orthoimage, visibility, write_ortho, OrthoBlend, OrthoView};
pub use outputs::{measured_cells, measured_from_sidecar, MeasuredFrom, Products, ProductsWritten};
pub use points::write_point_cloud;
pub use preview::{dsm_picture, hillshade, write_preview};

/// Result type of this crate.
pub type Result<T, E = ProductsError> = std::result::Result<T, E>;

//! Satellite camera geometry: RPC camera models (with the vendor sidecars they are delivered
//! in), UTM coordinates, the benchmark's iterative triangulation of rectified disparities and the
//! max-per-cell DSM rasterisation.
//!
//! Everything here follows the released evaluation code (rpcm's localisation, s2p's altitude
//! iteration, floor-and-max gridding), so altitude errors computed with it are comparable to the
//! paper's.

mod error;

pub mod adjust;
pub mod crs;
pub mod dsm;
pub mod geoid;
pub mod heights;
pub mod rectify;
pub mod rpc;
pub mod triangulate;
pub mod utm;
pub mod vendor;

pub use adjust::{
    adjust_translations, AdjustParams, Adjustment, Gauge, ImageFit, Observation, Track,
};
pub use crs::Crs;
pub use dsm::{
    fill_holes, grid_writer, median_filter, rasterize, rasterize_max, rasterize_window,
    rasterize_window_with, read_dsm, resample_nearest, write_dsm, write_grid_raster, DsmGrid,
    DsmRaster, GridWindow, Gridding, HoleFill,
};
pub use error::CameraError;
pub use geoid::{egm96_undulation, to_egm96};
pub use heights::{Band, Heights};
pub use rpc::RpcModel;
pub use triangulate::{altitude, evaluation_mask, triangulate_disparity, Points};
pub use utm::UtmZone;
pub use vendor::{
    camera_beside, find_camera_file, find_metadata_file, metadata_of, read_camera_file,
    read_metadata_file, Acquisition,
};

/// Result type of this crate.
pub type Result<T, E = CameraError> = std::result::Result<T, E>;

//! What to reconstruct and how: the options of [`super::reconstruct`], in a file of their own so
//! that the checks before work (`sanity`) read them without importing the job.

use std::path::PathBuf;

use camera::rectify::Roi;
use camera::Gridding;
use dataset::shard::Shard;

use crate::dsm::{GridChoice, DEFAULT_FILL_CELLS, DEFAULT_MEDIAN_CELLS};
use crate::matcher::Matcher;

/// What to reconstruct and how.
#[derive(Clone, Debug)]
pub struct ReconstructOptions {
    pub left: PathBuf,
    pub right: PathBuf,
    /// SatNeRF/rpcm JSON cameras (instead of the images' RPC tags).
    pub rpc_left: Option<PathBuf>,
    pub rpc_right: Option<PathBuf>,
    /// Region of the left raw image; the whole image when `None`.
    pub roi: Option<Roi>,
    /// Region as lon/lat bounds `[lon_min, lat_min, lon_max, lat_max]` (degrees), instead of
    /// `roi`: the pixels of the left image that see it at any altitude of the scene.
    pub roi_lonlat: Option<[f64; 4]>,
    /// Scene altitudes, metres (else from the JSON or the RPCs).
    pub alt_range: Option<(f64, f64)>,
    pub matcher: Matcher,
    /// Output DSM GeoTIFF.
    pub output: PathBuf,
    /// Folder of the tiles' records and cells; `<output without extension>_work` when `None`.
    pub work_dir: Option<PathBuf>,
    pub grid: GridChoice,
    pub gridding: Gridding,
    /// Hole filling distance in cells (see [`camera::fill_holes`]); `None`: no filling.
    pub fill_holes: Option<usize>,
    /// Median filter window of the DSM, cells (odd); `None`: none.
    pub median_filter: Option<usize>,
    /// Pixels of the rectified disparity ignored at each border.
    pub border: usize,
    /// A ground-truth `<AOI>_DSM.tif` (its `_CLS.tif` beside it) to score the DSM against; the
    /// DSM must then be on its grid (`grid` = `Like` the truth).
    pub truth: Option<PathBuf>,
    /// Tile side in left raw pixels.
    pub tile: usize,
    /// Overlap collar around each tile, pixels.
    pub collar: usize,
    /// Memory budget of the process, bytes.
    pub max_memory: u64,
    /// The tiles this process runs.
    pub shard: Shard,
    /// Only assemble the DSM from the tiles' records (after sharded runs).
    pub merge_only: bool,
    /// Run this shard's tiles and stop: never assemble the DSM (a cluster job's merge step
    /// does).
    pub tiles_only: bool,
    /// Refuse to assemble a DSM while some tiles are failed (exit code 3, naming them), instead
    /// of writing it from the others (exit code 2).
    pub complete_only: bool,
    /// Keep every tile's rectified pair and disparity in the work folder (`L/`, `R/`,
    /// `homography/`, `disparity/`, the layout `eval` reads).
    pub keep_intermediates: bool,
}

impl ReconstructOptions {
    /// The defaults for a pair: whole image, 1024-pixel tiles with 64-pixel collars, 2 GiB.
    pub fn new(
        left: PathBuf,
        right: PathBuf,
        matcher: Matcher,
        grid: GridChoice,
        output: PathBuf,
    ) -> Self {
        ReconstructOptions {
            left,
            right,
            rpc_left: None,
            rpc_right: None,
            roi: None,
            roi_lonlat: None,
            alt_range: None,
            matcher,
            output,
            work_dir: None,
            grid,
            gridding: Gridding::Median,
            fill_holes: Some(DEFAULT_FILL_CELLS),
            median_filter: Some(DEFAULT_MEDIAN_CELLS),
            border: 0,
            truth: None,
            tile: 1024,
            collar: 64,
            max_memory: 2 << 30,
            shard: Shard::ALL,
            merge_only: false,
            tiles_only: false,
            complete_only: false,
            keep_intermediates: false,
        }
    }
}

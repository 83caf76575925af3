//! # seasonstereo
//!
//! Dense stereo matching of multi-date satellite imagery: a pair of satellite images, taken in
//! the same pass or in different seasons, becomes a disparity map and a Digital Surface Model
//! (DSM). This crate is the product's library API: the `seasonstereo` command line, the Python
//! package and the cluster jobs all call these functions with these option structs, so what one
//! of them can do, the others can.
//!
//! | step | function | options → result |
//! |---|---|---|
//! | raw pair → rectified pair | [`rectify`] | [`RectifyOptions`] → [`RectifySummary`] |
//! | rectified pair → disparity | [`predict`] | [`Matcher`], [`RangeSource`] → [`Matched`] |
//! | disparity → DSM | [`dsm`] | [`DsmOptions`] → [`DsmSummary`] |
//! | raw pair → DSM, tiled, resumable | [`reconstruct`](fn@reconstruct) | [`ReconstructOptions`] → [`ReconstructSummary`] |
//! | many dates → best pairs → one fused DSM | [`reconstruct_many`] | [`ReconstructManyOptions`] → [`ReconstructManySummary`] |
//! | DSM → benchmark scores | [`score`] | [`Truth`] → [`DsmScores`] |
//! | two DSMs → scores on the cells both cover | [`score_against`] | [`Truth`] → [`Versus`] |
//! | disparities of a split → Table 1 | [`eval`](fn@eval) | [`EvalOptions`] → [`EvalReport`] |
//! | the training set | [`stages`] | teacher → curate → synthesize → masks → dataset build |
//!
//! Conventions: pairs are rectified (epipolar lines are rows); disparity lives on the left view,
//! `x_R = x_L − d`, positive and growing with altitude; invalid pixels are NaN. DSMs are float32
//! Cloud-Optimized GeoTIFFs on a UTM grid, NaN where no point fell.
//!
//! Beside the functions above, each job's own items live in a small module: [`stages`],
//! [`jobs`] (the Slurm submissions' helpers), [`world`], [`demo`], `train` (feature `network`),
//! [`bench`](mod@bench) (what `seasonstereo bench` times) and [`benchmark`] (the evaluation's splits and
//! rules); the front ends share [`flags`] (options as typed), [`defaults`] and [`outputs`] (the
//! outputs' guards).
//!
//! Long calls report progress through a [`Progress`] (the CLI draws bars; [`Silent`] draws
//! nothing). Errors are [`anyhow::Error`]s whose text names the file and the fix; the underlying
//! [`std::io::Error`] (a missing file, a full disk) stays reachable with `downcast_ref`.
//!
//! ```no_run
//! use seasonstereo::{reconstruct, GridChoice, Matcher, ReconstructOptions, SgmParams, Silent};
//!
//! let options = ReconstructOptions::new(
//!     "left.tif".into(),
//!     "right.tif".into(),
//!     Matcher::Classical(SgmParams::default()),
//!     GridChoice::Resolution { resolution: 0.5, bounds: None, epsg: None },
//!     "dsm.tif".into(),
//! );
//! let summary = reconstruct(&options, &Silent)?;
//! println!("{} of {} tiles done", summary.records.len(), summary.records.len() + summary.missing.len());
//! # Ok::<(), anyhow::Error>(())
//! ```
//!
//! The learned matcher (MonSter++) and segmenter (SegFormer) need the default feature `network`
//! (burn); without it everything else builds and runs.
#![deny(missing_docs)]

use std::path::Path;

pub use ::jobs::{
    ChainRequest, ChainStatus, ChainSubmitted, JobStatus, Resources, SlurmRequest, StageLine,
    StageStatus, Submitted, Units,
};
pub use anyhow::{Error, Result};
pub use camera::rectify::Roi;
pub use camera::{read_dsm, Crs, DsmGrid, DsmRaster, Gridding, Heights, RpcModel, UtmZone};
pub use dataset::Shard;
pub use eval::metrics::DsmScores;
pub use eval::score::truth_zone;
pub use eval::{CellsMae, EvalOptions, EvalReport, Truth, Versus};
pub use matching::{Aggregation, SgmParams};
#[cfg(feature = "network")]
pub use nn::device::DeviceChoice;
#[cfg(feature = "network")]
pub use nn::infer::Normalisation;
pub use products::{OrthoBlend, Products, ProductsWritten};
pub use raster::Image;
pub use reconstruct::dsm::{Comparison, DsmOptions, DsmSummary, GridChoice};
pub use reconstruct::finishing::Finishing;
pub use reconstruct::fuse::{Agreement, FusionParams};
pub use reconstruct::many::{
    auto_min_confidence, auto_min_support, FusedOutcome, PairOutcome, PairStatus,
    ReconstructManyOptions, ReconstructManySummary, MIN_CONFIDENCE_PER_PAIR,
};
pub use reconstruct::rectify::{RectifyOptions, RectifySummary};
pub use reconstruct::select::{PairChoice, PairTerms, View};
pub use reconstruct::tile::{TileRecord, TileStatus};
pub use reconstruct::{ReconstructOptions, ReconstructSummary, ScenePlan};
#[cfg(feature = "network")]
pub use workflow::matcher::MonsterOptions;
pub use workflow::matcher::{Matched, Matcher, RangeSource};
pub use workflow::outputs::Incomplete;
pub use workflow::progress::track;
pub use workflow::{Progress, Silent};

pub mod bench;
pub mod benchmark;
pub mod defaults;
pub mod demo;
pub mod flags;
pub mod jobs;
pub mod outputs;
pub mod stages;
#[cfg(feature = "network")]
pub mod train;
pub mod world;

/// The plan of a reconstruction without running it: the tiles, the DSM grid, every tile's
/// estimated memory and the merge's. Nothing is written.
pub fn plan_reconstruct(options: &ReconstructOptions) -> Result<ScenePlan> {
    reconstruct::plan(options)
}

/// Submits a reconstruction to Slurm: an array of tile tasks sized by the plan and a merge that
/// runs after them (`afterany`), refusing to write a DSM while tiles are failed. The job scripts
/// and `jobs/slurm.json` go into the work folder.
pub fn submit_slurm_reconstruct(
    options: &ReconstructOptions,
    request: &SlurmRequest,
) -> Result<Submitted> {
    ::jobs::submit_reconstruct(options, request)
}

/// The tiles of the submission in `work`: done, failed (with their errors), missing.
pub fn job_status(work: &Path) -> Result<JobStatus> {
    ::jobs::status(work)
}

/// Submits again only the array tasks of `work` whose tiles failed or are missing, and a merge
/// after them; with `wait`, until the merge ends.
pub fn resubmit_slurm(work: &Path, wait: bool) -> Result<Submitted> {
    ::jobs::resubmit(work, wait)
}

/// Submits a chain of sharded stages to Slurm: one array job per stage, a check step after
/// each (`afterany`) that fails naming the failed shards, the next stage `afterok` on it with
/// `--kill-on-invalid-dep=yes`. Scripts, shard markers and `jobs/chain.json` go into the work
/// folder.
pub fn submit_slurm_chain(request: &ChainRequest) -> Result<ChainSubmitted> {
    ::jobs::submit_chain(request)
}

/// The shards of every stage of the chain in `work`: done, failed (exit code, log), missing.
pub fn chain_status(work: &Path) -> Result<ChainStatus> {
    ::jobs::chain_status(work)
}

/// Submits again the failed and missing shards of the chain's first unfinished stage and every
/// later stage; with `wait`, until the last stage ends.
pub fn resubmit_slurm_chain(work: &Path, wait: bool) -> Result<ChainSubmitted> {
    ::jobs::resubmit_chain(work, wait)
}

/// Rectifies a raw satellite pair from its RPC cameras (epipolar lines become rows) into the
/// pair folder `options.out_dir` (`L/`, `R/`, `homography/`, `rectify/`), and gives the disparity
/// search range that the scene's altitudes imply.
pub fn rectify(options: &RectifyOptions, progress: &dyn Progress) -> Result<RectifySummary> {
    reconstruct::rectify::rectify(options, progress)
}

/// Reads a rectified pair (NPY `.iio`/`.npy`, TIFF, PNG, PFM), checking that both sides have the
/// same size.
pub fn read_pair(left: &Path, right: &Path) -> Result<(Image, Image)> {
    workflow::predict::read_pair(left, right)
}

/// The disparity of the rectified pair `left`, `right` (NaN where invalid), by `matcher`: census +
/// MGM/SGM over the range `range` gives, or MonSter++ (which ignores the range).
pub fn predict(
    left: &Image,
    right: &Image,
    matcher: &Matcher,
    range: RangeSource,
    progress: &dyn Progress,
) -> Result<Matched> {
    matcher.disparity(left, right, range, progress)
}

/// Writes a disparity; the extension picks the format: `.iio`/`.npy`, `.tif`, `.pfm` keep the
/// values (NaN = invalid), `.png` writes a colour-mapped picture.
pub fn write_disparity(path: &Path, disparity: &Image) -> Result<()> {
    workflow::predict::write_disparity(path, disparity)
}

/// Turns the disparity of a rectified pair into a georeferenced DSM: RPC triangulation (s2p's
/// iteration), points gridded per cell, optional hole filling and median filter.
pub fn dsm(options: &DsmOptions) -> Result<DsmSummary> {
    reconstruct::dsm::disparity_to_dsm(options)
}

/// From a raw pair to a DSM at any scene size: tiles with collars, each rectified, matched,
/// triangulated and gridded on its own within a memory budget, merged on one UTM grid, filled,
/// filtered and written as a COG. Resumable and shardable through the work folder.
pub fn reconstruct(
    options: &ReconstructOptions,
    progress: &dyn Progress,
) -> Result<ReconstructSummary> {
    reconstruct::reconstruct(options, progress)
}

/// Many acquisitions of one area → one DSM: the best pairs by date gap, convergence, incidence
/// and sun angles (`options.pairs` of them), each through [`reconstruct`](fn@reconstruct) without hole filling on
/// one common grid, fused cell by cell (strongest height cluster, its median), holes filled only
/// where no pair measured or too few agreed; writes the DSM, `<stem>_count.tif`, `<stem>_spread.tif` and
/// `<stem>_report.json`. With `options.dry_run` it only chooses the pairs. A pair that fails is
/// recorded in the summary ([`PairStatus`]), not returned as an error; bad input is refused
/// before any work.
pub fn reconstruct_many(
    options: &ReconstructManyOptions,
    progress: &dyn Progress,
) -> Result<ReconstructManySummary> {
    reconstruct::many::reconstruct_many(options, progress)
}

/// Reads a ground truth `<AOI>_DSM.tif` (GeoTIFF, or DFC2019 plain TIFF + `<AOI>_DSM.txt` in
/// UTM `zone`) with its `<AOI>_CLS.tif` and optional `<AOI>_WATER.png` beside it.
pub fn read_truth(dsm: &Path, zone: UtmZone) -> Result<Truth> {
    eval::score::read_truth(dsm, zone)
}

/// The benchmark's metric on a DSM (on the truth's grid, or on its own and cut onto the truth's
/// as the benchmark crops: nearest cell, NaN outside): the integer shift within ±5
/// cells that maximises NCC, the vertical offset, MAE over the cells both have (raw, without
/// water, without foliage and water) and the truth's coverage.
pub fn score(dsm: &Path, truth: &Truth) -> Result<DsmScores> {
    eval::score::score_dsm_file(dsm, truth)
}

/// Two DSMs ("ours" and another method's, e.g. s2p's; each cut onto the truth's grid as in
/// [`score`]) scored by the
/// benchmark's metric, each registered on its own, then compared cell by cell: the MAE of each
/// on the truth cells both cover, the MAE of the cells only one covers, and each one's coverage
/// and share of truth cells within 1 m and 2 m. Two MAEs over different cells do not rank two
/// methods (holes fall where matching is hard); these do.
pub fn score_against(dsm: &Path, other: &Path, truth: &Truth) -> Result<Versus> {
    eval::score::score_versus_files(dsm, other, truth)
}

/// Altitude MAE of the DSMs from the disparities of one or more splits, exactly as the
/// benchmark's code computes it; resumable (pairs already in the CSV are skipped) and writing
/// the paper's Table 1.
pub fn eval(options: &EvalOptions, progress: &dyn Progress) -> Result<EvalReport> {
    eval::evaluate(options, progress)
}

/// An error as one line, each cause once (a context already contained in its cause left out):
/// what the command line prints after `error: `, and the text of the Python package's exceptions.
pub fn error_line(e: &Error) -> String {
    workflow::outputs::one_line(e)
}

/// The kind of the file-system failure behind `e` (a missing file, a denied permission), when
/// one caused it: the readers keep the [`std::io::Error`] inside their own error types (its text
/// already in their message), and the Python package picks `FileNotFoundError`,
/// `PermissionError`, ... from it.
pub fn io_error_kind(e: &Error) -> Option<std::io::ErrorKind> {
    e.chain().find_map(|cause| {
        if let Some(io) = cause.downcast_ref::<std::io::Error>() {
            return Some(io.kind());
        }
        let raster = match cause.downcast_ref::<camera::CameraError>() {
            Some(camera::CameraError::Raster(r)) => Some(r),
            _ => cause.downcast_ref::<raster::RasterError>(),
        };
        match raster {
            Some(raster::RasterError::Io { error, .. }) => Some(error.kind()),
            _ => None,
        }
    })
}

/// Runs `work` on `threads` worker threads of its own (all the cores' shared pool when `None`):
/// a caller that runs several calls at once (Python threads, a job scheduler) gives each its
/// share of the cores instead of queueing them all on the one shared pool.
pub fn with_threads<T: Send>(
    threads: Option<usize>,
    work: impl FnOnce() -> Result<T> + Send,
) -> Result<T> {
    let Some(n) = threads else {
        return work();
    };
    if n == 0 {
        anyhow::bail!("threads must be at least 1 (got 0)");
    }
    rayon::ThreadPoolBuilder::new()
        .num_threads(n)
        .build()?
        .install(work)
}

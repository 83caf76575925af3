//! What to reconstruct and how: the options of [`super::reconstruct`], in a file of their own so
//! that the checks before work (`sanity`) read them without importing the job.

use std::path::{Path, PathBuf};

use camera::rectify::Roi;
use dataset::shard::Shard;
use serde_json::json;

use crate::dsm::GridChoice;
use crate::finishing::Finishing;
use crate::provenance::{delivery_files, grid_input, grid_json, InputFile, Product, RunRecord};
use workflow::matcher::Matcher;
use workflow::outputs::resolve;

/// Tile side, left raw pixels: an affine rectification holds over about a kilometre.
pub const DEFAULT_TILE: usize = 1024;
/// Overlap collar around each tile, pixels.
pub const DEFAULT_COLLAR: usize = 64;
/// Memory budget of a run, GiB.
pub const DEFAULT_MEMORY_GIB: f64 = 2.0;

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
    /// How the merged cells become the DSM: gridding, hole filling, median filter.
    pub finishing: Finishing,
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
    /// Measure the tiles of very narrow baselines from both views and keep the cells they agree
    /// on ([`super::both_views`]); `false` matches from the left view only
    /// (`--single-view`; `reconstruct-many` passes its own choice to each pair).
    pub both_views: bool,
    /// Shear the right rectified image so that one ground altitude has one disparity over a
    /// tile ([`camera::rectify::Shear::Level`]): the search covers the altitude range alone. It
    /// won in every bin of the dev pairs, and `reconstruct-many`'s pairs keep it (BENCHMARKS.md,
    /// "The right image sheared to level the ground").
    pub level_ground: bool,
    /// Correct the relative pointing error of the pair from tie points (the right camera
    /// translated; [`super::pointing`]) and take the scene's altitudes from them when
    /// `alt_range` gives none; cameras that both carry the scene's altitudes (curated JSONs) are
    /// used as given. `reconstruct-many` turns it off for its pairs, whose cameras it has
    /// adjusted all together.
    pub adjust_pointing: bool,
    /// The products written beside the DSM (orthoimage, point cloud, quicklook); none by
    /// default.
    pub products: products::Products,
}

impl ReconstructOptions {
    /// The record of this run in its work folder ([`crate::provenance`]; also each pair's of
    /// `reconstruct-many`).
    pub fn run_record(&self) -> RunRecord {
        let o = self;
        let mut inputs = vec![
            InputFile::of("left", &o.left),
            InputFile::of("right", &o.right),
        ];
        let optional = [
            ("rpc_left", o.rpc_left.as_deref()),
            ("rpc_right", o.rpc_right.as_deref()),
            ("like", grid_input(&o.grid)),
            ("truth", o.truth.as_deref()),
        ];
        for (role, path) in optional {
            inputs.extend(path.map(|p| InputFile::of(role, p)));
        }
        inputs.extend(delivery_files(&o.left).chain(delivery_files(&o.right)));
        RunRecord {
            command: "reconstruct".into(),
            inputs,
            work: json!({
                "roi": o.roi,
                "roi_lonlat": o.roi_lonlat,
                "alt_range": o.alt_range,
                "matcher": { "kind": o.matcher.kind(), "settings": o.matcher.settings() },
                "grid": grid_json(&o.grid),
                "gridding": format!("{:?}", o.finishing.gridding),
                "border": o.border,
                "tile": o.tile,
                "collar": o.collar,
                "both_views": o.both_views,
                "level_ground": o.level_ground,
                "adjust_pointing": o.adjust_pointing,
            }),
            product: Product {
                output: resolve(&o.output),
                finishing: o.finishing.record(),
            },
        }
    }

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
            finishing: Finishing::default(),
            border: 0,
            truth: None,
            tile: DEFAULT_TILE,
            collar: DEFAULT_COLLAR,
            max_memory: (DEFAULT_MEMORY_GIB * (1u64 << 30) as f64) as u64,
            shard: Shard::ALL,
            merge_only: false,
            tiles_only: false,
            complete_only: false,
            keep_intermediates: false,
            both_views: true,
            level_ground: true,
            adjust_pointing: true,
            products: Default::default(),
        }
    }

    /// The scores need the truth's grid: `truth` must be the DSM whose grid is used (`Like`).
    pub fn check_truth(&self) -> anyhow::Result<()> {
        let Some(truth) = &self.truth else {
            return Ok(());
        };
        match &self.grid {
            GridChoice::Like(like) if like == truth => Ok(()),
            _ => anyhow::bail!(
                "--truth {} must be the DSM given to --like (the scores need its grid)",
                truth.display()
            ),
        }
    }

    /// The work folder: `work_dir`, else beside the output.
    pub fn work(&self) -> std::path::PathBuf {
        self.work_dir
            .clone()
            .unwrap_or_else(|| default_work_dir(&self.output))
    }

    /// Refuses, before any work, an output DSM that is not a GeoTIFF, that (or one of its
    /// sidecars) is one of the inputs, or that exists unless `overwrite` or it is the product
    /// of an earlier run of this same run in its work folder ([`crate::provenance`]: another
    /// run's folder is refused, or cleared with `overwrite`). The rule of every caller (command
    /// line, Python).
    pub fn check_output(&self, overwrite: bool) -> anyhow::Result<()> {
        // A wrong command line is said before what it would write.
        self.check_truth()?;
        let like = match &self.grid {
            GridChoice::Like(p) => Some(p),
            _ => None,
        };
        let inputs = [
            Some(&self.left),
            Some(&self.right),
            self.rpc_left.as_ref(),
            self.rpc_right.as_ref(),
            like,
            self.truth.as_ref(),
        ];
        let inputs: Vec<&std::path::Path> =
            inputs.into_iter().flatten().map(|p| p.as_path()).collect();
        let mut outputs = vec![self.output.clone()];
        outputs.extend(crate::dsm::sidecars(&self.output));
        for (i, out) in outputs.iter().enumerate() {
            let flag = if i == 0 { "-o" } else { "-o (its sidecar)" };
            workflow::outputs::check_output_file(flag, out, &inputs, true)?;
        }
        workflow::outputs::check_dsm_extension("-o", &self.output)?;
        workflow::outputs::check_products(&self.products, &self.output, &inputs, &mut outputs)?;
        let run = self.run_record();
        crate::provenance::check(&self.work(), &run, &outputs, &inputs, overwrite)
    }

    /// How the cameras are named in messages: the JSON files, or the images' RPC tags.
    pub fn camera_names(&self) -> [String; 2] {
        let name = |rpc: &Option<PathBuf>, image: &PathBuf| match rpc {
            Some(p) => p.display().to_string(),
            None => format!("the RPC tag of {}", image.display()),
        };
        [
            name(&self.rpc_left, &self.left),
            name(&self.rpc_right, &self.right),
        ]
    }
}

/// The default work folder of an output DSM: `out/dsm.tif` → `out/dsm_work`.
pub fn default_work_dir(output: &Path) -> PathBuf {
    crate::dsm::sidecar_path(output, "_work")
}

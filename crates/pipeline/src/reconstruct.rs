//! From a raw satellite pair to a DSM in one call: rectify from the RPCs, match with the
//! disparity range implied by the cameras and the scene's altitudes, triangulate, grid.
//!
//! The intermediate files stay beside the output (`<work>/L`, `R`, `homography`, `rectify`,
//! `disparity`, in the layout `eval` reads), so every step can be inspected or rerun on its own
//! with `rectify`, `predict` and `dsm`.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use camera::rectify::Roi;
use camera::{Gridding, UtmZone};
use matching::SgmParams;

use crate::dsm::{disparity_to_dsm, DsmOptions, DsmSummary, GridChoice};
use crate::eval::metrics::DsmScores;
use crate::predict::{predict_monster, predict_sgm, read_pair, write_disparity, MonsterOptions};
use crate::progress::Progress;
use crate::rectify::{rectify, RectifyOptions, RectifySummary};

/// The matcher of a reconstruction.
#[derive(Clone, Debug)]
pub enum Matcher {
    /// Census + MGM/SGM over the range from the cameras.
    Classical(SgmParams),
    /// MonSter++ with weights (no range needed).
    Network(MonsterOptions),
}

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
    /// Scene altitudes, metres (else from the JSON or the RPCs).
    pub alt_range: Option<(f64, f64)>,
    pub matcher: Matcher,
    /// Output DSM GeoTIFF.
    pub output: PathBuf,
    /// Folder of the intermediate files; `<output without extension>_work` when `None`.
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
}

/// What [`reconstruct`] did.
#[derive(Clone, Debug)]
pub struct ReconstructSummary {
    pub rectified: RectifySummary,
    pub disparity: PathBuf,
    /// Share of the rectified left pixels with a disparity.
    pub matched: f64,
    pub dsm: DsmSummary,
    /// Benchmark scores against the truth, when one was given.
    pub scores: Option<DsmScores>,
    /// Wall time of each step, seconds.
    pub seconds: Vec<(&'static str, f64)>,
}

/// The default work folder of an output DSM: `out/dsm.tif` → `out/dsm_work`.
pub fn default_work_dir(output: &Path) -> PathBuf {
    let stem = output
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "dsm".into());
    output.with_file_name(format!("{stem}_work"))
}

/// Runs rectify → match → DSM (→ score).
pub fn reconstruct(
    opts: &ReconstructOptions,
    progress: &dyn Progress,
) -> Result<ReconstructSummary> {
    let work = opts
        .work_dir
        .clone()
        .unwrap_or_else(|| default_work_dir(&opts.output));
    let mut seconds = Vec::new();
    let t = Instant::now();
    let rectified = rectify(
        &RectifyOptions {
            left: opts.left.clone(),
            right: opts.right.clone(),
            out_dir: work.clone(),
            roi: opts.roi,
            rpc_left: opts.rpc_left.clone(),
            rpc_right: opts.rpc_right.clone(),
            alt_range: opts.alt_range,
            stem: None,
        },
        progress,
    )?;
    seconds.push(("rectify", t.elapsed().as_secs_f64()));

    let t = Instant::now();
    let (left, right) = read_pair(&rectified.left, &rectified.right)?;
    let disparity = match &opts.matcher {
        Matcher::Classical(params) => {
            predict_sgm(
                &left,
                &right,
                Some(rectified.disparity_range),
                params,
                progress,
            )?
            .0
        }
        Matcher::Network(o) => predict_monster(&o.load()?, &left, &right, progress)?,
    };
    drop((left, right));
    let disparity_path = work
        .join("disparity")
        .join(format!("{}.iio", rectified.stem));
    write_disparity(&disparity_path, &disparity)
        .with_context(|| format!("writing {}", disparity_path.display()))?;
    let matched = disparity.data().iter().filter(|v| v.is_finite()).count() as f64
        / disparity.data().len().max(1) as f64;
    seconds.push(("match", t.elapsed().as_secs_f64()));

    let t = Instant::now();
    let rpc = |json: &Option<PathBuf>, image: &Path| json.clone().unwrap_or(image.to_path_buf());
    let dsm = disparity_to_dsm(&DsmOptions {
        disparity: disparity_path.clone(),
        homography: rectified.homography.clone(),
        rpc_left: rpc(&opts.rpc_left, &opts.left),
        rpc_right: rpc(&opts.rpc_right, &opts.right),
        grid: opts.grid.clone(),
        border: opts.border,
        gridding: opts.gridding,
        fill_holes: opts.fill_holes,
        median_filter: opts.median_filter,
        output: opts.output.clone(),
        compare: None,
    })?;
    seconds.push(("dsm", t.elapsed().as_secs_f64()));

    let scores = match &opts.truth {
        Some(truth) => {
            let zone = UtmZone::from_epsg(dsm.grid.epsg)?;
            let truth = crate::score::read_truth(truth, zone)?;
            Some(crate::score::score_dsm_file(&opts.output, &truth)?)
        }
        None => None,
    };
    Ok(ReconstructSummary {
        rectified,
        disparity: disparity_path,
        matched,
        dsm,
        scores,
        seconds,
    })
}

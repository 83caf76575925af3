//! Many dates, one DSM: every acquisition of an area → the best pairs by metadata and geometry
//! ([`super::select`]) → each pair through the tiled [`super::reconstruct`] on one common grid,
//! without hole filling (the fusion uses measured cells only) → the pairs' DSMs fused cell by
//! cell ([`super::fuse`]) → holes filled where no cluster had enough agreeing pairs, median filter, the COG.
//!
//! Files, for `-o OUT/dsm.tif` (work folder `OUT/dsm_work` unless `work_dir` is given):
//!
//! ```text
//! OUT/dsm.tif                 fused DSM (float32 COG, NaN where nothing measured nor filled)
//! OUT/dsm_count.tif           pairs that measured each cell
//! OUT/dsm_spread.tif          median absolute deviation of the kept cluster, metres; NaN where
//!                             no cluster was kept (the height there, if any, is filled)
//! OUT/dsm_confidence.tif      summed matcher confidence of the kept cluster's pairs (each in
//!                             [0, 1]; 1 a pair when the matcher gives none); NaN where none
//! OUT/dsm_report.json         chosen pairs and their score terms, per-pair coverage (and scores),
//!                             fused coverage (and scores), times
//! OUT/dsm_work/pairs/<pair>.tif       the pair's DSM, measured cells only
//! OUT/dsm_work/pairs/<pair>_confidence.tif   the matcher's confidence of its cells
//! OUT/dsm_work/pairs/<pair>_work/     the pair's tiles (resumable: a rerun redoes only
//!                                     unfinished tiles of unfinished pairs)
//! ```
//!
//! Bad input is refused before any work: fewer than two images, one image given twice (same
//! file or identical pixels), a missing camera JSON, an image that overlaps no other, an output
//! that is one of the inputs.

use std::collections::hash_map::DefaultHasher;
use std::hash::{Hash, Hasher};
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use camera::rectify::Roi;
use camera::{write_dsm, write_grid_raster, Crs, DsmGrid, Gridding, UtmZone};
use dataset::shard::Shard;
use raster::Image;
use serde::Serialize;
use serde_json::json;

use super::fuse::{fuse_files, pair_weight, Agreement, Fused, FusionParams, Layer, Shift};
use super::raw::RawImage;
use super::select::{
    choose_pairs, json_metadata, parse_day, rank_pairs, Acquisition, PairChoice, View,
};
use super::tile::TileStatus;
use super::{footprint, reconstruct, score_against_truth, ReconstructOptions};
use crate::dsm::{bands, GridChoice};
use crate::finishing::{Finishing, DEFAULT_FILL_CELLS, FUSED_MEDIAN_CELLS};
use crate::provenance::{delivery_files, grid_input, grid_json, InputFile, Product, RunRecord};
use crate::rectify::{altitude_range, camera_of, file_stem};
use eval::align::{align, AlignParams};
use eval::metrics::DsmScores;
use workflow::matcher::Matcher;
use workflow::outputs::{check_output_file, check_output_folder, resolve};
use workflow::progress::{Progress, Sequence};
use workflow::stage::write_json;

/// What to reconstruct from many acquisitions, and how.
#[derive(Clone, Debug)]
pub struct ReconstructManyOptions {
    /// The raw images (two or more).
    pub images: Vec<PathBuf>,
    /// Folder of the cameras, `<image stem>.json` each (else the images' RPC tags).
    pub rpc_dir: Option<PathBuf>,
    /// Output DSM; the count, spread and report files are named after it.
    pub output: PathBuf,
    /// Folder of the pairs' DSMs and tiles; `<output without extension>_work` when `None`.
    pub work_dir: Option<PathBuf>,
    /// The grid of every pair and of the fused DSM. `Resolution` without bounds: the union of
    /// the chosen pairs' overlaps.
    pub grid: GridChoice,
    /// How many pairs to reconstruct (the best by score).
    pub pairs: usize,
    /// Choose and describe the pairs, reconstruct nothing.
    pub dry_run: bool,
    /// Heights of one cell further apart than this, metres, are different surfaces
    /// ([`FusionParams::tolerance`]).
    pub cluster_tolerance: f32,
    /// Fewest pairs that must agree for a cell to keep a measured height; `None`: 1 when the
    /// confidence rule applies, else [`auto_min_support`] of the pairs fused.
    pub min_support: Option<usize>,
    /// Least summed confidence of the agreeing pairs for a cell to keep a measured height, when
    /// every pair has a confidence (the classical matcher); `None`: [`auto_min_confidence`] of
    /// the pairs fused; 0 turns the rule off.
    pub min_confidence: Option<f32>,
    /// Register every pair's DSM on the first pair's (NCC shift, vertical offset) before fusing.
    pub co_register: bool,
    /// Weight each pair by its agreement with a first, equal-weight fusion ([`pair_weight`]);
    /// false (the default) keeps that equal-weight fusion.
    pub weight_pairs: bool,
    /// How the fused DSM is finished (only cells without a fused height are filled); its
    /// gridding is also each pair's.
    pub finishing: Finishing,
    /// Median filter of each pair's DSM before fusion, cells (odd); it never fills a cell.
    pub pair_median_filter: Option<usize>,
    /// Measure each pair's very narrow tiles from both views ([`super::both_views`]).
    pub both_views: bool,
    /// Ground truth to score the fused DSM and every pair's against (`grid` = `Like` it).
    pub truth: Option<PathBuf>,
    /// Scene altitudes, metres (else from the JSONs or the RPCs).
    pub alt_range: Option<(f64, f64)>,
    pub matcher: Matcher,
    /// Tiles of each pair: side and collar, pixels.
    pub tile: usize,
    pub collar: usize,
    /// Memory budget of the process, bytes (each pair's tiles, then the fusion).
    pub max_memory: u64,
    /// This process's share of every pair's tiles (array jobs sharing `work_dir`): a sharded
    /// run only runs its tiles ([`shard_of_pair`]); the run without a shard (`Shard::ALL`)
    /// assembles the pairs and fuses them.
    pub shard: Shard,
    /// Replace an existing DSM, count, spread or report (atomically), and clear a work folder of
    /// another run. A rerun of the same run ([`crate::provenance`]) replaces them without it.
    pub overwrite: bool,
    /// Adjust every camera's pointing at once from tie points ([`super::pointing`]) and take
    /// the scene's altitudes from them when `alt_range` gives none; the corrected cameras are
    /// written under the work folder (`cameras/<image stem>.json`) and the pairs use them.
    /// Cameras that all carry the scene's altitudes (curated JSONs) are used as given
    /// ([`super::pointing::needs_adjustment`]).
    pub adjust_pointing: bool,
    /// The products written beside the fused DSM (orthoimage from every view, point cloud,
    /// quicklook); none by default.
    pub products: products::Products,
}

/// Default number of pairs.
pub const DEFAULT_PAIRS: usize = 12;

/// The confidence a kept cluster needs per pair fused ([`auto_min_confidence`]).
pub const MIN_CONFIDENCE_PER_PAIR: f32 = 0.1;

/// The default least summed confidence of a kept cluster in a fusion of `pairs` DSMs: 0.1 a
/// pair (1.2 for 12: about two pairs at the median confidence of the dev pairs, or three
/// hesitant ones). More pairs mean more chance agreements, as for the count rule. Against that
/// rule it did better at every number of pairs tried, on the ten dev images and on the six-date
/// world at both sizes, and kept the fused DSM's quality nearly independent of the number of
/// pairs; a fixed sum is not right for every count (too strict for few pairs on the world)
/// (BENCHMARKS.md, "Many dates, one DSM", "Confidence-weighted fusion").
pub fn auto_min_confidence(pairs: usize) -> f32 {
    MIN_CONFIDENCE_PER_PAIR * pairs as f32
}

impl ReconstructManyOptions {
    /// The record of this run in its work folder ([`crate::provenance`]).
    pub fn run_record(&self) -> RunRecord {
        let o = self;
        let mut inputs: Vec<InputFile> = Vec::new();
        for image in &o.images {
            inputs.push(InputFile::of("image", image));
            let camera = o.rpc_dir.as_ref().and_then(|dir| {
                let stem = image.file_stem()?;
                Some(dir.join(format!("{}.json", stem.to_string_lossy())))
            });
            inputs.extend(camera.map(|c| InputFile::of("camera", &c)));
            inputs.extend(delivery_files(image));
        }
        inputs.extend(grid_input(&o.grid).map(|p| InputFile::of("like", p)));
        inputs.extend(o.truth.as_deref().map(|p| InputFile::of("truth", p)));
        RunRecord {
            command: "reconstruct-many".into(),
            inputs,
            work: json!({
                "grid": grid_json(&o.grid),
                "pairs": o.pairs,
                "pair_median_filter": o.pair_median_filter,
                "both_views": o.both_views,
                "alt_range": o.alt_range,
                "adjust_pointing": o.adjust_pointing,
                "matcher": { "kind": o.matcher.kind(), "settings": o.matcher.settings() },
                "gridding": format!("{:?}", o.finishing.gridding),
                "tile": o.tile,
                "collar": o.collar,
            }),
            product: Product {
                output: resolve(&o.output),
                finishing: json!({
                    "cluster_tolerance": o.cluster_tolerance,
                    "min_support": o.min_support,
                    "min_confidence": o.min_confidence,
                    "co_register": o.co_register,
                    "weight_pairs": o.weight_pairs,
                    "fill_holes": o.finishing.fill_holes.map(|f| f.span),
                    "median_filter": o.finishing.median_filter,
                }),
            },
        }
    }

    /// The defaults: the best 12 pairs, 0.5 m clusters, agreement by [`auto_min_confidence`]
    /// (else [`auto_min_support`]), no co-registration, equal weights, fill 40 cells, 7×7
    /// median.
    pub fn new(
        images: Vec<PathBuf>,
        rpc_dir: Option<PathBuf>,
        matcher: Matcher,
        grid: GridChoice,
        output: PathBuf,
    ) -> Self {
        ReconstructManyOptions {
            images,
            rpc_dir,
            output,
            work_dir: None,
            grid,
            pairs: DEFAULT_PAIRS,
            dry_run: false,
            cluster_tolerance: FusionParams::default().tolerance,
            min_support: None,
            min_confidence: None,
            co_register: false,
            weight_pairs: false,
            finishing: Finishing::new(
                Gridding::Median,
                Some(DEFAULT_FILL_CELLS),
                None,
                Some(FUSED_MEDIAN_CELLS),
            ),
            pair_median_filter: None,
            both_views: true,
            truth: None,
            alt_range: None,
            matcher,
            tile: 1024,
            collar: 64,
            max_memory: 2 << 30,
            shard: Shard::ALL,
            overwrite: false,
            adjust_pointing: true,
            products: Default::default(),
        }
    }

    /// The folder of the pairs' DSMs and tiles.
    pub fn work_dir(&self) -> PathBuf {
        self.work_dir
            .clone()
            .unwrap_or_else(|| super::default_work_dir(&self.output))
    }

    /// `<output stem><suffix>` beside the output.
    pub fn sibling(&self, suffix: &str) -> PathBuf {
        crate::dsm::sidecar_path(&self.output, suffix)
    }
}

/// How a pair's reconstruction ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum PairStatus {
    /// Every tile finished.
    Done,
    /// A DSM, but some tiles failed (named in `failed_tiles`).
    Partial,
    /// No DSM, or one without a measured cell.
    Failed,
    /// A sharded run's tiles of the pair finished; the run without a shard assembles it.
    Tiles,
}

impl PairStatus {
    /// The status as the messages say it.
    pub fn word(self) -> &'static str {
        match self {
            PairStatus::Done => "done",
            PairStatus::Partial => "partial (tiles failed)",
            PairStatus::Failed => "FAILED",
            PairStatus::Tiles => "this shard's tiles done",
        }
    }
}

/// One pair's outcome.
#[derive(Clone, Debug, Serialize)]
pub struct PairOutcome {
    pub stem: String,
    pub status: PairStatus,
    pub dsm: PathBuf,
    pub error: Option<String>,
    pub failed_tiles: Vec<String>,
    /// Cells of the grid the pair measured, and their share of the grid.
    pub measured_cells: usize,
    pub measured_share: f64,
    /// Scores of the pair's (unfilled) DSM against the truth.
    pub scores: Option<DsmScores>,
    /// How the pair's DSM was moved onto the reference pair's before fusion.
    pub registration: Option<Shift>,
    /// How often the pair agreed with the equal-weight fusion, and its weight in the fusion
    /// that was kept.
    pub agreement: Option<Agreement>,
    pub weight: Option<f32>,
    pub seconds: f64,
}

/// The fused DSM's files and cells.
#[derive(Clone, Debug, Serialize)]
pub struct FusedOutcome {
    pub dsm: PathBuf,
    pub count: PathBuf,
    pub spread: PathBuf,
    pub confidence: PathBuf,
    /// Pairs fused.
    pub pairs: usize,
    pub grid: DsmGrid,
    /// Cells with a fused height, cells with a height after filling.
    pub measured_cells: usize,
    pub filled_cells: usize,
    pub seconds: f64,
}

/// What [`reconstruct_many`] did (also written as the report).
#[derive(Clone, Debug, Serialize)]
pub struct ReconstructManySummary {
    pub views: Vec<View>,
    /// The bundle adjustment of the cameras, when run.
    pub pointing: Option<super::pointing::Pointing>,
    /// Overlapping pairs considered.
    pub candidates: usize,
    pub chosen: Vec<PairChoice>,
    pub pairs: Vec<PairOutcome>,
    /// The fusion's parameters as used.
    pub fusion: Option<FusionParams>,
    pub fused: Option<FusedOutcome>,
    pub scores: Option<DsmScores>,
    pub work: PathBuf,
    pub report: Option<PathBuf>,
    /// `i/n` of a sharded run (its tiles only); `None` for the run that fuses.
    pub shard: Option<String>,
    /// The products written beside the fused DSM, when asked for.
    pub products: Option<products::ProductsWritten>,
    pub seconds: f64,
}

impl ReconstructManySummary {
    /// Stems of the pairs that failed or lost tiles.
    pub fn incomplete_pairs(&self) -> Vec<&PairOutcome> {
        self.pairs
            .iter()
            .filter(|p| !matches!(p.status, PairStatus::Done | PairStatus::Tiles))
            .collect()
    }

    /// One warning per pair that failed or lost tiles, with its cause: what the command line
    /// prints and the Python package issues, so both say the same.
    pub fn warnings(&self) -> Vec<String> {
        self.incomplete_pairs()
            .iter()
            .map(|p| {
                let why = p
                    .error
                    .clone()
                    .unwrap_or_else(|| format!("tiles {} failed", p.failed_tiles.join(", ")));
                let status = p.status.word();
                format!(
                    "pair {} {status}: {why} (rerun the same command after fixing it: finished \
                     pairs and tiles are kept)",
                    p.stem
                )
            })
            .collect()
    }

    /// [`workflow::outputs::Incomplete::Nothing`] when pairs ran and none produced a DSM (a dry
    /// run produces nothing by design and passes): every caller ends such a run as a failure.
    pub fn check_produced(&self) -> Result<()> {
        if self.pairs.is_empty() || self.fused.is_some() || self.shard.is_some() {
            return Ok(());
        }
        Err(workflow::outputs::Incomplete::Nothing {
            message: "no pair produced a DSM: no DSM, count, spread or report written".into(),
        }
        .into())
    }
}

/// Chooses the pairs, reconstructs each, fuses them and writes the DSM, its count and spread
/// rasters and the report. With `dry_run`, only chooses. The steps: `plan` (inputs checked,
/// pairs chosen, grid), `run_pairs`, `fuse_pairs`, the report.
pub fn reconstruct_many(
    opts: &ReconstructManyOptions,
    progress: &dyn Progress,
) -> Result<ReconstructManySummary> {
    let start = Instant::now();
    progress.begin("selecting pairs", 1);
    let (mut summary, grids) = plan(opts, progress)?;
    progress.advance(1);
    progress.end();
    if opts.dry_run {
        return Ok(summary);
    }
    let rows = fusion_rows(&grids.fused, summary.chosen.len(), opts.max_memory)?;
    crate::provenance::claim(&summary.work, &opts.run_record())?;
    run_pairs(opts, &mut summary, &grids, progress);
    if opts.shard != Shard::ALL {
        summary.shard = Some(format!("{}/{}", opts.shard.index, opts.shard.count));
        summary.seconds = start.elapsed().as_secs_f64();
        return Ok(summary);
    }
    fuse_pairs(opts, &mut summary, &grids.fused, rows, progress)?;
    if summary.fused.is_some() {
        let views: Vec<_> = summary
            .views
            .iter()
            .map(|v| (v.image.as_path(), &v.rpc))
            .collect();
        summary.products = workflow::finished::write_products(
            &opts.products,
            &opts.output,
            &grids.fused,
            &views,
            (&opts.sibling("_count.tif"), products::MeasuredFrom::Count),
            progress,
        )?;
    }
    summary.seconds = start.elapsed().as_secs_f64();
    if summary.fused.is_some() {
        let report = opts.sibling("_report.json");
        write_json(&report, &summary)?;
        summary.report = Some(report);
    }
    Ok(summary)
}

/// The fused grid, and the choice that gives every pair exactly that grid.
struct Grids {
    fused: DsmGrid,
    pairs: GridChoice,
}

/// Everything decided before any work: the inputs checked, the views, the chosen pairs and the
/// grid.
fn plan(
    opts: &ReconstructManyOptions,
    progress: &dyn Progress,
) -> Result<(ReconstructManySummary, Grids)> {
    check_outputs(opts)?;
    let zone = scene_zone(opts)?;
    let mut views = open_views(opts, zone, progress)?;
    check_distinct(&views)?;
    check_overlaps(&views)?;
    let adjust = super::pointing::needs_adjustment(views.iter().map(|v| &v.rpc));
    let pointing = if opts.adjust_pointing && adjust && !opts.dry_run {
        // The adjusted cameras are the work folder's first content: it is this run's from now.
        crate::provenance::claim(&opts.work_dir(), &opts.run_record())?;
        match adjust_cameras(opts, &mut views, zone, progress) {
            Ok(p) => Some(p),
            // Cameras that carry the scene's altitudes can go on as given, said loudly.
            Err(e)
                if !e.is::<super::pointing::Misfit>() && given_range(opts, &views)?.is_some() =>
            {
                progress.note(&format!(
                    "warning: the cameras' pointing was not corrected ({}); they are used as given",
                    workflow::outputs::one_line(&e)
                ));
                None
            }
            Err(e) if e.is::<super::pointing::Misfit>() => return Err(e),
            Err(e) => {
                return Err(e.context(
                    "the scene's altitudes could not be found from tie points: give them with \
                     --alt-range MIN:MAX",
                ))
            }
        }
    } else {
        None
    };
    let alt = middle_altitude(opts, &views)?;
    let ranked = rank_pairs(&views, zone, alt)?;
    let chosen = choose_pairs(&ranked, opts.pairs)?;
    progress.note(&format!(
        "chosen {} of {} overlapping pairs: {}",
        chosen.len(),
        ranked.len(),
        chosen
            .iter()
            .map(|p| p.stem.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    ));
    let (fused, pairs) = common_grid(opts, &chosen, zone)?;
    let work = opts.work_dir();
    let summary = ReconstructManySummary {
        views,
        pointing,
        candidates: ranked.len(),
        chosen,
        pairs: Vec::new(),
        fusion: None,
        fused: None,
        scores: None,
        work,
        report: None,
        shard: None,
        products: None,
        seconds: 0.0,
    };
    Ok((summary, Grids { fused, pairs }))
}

/// Runs every chosen pair through the tiled reconstruction, one after the other; a failing pair
/// is recorded and the others go on.
fn run_pairs(
    opts: &ReconstructManyOptions,
    summary: &mut ReconstructManySummary,
    grids: &Grids,
    progress: &dyn Progress,
) {
    let shown = Sequence::new(progress, "matching pair", summary.chosen.len());
    for (k, pair) in summary.chosen.iter().enumerate() {
        shown.enter(k);
        let mut pair_opts = pair_options(opts, &summary.views, pair, &grids.pairs, &summary.work);
        if opts.shard != Shard::ALL {
            pair_opts.shard = shard_of_pair(opts.shard, k);
            pair_opts.tiles_only = true;
        }
        let outcome = run_pair(&pair_opts, &grids.fused, &pair.stem, &shown);
        shown.note(&finished_pair_line(k, summary.chosen.len(), &outcome));
        summary.pairs.push(outcome);
    }
}

/// What the log says of a pair when it finishes (the run's summary says more at the end).
fn finished_pair_line(k: usize, n: usize, p: &PairOutcome) -> String {
    let scores = p
        .scores
        .as_ref()
        .and_then(|s| s.mae_filtered)
        .map_or(String::new(), |m| format!(", MAE {m:.3} m vs truth"));
    let why = p
        .error
        .as_deref()
        .map_or(String::new(), |e| format!(": {e}"));
    format!(
        "pair {}/{n} {} {}: {:.1} % of the grid measured{scores}, {:.1} s{why}",
        k + 1,
        p.stem,
        p.status.word(),
        100.0 * p.measured_share,
        p.seconds
    )
}

/// Fuses the DSMs of the pairs that produced one (registered on the first when asked), writes
/// the fused files and scores them; nothing when no pair produced a DSM.
fn fuse_pairs(
    opts: &ReconstructManyOptions,
    summary: &mut ReconstructManySummary,
    grid: &DsmGrid,
    rows: usize,
    progress: &dyn Progress,
) -> Result<()> {
    let t = Instant::now();
    let fusable: Vec<usize> = (0..summary.pairs.len())
        .filter(|&i| summary.pairs[i].status != PairStatus::Failed)
        .collect();
    let Some(&first) = fusable.first() else {
        return Ok(());
    };
    let reference = summary.pairs[first].dsm.clone();
    let mut layers = Vec::with_capacity(fusable.len());
    for &i in &fusable {
        let p = &mut summary.pairs[i];
        let shift = if opts.co_register {
            co_register(&reference, &p.dsm, grid)?
        } else {
            Shift::default()
        };
        p.registration = Some(shift);
        let confidence = crate::dsm::confidence_path(&p.dsm);
        layers.push(Layer {
            dsm: p.dsm.clone(),
            confidence: confidence.is_file().then_some(confidence),
            shift,
        });
    }
    // `fuse_files` uses the confidences only when every layer has one (a layer without would
    // weigh 1 and be favoured); the rules follow the same condition.
    let confident = layers.iter().all(|l| l.confidence.is_some());
    let params = fusion_params(opts, layers.len(), confident);
    summary.fusion = Some(params);
    let equal = vec![1.0; layers.len()];
    let mut fused = fuse_files(&layers, &equal, grid, rows, &params, progress)?;
    let agreement = std::mem::take(&mut fused.agreement);
    let weights: Vec<f32> = if opts.weight_pairs {
        let weights: Vec<f32> = agreement.iter().map(pair_weight).collect();
        fused = fuse_files(&layers, &weights, grid, rows, &params, progress)?;
        weights
    } else {
        equal
    };
    for (k, &i) in fusable.iter().enumerate() {
        let p = &mut summary.pairs[i];
        p.agreement = Some(agreement[k]);
        p.weight = Some(weights[k]);
    }
    summary.fused = Some(write_fused(opts, fused, grid, layers.len(), t)?);
    if let Some(path) = &opts.truth {
        summary.scores = Some(score_against_truth(&opts.output, path, grid)?);
    }
    Ok(())
}

/// The fusion's rules for `pairs` DSMs, `confident` when every one has a confidence sidecar:
/// then the summed confidence decides which cells are trusted (and the count only when asked),
/// else the count of agreeing pairs.
fn fusion_params(opts: &ReconstructManyOptions, pairs: usize, confident: bool) -> FusionParams {
    let min_confidence = opts
        .min_confidence
        .unwrap_or_else(|| auto_min_confidence(pairs));
    let by_confidence = confident && min_confidence > 0.0;
    FusionParams {
        tolerance: opts.cluster_tolerance,
        min_support: opts.min_support.unwrap_or(if by_confidence {
            1
        } else {
            auto_min_support(pairs)
        }),
        min_confidence: by_confidence.then_some(min_confidence),
    }
}

/// The default agreement of a fusion of `pairs` DSMs without confidence: at least 2 pairs (a height that only one
/// pair measured is too often a mismatch), a quarter of them from 12 pairs on, never more than
/// there are pairs. On the dev set each further agreeing pair asked for, up to four, lowered the
/// MAE at a small cost in coverage (BENCHMARKS.md, "Many dates, one DSM", the fusion variants
/// measured with the count rule).
pub fn auto_min_support(pairs: usize) -> usize {
    (pairs.div_ceil(4)).max(2).min(pairs.max(1))
}

/// The shard of pair `k`'s tiles that the run's `shard` takes: its tiles at positions `p` with
/// `p + k ≡ i (mod n)`, so that pairs of a single tile (or fewer tiles than shards) still
/// spread over the shards instead of all landing on shard 0.
pub fn shard_of_pair(shard: Shard, k: usize) -> Shard {
    let n = shard.count;
    Shard {
        index: (shard.index + n - k % n) % n,
        count: n,
    }
}

/// The options of one pair's tiled reconstruction.
fn pair_options(
    opts: &ReconstructManyOptions,
    views: &[View],
    pair: &PairChoice,
    grid: &GridChoice,
    work: &Path,
) -> ReconstructOptions {
    let (l, r) = (&views[pair.left], &views[pair.right]);
    let dir = work.join("pairs");
    let mut o = ReconstructOptions::new(
        l.image.clone(),
        r.image.clone(),
        opts.matcher.clone(),
        grid.clone(),
        dir.join(format!("{}.tif", pair.stem)),
    );
    o.rpc_left = l.rpc_file.clone();
    o.rpc_right = r.rpc_file.clone();
    o.alt_range = opts.alt_range;
    o.work_dir = Some(dir.join(format!("{}_work", pair.stem)));
    o.finishing = Finishing::new(opts.finishing.gridding, None, None, opts.pair_median_filter);
    o.truth = opts.truth.clone();
    o.tile = opts.tile;
    o.collar = opts.collar;
    o.max_memory = opts.max_memory;
    o.shard = Shard::ALL;
    o.both_views = opts.both_views;
    // The cameras were adjusted all together (or are used as given).
    o.adjust_pointing = false;
    // The pairs level the ground as `reconstruct` does (the right image sheared): they measure
    // more cells, which the confidence rule turns into a gain on the ten dev images (more
    // coverage and more cells within 1 m than from unsheared pairs), where the count rule lost
    // with them (BENCHMARKS.md, "The right image sheared to level the ground", "Not in
    // `reconstruct-many`"). The procedural world's cameras have no tilt: unchanged there.
    o
}

/// Runs one pair; a failure is recorded, not returned.
fn run_pair(
    o: &ReconstructOptions,
    grid: &DsmGrid,
    stem: &str,
    progress: &dyn Progress,
) -> PairOutcome {
    let t = Instant::now();
    let mut out = PairOutcome {
        stem: stem.to_string(),
        status: PairStatus::Failed,
        dsm: o.output.clone(),
        error: None,
        failed_tiles: Vec::new(),
        measured_cells: 0,
        measured_share: 0.0,
        scores: None,
        registration: None,
        agreement: None,
        weight: None,
        seconds: 0.0,
    };
    match reconstruct(o, progress) {
        Err(e) => out.error = Some(format!("{e:#}")),
        Ok(s) => {
            out.failed_tiles = s
                .records
                .iter()
                .filter(|r| r.status == TileStatus::Failed)
                .map(|r| r.tile.id.clone())
                .collect();
            match s.dsm {
                None if o.tiles_only => {
                    out.status = if out.failed_tiles.is_empty() {
                        PairStatus::Tiles
                    } else {
                        PairStatus::Partial
                    };
                }
                Some(d) if d.measured_cells > 0 => {
                    out.measured_cells = d.measured_cells;
                    out.measured_share =
                        d.measured_cells as f64 / (grid.width * grid.height) as f64;
                    out.status = if out.failed_tiles.is_empty() {
                        PairStatus::Done
                    } else {
                        PairStatus::Partial
                    };
                    out.scores = s.scores;
                }
                Some(_) => out.error = Some("no cell of the grid was measured".into()),
                None => out.error = Some("the DSM was not assembled".into()),
            }
        }
    }
    out.seconds = t.elapsed().as_secs_f64();
    out
}

/// Fills (where no cluster was kept), filters and writes the fused DSM, its count, spread and
/// confidence.
fn write_fused(
    opts: &ReconstructManyOptions,
    fused: Fused,
    grid: &DsmGrid,
    pairs: usize,
    t: Instant,
) -> Result<FusedOutcome> {
    let (w, h) = (grid.width, grid.height);
    let measured_cells = fused.measured();
    let count = Image::new(w, h, 1, fused.counts.iter().map(|&c| c as f32).collect())?;
    let (count_path, spread_path) = (opts.sibling("_count.tif"), opts.sibling("_spread.tif"));
    let confidence_path = opts.sibling("_confidence.tif");
    // The report is rewritten after the DSM; `reconstruct`'s filled cells describe no fusion.
    crate::dsm::remove_other_sidecars(
        &opts.output,
        &["_count.tif", "_spread.tif", crate::dsm::CONFIDENCE_SUFFIX],
    )?;
    let write = |path: &Path, image: Image, band| {
        write_grid_raster(path, &image, grid, band)
            .with_context(|| format!("writing {}", path.display()))
    };
    write(&count_path, count, bands::COUNT)?;
    write(
        &spread_path,
        Image::new(w, h, 1, fused.spreads)?,
        bands::SPREAD,
    )?;
    let confidences = Image::new(w, h, 1, fused.confidences)?;
    write(&confidence_path, confidences, bands::SUMMED_CONFIDENCE)?;
    let dsm = Image::new(w, h, 1, fused.heights)?;
    let dsm = opts.finishing.finish(dsm)?;
    write_dsm(&opts.output, &dsm, grid)
        .with_context(|| format!("writing {}", opts.output.display()))?;
    Ok(FusedOutcome {
        dsm: opts.output.clone(),
        count: count_path,
        spread: spread_path,
        confidence: confidence_path,
        pairs,
        grid: grid.clone(),
        measured_cells,
        filled_cells: dsm.data().iter().filter(|v| v.is_finite()).count(),
        seconds: t.elapsed().as_secs_f64(),
    })
}

/// Side of the central window two pairs' DSMs are registered on, cells.
const REGISTRATION_WINDOW: usize = 1024;

/// The shift and offset that register the DSM at `path` on the `reference` DSM (both on `grid`),
/// estimated on a central window; none when they share no cell there.
fn co_register(reference: &Path, path: &Path, grid: &DsmGrid) -> Result<Shift> {
    if reference == path {
        return Ok(Shift::default());
    }
    let (w, h) = (
        grid.width.min(REGISTRATION_WINDOW),
        grid.height.min(REGISTRATION_WINDOW),
    );
    let (x0, y0) = ((grid.width - w) / 2, (grid.height - h) / 2);
    let read = |p: &Path| -> Result<Image> {
        let mut r = raster::formats::TiffReader::open(p)
            .with_context(|| format!("opening {}", p.display()))?;
        Ok(r.read_window(x0, y0, w, h)?)
    };
    let (a, b) = (read(reference)?, read(path)?);
    Ok(
        align(&a, &b, &AlignParams::default()).map_or(Shift::default(), |al| Shift {
            dx: al.dx,
            dy: al.dy,
            offset: al.offset as f32,
        }),
    )
}

/// The UTM zone of the scene, where the pairs are chosen: the grid's when it is UTM, else the
/// first camera's.
fn scene_zone(opts: &ReconstructManyOptions) -> Result<UtmZone> {
    if let GridChoice::Resolution {
        epsg: Some(code), ..
    } = &opts.grid
    {
        if let Some(zone) = Crs::from_epsg(*code)?.utm_zone() {
            return Ok(zone);
        }
    }
    let first = &opts.images[0];
    let raw = RawImage::open(first, "first")?;
    let rpc = camera_of(
        first,
        raw.rpc.clone(),
        rpc_json(opts, first)?.as_deref(),
        "first",
    )?;
    Ok(UtmZone::from_lonlat(rpc.lon_offset, rpc.lat_offset))
}

/// `DIR/<image stem>.json` when `--rpc-dir` is given; an error naming both when it is missing.
fn rpc_json(opts: &ReconstructManyOptions, image: &Path) -> Result<Option<PathBuf>> {
    let Some(dir) = &opts.rpc_dir else {
        return Ok(None);
    };
    let json = dir.join(format!("{}.json", file_stem(image)?));
    if !json.is_file() {
        bail!(
            "{}: its camera {} does not exist: put the image's SatNeRF/rpcm JSON there (named \
             after the image), or leave the image out",
            image.display(),
            json.display()
        );
    }
    Ok(Some(json))
}

/// Opens every image and its camera, metadata and footprint.
fn open_views(
    opts: &ReconstructManyOptions,
    zone: UtmZone,
    progress: &dyn Progress,
) -> Result<Vec<View>> {
    if opts.images.len() < 2 {
        bail!(
            "reconstruct-many needs two or more images of the area, got {}{}: give every \
             acquisition (or use `reconstruct` for one pair)",
            opts.images.len(),
            opts.images
                .first()
                .map_or(String::new(), |p| format!(" ({})", p.display()))
        );
    }
    let mut views = Vec::with_capacity(opts.images.len());
    for image in &opts.images {
        let raw = RawImage::open(image, "input")?;
        let json = rpc_json(opts, image)?;
        let rpc = camera_of(image, raw.rpc.clone(), json.as_deref(), "input")?;
        let Acquisition { date, sun } = match &json {
            Some(j) => json_metadata(j)?,
            None => delivered_metadata(image, progress)?,
        };
        let (alt_range, _) = altitude_range(opts.alt_range, &rpc, &rpc)?;
        let (w, h) = raw.size();
        let fp = footprint(&rpc, Roi::full(w, h), alt_range, &Crs::Utm(zone))
            .with_context(|| format!("the ground footprint of {}", image.display()))?;
        views.push(View {
            image: image.clone(),
            rpc_file: json,
            day: date.as_deref().and_then(parse_day),
            date,
            sun,
            footprint: fp,
            rpc,
        });
    }
    Ok(views)
}

/// Adjusts every view's camera from tie points, writes the corrected cameras as RPC JSON under
/// the work folder and points the views at them (their altitudes: the user's, else the
/// cameras', else the tie points'). A resumed run whose work folder holds the adjustment of the
/// same images reads it back instead.
fn adjust_cameras(
    opts: &ReconstructManyOptions,
    views: &mut [View],
    zone: UtmZone,
    progress: &dyn Progress,
) -> Result<super::pointing::Pointing> {
    use super::pointing::{adjust_views, describe, tie_pairs, write_camera_json, TieView};
    let dir = opts.work_dir().join("cameras");
    let record = dir.join("adjustment.json");
    let images: Vec<PathBuf> = views
        .iter()
        .map(|v| workflow::outputs::resolve(&v.image))
        .collect();
    let names: Vec<String> = views
        .iter()
        .map(|v| file_stem(&v.image))
        .collect::<Result<_>>()?;
    let cameras: Vec<PathBuf> = names
        .iter()
        .map(|n| dir.join(format!("{n}.json")))
        .collect();
    let given = given_range(opts, views)?;
    let pointing = match read_adjustment(&record, &images) {
        Some(p) if cameras.iter().all(|c| c.is_file()) => {
            progress.note("pointing: the cameras adjusted by an earlier run of this work folder");
            p
        }
        _ => {
            let alt = given.map_or_else(
                || views.iter().map(|v| v.rpc.alt_offset).sum::<f64>() / views.len() as f64,
                |(lo, hi)| 0.5 * (lo + hi),
            );
            let days: Vec<Option<f64>> = views.iter().map(|v| v.day).collect();
            let pairs = tie_pairs(&days, |i, j| {
                super::select::intersect(views[i].footprint, views[j].footprint).is_some()
            });
            progress.note(&format!(
                "pointing: tying {} pairs of the {} images, then one bundle adjustment",
                pairs.len(),
                views.len()
            ));
            let tie_views: Vec<TieView> = views
                .iter()
                .map(|v| {
                    let raw = RawImage::open(&v.image, "input")?;
                    TieView::read(&raw, &v.rpc)
                })
                .collect::<Result<_>>()?;
            let p = adjust_views(&tie_views, &pairs, camera::Gauge::MeanZero, alt)
                .context("the bundle adjustment of the cameras")?;
            for (v, fit) in views.iter().zip(&p.images) {
                let camera = super::pointing::camera_source(&v.image, v.rpc_file.as_deref());
                super::pointing::check_fit(fit, &v.image, &camera)?;
            }
            std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
            let range = given.unwrap_or(p.alt_range);
            for ((v, fit), path) in views.iter().zip(&p.images).zip(&cameras) {
                let rpc = v.rpc.translated(fit.col_shift, fit.row_shift);
                write_camera_json(path, &rpc, fit, range, v.date.as_deref(), v.sun)?;
            }
            workflow::stage::write_json(
                &record,
                &serde_json::json!({ "images": images, "pointing": p }),
            )?;
            p
        }
    };
    for line in describe(&pointing, &names) {
        progress.note(&format!("pointing: {line}"));
    }
    let (range, source) = match given {
        Some(r) => (r, "given"),
        None => (pointing.alt_range, "tie points"),
    };
    progress.note(&format!(
        "altitudes: {:.1} to {:.1} m ({source})",
        range.0, range.1
    ));
    for (v, path) in views.iter_mut().zip(&cameras) {
        v.rpc = crate::dsm::read_camera(path)?;
        v.rpc_file = Some(path.clone());
        let (w, h) = RawImage::open(&v.image, "input")?.size();
        v.footprint = footprint(&v.rpc, Roi::full(w, h), range, &Crs::Utm(zone))
            .with_context(|| format!("the ground footprint of {}", v.image.display()))?;
    }
    Ok(pointing)
}

/// The altitudes the user or every camera gives (the union of the cameras' ranges).
fn given_range(opts: &ReconstructManyOptions, views: &[View]) -> Result<Option<(f64, f64)>> {
    let mut range: Option<(f64, f64)> = None;
    for v in views {
        let Some(((lo, hi), _)) =
            crate::rectify::given_altitude_range(opts.alt_range, &v.rpc, &v.rpc)?
        else {
            return Ok(None);
        };
        range = Some(range.map_or((lo, hi), |(a, b)| (a.min(lo), b.max(hi))));
    }
    Ok(range)
}

/// The adjustment recorded in a work folder, if it is of these images.
fn read_adjustment(record: &Path, images: &[PathBuf]) -> Option<super::pointing::Pointing> {
    #[derive(serde::Deserialize)]
    struct Record {
        images: Vec<PathBuf>,
        pointing: super::pointing::Pointing,
    }
    let text = std::fs::read_to_string(record).ok()?;
    let r: Record = serde_json::from_str(&text).ok()?;
    (r.images == images).then_some(r.pointing)
}

/// The date and sun of an image as delivered: its metadata sidecar (`.IMD`, DIMAP) or the NITF
/// date in its TIFF tags; a warning when none gives a date (the pairs are then chosen without
/// it).
fn delivered_metadata(image: &Path, progress: &dyn Progress) -> Result<Acquisition> {
    let found = camera::metadata_of(image)
        .with_context(|| format!("the acquisition metadata of {}", image.display()))?;
    let date = found.as_ref().and_then(|a| a.datetime.clone());
    if date.is_none() {
        progress.note(&format!(
            "warning: {}: no acquisition date (no .IMD or DIMAP metadata beside it, no NITF date \
             in its tags): its pairs are chosen without it",
            image.display()
        ));
    }
    let sun = found.and_then(|a| a.sun_elevation.zip(a.sun_azimuth));
    Ok(Acquisition { date, sun })
}

/// The middle of the scene's altitudes (the user's, else the cameras').
fn middle_altitude(opts: &ReconstructManyOptions, views: &[View]) -> Result<f64> {
    let (lo, hi) = altitude_range(opts.alt_range, &views[0].rpc, &views[1].rpc)?.0;
    Ok(0.5 * (lo + hi))
}

/// Refuses one image given twice: the same file, or the same pixels under another name (only
/// images of the same size are read to compare their pixels).
fn check_distinct(views: &[View]) -> Result<()> {
    let canon: Vec<PathBuf> = views
        .iter()
        .map(|v| std::fs::canonicalize(&v.image).unwrap_or_else(|_| v.image.clone()))
        .collect();
    let sizes: Vec<(usize, usize)> = views
        .iter()
        .map(|v| RawImage::open(&v.image, "input").map(|r| r.size()))
        .collect::<Result<_>>()?;
    let mut hashes: Vec<Option<u64>> = vec![None; views.len()];
    let mut hash = |i: usize| -> Result<u64> {
        if hashes[i].is_none() {
            hashes[i] = Some(pixel_hash(&views[i].image)?);
        }
        Ok(hashes[i].expect("just set"))
    };
    for i in 0..views.len() {
        for j in i + 1..views.len() {
            let why = if canon[i] == canon[j] {
                "the same file"
            } else if sizes[i] == sizes[j] && hash(i)? == hash(j)? {
                "identical pixels"
            } else {
                continue;
            };
            bail!(
                "{} and {} are the same acquisition ({why}): give each image once",
                views[i].image.display(),
                views[j].image.display(),
            );
        }
    }
    Ok(())
}

/// A hash of an image's pixels, read by strips of rows.
fn pixel_hash(path: &Path) -> Result<u64> {
    let raw = RawImage::open(path, "input")?;
    let (w, h) = raw.size();
    let mut hasher = DefaultHasher::new();
    const STRIP: usize = 256;
    for y in (0..h).step_by(STRIP) {
        let strip = raw.window(0, y, w, STRIP.min(h - y))?;
        for v in strip.data() {
            v.to_bits().hash(&mut hasher);
        }
    }
    Ok(hasher.finish())
}

/// Refuses an image whose footprint meets no other image's.
fn check_overlaps(views: &[View]) -> Result<()> {
    for (i, v) in views.iter().enumerate() {
        let alone = views
            .iter()
            .enumerate()
            .all(|(j, o)| j == i || super::select::intersect(v.footprint, o.footprint).is_none());
        if alone {
            bail!(
                "{} overlaps none of the other images (its ground footprint, UTM {:.0}..{:.0} E, \
                 {:.0}..{:.0} N, meets no other): leave it out, or check its camera",
                v.image.display(),
                v.footprint[0],
                v.footprint[2],
                v.footprint[1],
                v.footprint[3]
            );
        }
    }
    Ok(())
}

/// Refuses outputs that are inputs or not GeoTIFFs, existing ones that are not this run's
/// ([`crate::provenance`]), and `--truth` without its grid.
fn check_outputs(opts: &ReconstructManyOptions) -> Result<()> {
    let mut inputs: Vec<PathBuf> = opts.images.clone();
    if let Some(dir) = &opts.rpc_dir {
        for image in &opts.images {
            if let Ok(stem) = file_stem(image) {
                inputs.push(dir.join(format!("{stem}.json")));
            }
        }
    }
    if let GridChoice::Like(p) = &opts.grid {
        inputs.push(p.clone());
    }
    inputs.extend(opts.truth.iter().cloned());
    let inputs: Vec<&Path> = inputs.iter().map(PathBuf::as_path).collect();
    let mut outputs = vec![opts.output.clone()];
    outputs.extend(crate::dsm::sidecars(&opts.output));
    for out in &outputs {
        check_output_file("-o", out, &inputs, true)?;
    }
    workflow::outputs::check_dsm_extension("-o", &opts.output)?;
    workflow::outputs::check_products(&opts.products, &opts.output, &inputs, &mut outputs)?;
    check_output_folder("--work", &opts.work_dir(), &inputs, false)?;
    let canon = |p: &Path| std::fs::canonicalize(p).ok();
    if let (Some(t), GridChoice::Like(l)) = (&opts.truth, &opts.grid) {
        if canon(t) != canon(l) {
            bail!(
                "--truth {} must be the DSM given to --like (the scores need its grid)",
                t.display()
            );
        }
    } else if opts.truth.is_some() {
        bail!("--truth needs --like on the same file (the scores need its grid)");
    }
    // Last, as it may clear another run's work folder (with --overwrite): a rerun of the same
    // run resumes it and rewrites its products; a dry run writes nothing.
    if !opts.dry_run {
        let run = opts.run_record();
        crate::provenance::check(&opts.work_dir(), &run, &outputs, &inputs, opts.overwrite)?;
    }
    Ok(())
}

/// The fused grid, and the grid choice that gives every pair exactly that grid.
fn common_grid(
    opts: &ReconstructManyOptions,
    chosen: &[PairChoice],
    zone: UtmZone,
) -> Result<(DsmGrid, GridChoice)> {
    match &opts.grid {
        GridChoice::Like(p) => {
            let grid = DsmGrid::read(p, Some(zone))
                .with_context(|| format!("reading the grid of {}", p.display()))?;
            Ok((grid, opts.grid.clone()))
        }
        GridChoice::Exact(grid) => Ok((grid.clone(), opts.grid.clone())),
        GridChoice::Resolution {
            resolution,
            bounds,
            epsg,
        } => {
            let crs = Crs::from_epsg(epsg.unwrap_or(zone.epsg()))?;
            let utm = Crs::Utm(zone);
            let b = match bounds {
                Some(b) => *b,
                None => crs.bounds_of(&utm, union_bounds(chosen)),
            };
            let (lon, lat) = crs.inverse((b[0] + b[2]) / 2.0, (b[1] + b[3]) / 2.0);
            let cell = crs.cell_size(*resolution, lon, lat);
            let b = if bounds.is_some() {
                b
            } else {
                super::snap_outwards(b, cell)
            };
            let grid = DsmGrid::from_bounds(b[0], b[1], b[2], b[3], cell, crs.epsg())?;
            Ok((grid.clone(), GridChoice::Exact(grid)))
        }
    }
}

/// The union of the pairs' overlaps (UTM).
fn union_bounds(chosen: &[PairChoice]) -> [f64; 4] {
    chosen.iter().fold(
        [
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        ],
        |u, p| {
            let o = p.overlap;
            [
                u[0].min(o[0]),
                u[1].min(o[1]),
                u[2].max(o[2]),
                u[3].max(o[3]),
            ]
        },
    )
}

/// Bytes per fused cell held at once: heights, counts, spreads, confidences, and the filled and
/// filtered copies of the heights.
const FUSE_BYTES_PER_CELL: u64 = 26;

/// Rows of each pair read at once, refused when the fused grid does not fit the budget.
fn fusion_rows(grid: &DsmGrid, pairs: usize, max_memory: u64) -> Result<usize> {
    let cells = (grid.width * grid.height) as u64;
    let held = cells * FUSE_BYTES_PER_CELL;
    if held + super::PROCESS_BYTES > max_memory {
        bail!(
            "fusing the {}x{}-cell DSM needs about {:.2} GiB, more than --max-memory {:.2} GiB: \
             use a coarser --resolution or raise --max-memory",
            grid.width,
            grid.height,
            crate::flags::gib(held),
            crate::flags::gib(max_memory)
        );
    }
    // A block of every pair (heights and confidences: read buffer and copy) in an eighth of what
    // is left, 16 rows at least.
    let left = (max_memory - held - super::PROCESS_BYTES) / 8;
    let per_row = (grid.width * pairs.max(1) * 16) as u64;
    Ok(((left / per_row.max(1)) as usize).clamp(16, grid.height.max(16)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn agreement_grows_with_the_pairs_but_never_beyond_them() {
        let m: Vec<usize> = [1, 2, 3, 8, 12, 16, 20].map(auto_min_support).to_vec();
        assert_eq!(m, vec![1, 2, 2, 2, 3, 4, 5]);
        assert!((auto_min_confidence(12) - 1.2).abs() < 1e-6);
    }

    #[test]
    fn every_tile_of_every_pair_lands_on_exactly_one_shard_and_single_tiles_spread() {
        for n in 1..5 {
            for k in 0..7 {
                for p in 0..9 {
                    let owners = (0..n)
                        .filter(|&i| shard_of_pair(Shard { index: i, count: n }, k).contains(p))
                        .count();
                    assert_eq!(owners, 1, "{n} shards, pair {k}, tile {p}");
                }
            }
        }
        // Three pairs of one tile each over three shards: one pair each.
        let owner =
            |k| (0..3).find(|&i| shard_of_pair(Shard { index: i, count: 3 }, k).contains(0));
        assert_eq!([0, 1, 2].map(owner), [Some(0), Some(1), Some(2)]);
    }

    #[test]
    fn confidences_decide_when_every_pair_has_one_and_the_count_otherwise() {
        let opts = ReconstructManyOptions::new(
            vec![],
            None,
            Matcher::Classical(Default::default()),
            GridChoice::Like("t.tif".into()),
            "o.tif".into(),
        );
        let p = fusion_params(&opts, 12, true);
        assert_eq!((p.min_support, p.min_confidence), (1, Some(1.2)));
        let p = fusion_params(&opts, 12, false);
        assert_eq!((p.min_support, p.min_confidence), (3, None));
        let given = ReconstructManyOptions {
            min_confidence: Some(0.0),
            ..opts.clone()
        };
        let p = fusion_params(&given, 12, true);
        assert_eq!(
            (p.min_support, p.min_confidence),
            (3, None),
            "0 turns it off"
        );
        let given = ReconstructManyOptions {
            min_confidence: Some(2.0),
            min_support: Some(2),
            ..opts
        };
        let p = fusion_params(&given, 6, true);
        assert_eq!((p.min_support, p.min_confidence), (2, Some(2.0)));
    }
}

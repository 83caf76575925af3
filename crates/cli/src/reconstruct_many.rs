//! `seasonstereo reconstruct-many`: every acquisition of an area → the best pairs → one fused
//! DSM.

use std::path::{Path, PathBuf};

use anyhow::Result;
use clap::Args;
use seasonstereo::{defaults, flags};
use seasonstereo::{
    reconstruct_many, FusionParams, PairChoice, Progress, ReconstructManyOptions,
    ReconstructManySummary, View,
};

use crate::args::{
    heading, parse_alt_range, print_products_and_scores, GridArgs, GriddingArg, MatcherArgs,
    ProductArgs, TilingArgs,
};

/// `reconstruct-many -h`'s epilogue: the principal use, as it pastes.
const AFTER_HELP: &str = "\
Example (every acquisition of an area, vendor cameras beside the images):
  D=../shared/data/dfc2019-jax068-dev
  seasonstereo reconstruct-many $D/vendor/*.TIF -o out/jax-many/dsm.tif

Every option, how pairs are chosen and fused, the files: reconstruct-many --help";

/// `reconstruct-many --help`'s epilogue: pairs, fusion, files, clusters, exit codes, examples.
const AFTER_LONG_HELP: &str = "\
Cameras: one bundle adjustment corrects every camera's pointing on tie points tracked across \
the images and writes the corrected cameras to WORK/cameras/<image stem>.json (not with \
--no-pointing-correction or --dry-run, nor for JSON cameras that all carry the scene's \
altitudes).

Pairs: every overlapping pair is scored from metadata and geometry alone: date 1/(1 + days/45) \
× convergence (0 below 1°, 1 from 5° to 45°, 0 from 60°) × cos(largest incidence) × sun \
(1 − 0.5·min(Δsun/60°, 1)); the best --pairs run (--dry-run prints them with these terms). Each \
pair runs through `reconstruct` without hole filling on one grid (--like, else the union of the \
pairs' overlaps).

Fusion: per cell the pairs' heights are cut into clusters at gaps over --cluster-tolerance; each \
height weighs the matcher's confidence in it (the pair's _confidence.tif: 1 − S1/S2, 0 to 1); \
the strongest cluster (the largest summed confidence; ties: the higher) gives the weighted \
median when its confidences sum to --min-confidence (and --min-support pairs agree, when given; \
without confidences, as with MonSter++, the count alone decides). The other cells (no pair \
measured, or too little agreed) are filled as holes (--fill-holes), then the DSM is \
median-filtered (--median-filter). Every pair's agreement (the share of its cells within \
--cluster-tolerance of the fused height) is reported; --pair-weights fuses again with each pair \
weighted by agreement^8.

Files: OUTPUT (float32 COG), OUTPUT_count.tif (pairs that measured each cell), \
OUTPUT_spread.tif (median absolute deviation of the kept heights, m; NaN where no height was \
kept: those cells are filled or empty), OUTPUT_confidence.tif (the kept cluster's summed \
confidence; NaN where none), OUTPUT_report.json, and the work folder (--work, default \
OUTPUT_work/): cameras/, pairs/<pair>.tif, <pair>_confidence.tif and <pair>_work/ (the pair's \
tiles); a rerun resumes.

Clusters: --shard I/N (with --work on a shared file system) runs only this task's share of \
every pair's tiles (pair k's tiles at positions p with p + k ≡ I mod N) and stops; the same \
command without --shard then retries failed tiles, assembles the pairs and fuses them \
(docs/jobs/reconstruct-many-slurm.sh submits both on Slurm).

Exit codes: 0 all pairs done; 1 error before any work; 2 partial (some pairs failed, named; the \
DSM fuses the others); 3 nothing produced.

Examples:
  D=../shared/data/dfc2019-jax068-dev
  # Every acquisition as delivered (.RPB and .IMD beside each image)
  seasonstereo reconstruct-many $D/vendor/*.TIF -o out/jax-many/dsm.tif
  # Only the chosen pairs and their scores, nothing reconstructed
  seasonstereo reconstruct-many $D/vendor/*.TIF -o out/jax-many/dsm.tif \\
      --dry-run
  # On the truth's grid and scored against it
  seasonstereo reconstruct-many $D/vendor/*.TIF -o out/jax-many/dsm.tif \\
      --like $D/truth/JAX_068_DSM.tif --truth $D/truth/JAX_068_DSM.tif";

#[derive(Args)]
#[command(
    after_help = AFTER_HELP,
    after_long_help = AFTER_LONG_HELP,
    // The matcher's choice shows in `predict -h`; here the default is what most runs need.
    mut_arg("method", |a| a.hide_short_help(true)),
    mut_arg("model", |a| a.hide_short_help(true)),
    mut_arg("weights", |a| a.hide_short_help(true)),
)]
pub struct ReconstructManyArgs {
    /// The raw images of the area, two or more.
    ///
    /// Each with its camera as for `reconstruct` (a vendor sidecar beside it, or its RPC tag),
    /// or as `<image stem>.json` in --rpc-dir.
    #[arg(required = true, value_name = "IMAGE", help_heading = heading::INPUTS, display_order = 0)]
    images: Vec<PathBuf>,
    /// Folder of the cameras as SatNeRF/rpcm JSON, one `<image stem>.json` per image.
    ///
    /// Dates and sun angles are read from them too. Default: each image's vendor camera beside
    /// it (.RPB, _RPC.TXT, DIMAP RPC XML), else its RPC tag, with the metadata beside it.
    #[arg(long, value_name = "DIR", help_heading = heading::INPUTS, display_order = 1)]
    rpc_dir: Option<PathBuf>,
    /// Output fused DSM (.tif): heights above the WGS84 ellipsoid, float32 COG.
    ///
    /// The geoid's heights with --heights egm96. Cells no pair measured, or where too few
    /// agreed, are filled near data (--fill-holes); those left without a height are NaN. Beside
    /// it: OUTPUT_count.tif, OUTPUT_spread.tif, OUTPUT_confidence.tif and OUTPUT_report.json.
    #[arg(short, long, help_heading = heading::OUTPUTS)]
    output: PathBuf,
    /// Work folder, to resume (default: OUTPUT without extension + "_work").
    ///
    /// It holds the corrected cameras, the pairs' DSMs and their tiles; a rerun resumes there:
    /// finished pairs and tiles are kept.
    #[arg(long, value_name = "DIR", help_heading = heading::OUTPUTS)]
    work: Option<PathBuf>,
    #[command(flatten)]
    grid: GridArgs,
    /// How many pairs to reconstruct and fuse: the best by score.
    #[arg(long, value_name = "K", default_value_t = defaults::PAIRS,
          help_heading = heading::QUALITY)]
    pairs: usize,
    /// Print the chosen pairs and their score terms; reconstruct nothing.
    #[arg(long, help_heading = heading::QUALITY)]
    dry_run: bool,
    /// Scene altitudes MIN:MAX, metres (default: from cameras or tie points).
    ///
    /// The disparity search covers them. Default: the JSONs' min_alt/max_alt, else the
    /// altitudes of the bundle adjustment's tie points, their 0.5 and 99.5 percentiles widened
    /// by 5 m and a tenth of their span.
    #[arg(long, value_name = "MIN:MAX", value_parser = parse_alt_range, allow_hyphen_values = true,
          help_heading = heading::QUALITY)]
    alt_range: Option<(f64, f64)>,
    /// Score the DSMs against this ground truth (needs --like on it).
    ///
    /// The fused DSM and every pair's, against a ground truth <AOI>_DSM.tif, with the
    /// benchmark's metric (MAE and coverage); --like must name the same file.
    #[arg(long, value_name = "DSM", requires = "like", help_heading = heading::QUALITY)]
    truth: Option<PathBuf>,
    /// Each pair's tiles; the fusion runs by row blocks within the same memory budget.
    #[command(flatten)]
    tiling: TilingArgs,
    /// Run only this shard's tiles of every pair (array jobs sharing --work; pair k's tiles at
    /// positions p with p + k ≡ I mod N), then stop; once every shard has finished, the same
    /// command without --shard assembles the pairs and fuses them.
    #[command(flatten)]
    shard: crate::args::ShardArg,
    #[command(flatten)]
    matcher: MatcherArgs,
    /// Match each pair's very narrow baselines from the left view only.
    ///
    /// See `reconstruct --single-view`; by default, under 0.63 px/m, a pair keeps the cells
    /// both views agree on.
    #[arg(long, help_heading = heading::MATCHING, hide_short_help = true)]
    single_view: bool,
    /// Use the cameras as given, without the bundle adjustment.
    ///
    /// By default every camera's pointing error (vendor RPCs are off by a few to tens of
    /// pixels, one translation over each image) is corrected by one bundle adjustment of all
    /// the images on tie points tracked across them (near dates chaining the seasons); the
    /// corrected cameras are written as RPC JSON under the work folder (cameras/<image
    /// stem>.json, usable by `reconstruct --rpc-left/--rpc-right`) and the corrections and
    /// residuals printed and kept in the report. JSON cameras that all carry the scene's
    /// altitudes (--rpc-dir of a curated, bundle-adjusted set) are used as given.
    #[arg(long, help_heading = heading::MATCHING, hide_short_help = true)]
    no_pointing_correction: bool,
    /// Height of a cell of a pair's DSM from its points.
    #[arg(long, value_enum, default_value_t = GriddingArg::Median,
          help_heading = heading::GRID, hide_short_help = true)]
    gridding: GriddingArg,
    /// Heights of one cell further apart than this, metres, are different surfaces.
    #[arg(long, value_name = "M", default_value_t = FusionParams::default().tolerance,
          help_heading = heading::FUSION, hide_short_help = true)]
    cluster_tolerance: f32,
    /// Fewest pairs that must agree for a cell to keep a measured height.
    ///
    /// Within the tolerance; other cells are filled like unmeasured ones. Default: 1 when the
    /// pairs have confidences (--min-confidence decides), else a quarter of the pairs rounded
    /// up, at least 2 and at most the number of pairs.
    #[arg(long, value_name = "N", help_heading = heading::FUSION, hide_short_help = true)]
    min_support: Option<usize>,
    /// Least summed confidence of the agreeing pairs for a cell to keep a measured height.
    ///
    /// Each pair's confidence is 0 to 1. Default: 0.1 per pair fused (1.2 for 12: about two
    /// confident pairs, or three hesitant ones); on the ten dev images 0.807 m / 84.0 % within
    /// 1 m against 0.878 m / 82.5 % by counting 3 pairs. 0 turns it off (the count of
    /// --min-support then decides).
    #[arg(long, value_name = "SUM", help_heading = heading::FUSION, hide_short_help = true)]
    min_confidence: Option<f32>,
    /// Register each pair's DSM on the first pair's before fusing.
    ///
    /// Integer NCC shift and vertical offset; off by default (it did not help on the dev set,
    /// BENCHMARKS.md).
    #[arg(long, help_heading = heading::FUSION, hide_short_help = true)]
    register: bool,
    /// Weight each pair by its agreement with a first, equal-weight fusion (agreement^8).
    ///
    /// On the ten dev images 0.850 → 0.824 m (within 1 m 82.8 → 83.2 %); on the procedural
    /// six-date world 0.72 → 1.13 m: pairs sharing an image agree with each other, and noisy
    /// narrow pairs are not wrong ones. Off by default.
    #[arg(long, help_heading = heading::FUSION, hide_short_help = true)]
    pair_weights: bool,
    /// Fill the fused DSM's holes enclosed by data within this many cells; 0 leaves them empty.
    ///
    /// The holes are the cells without a fused height: no pair measured them, or too few
    /// agreed.
    #[arg(long, value_name = "CELLS", default_value_t = 40,
          help_heading = heading::FINISHING, hide_short_help = true)]
    fill_holes: usize,
    /// Median filter of the fused DSM over this odd window of cells; 0 or 1 disables it.
    #[arg(long, value_name = "CELLS", default_value_t = defaults::FUSED_MEDIAN_CELLS,
          help_heading = heading::FINISHING, hide_short_help = true)]
    median_filter: usize,
    /// Median filter of each pair's DSM before fusion (never fills a cell); 0 or 1 disables it.
    #[arg(long, value_name = "CELLS", default_value_t = 0,
          help_heading = heading::FINISHING, hide_short_help = true)]
    pair_median_filter: usize,
    #[command(flatten)]
    products: ProductArgs,
}

/// Runs the command: an error of [`seasonstereo::Incomplete`] when some pairs failed (exit 2) or none produced
/// a DSM (exit 3).
pub fn run(a: ReconstructManyArgs, progress: &dyn Progress) -> Result<()> {
    // Pairs of different sizes run one after the other: freed pages go back to the kernel after
    // 10 ms (mimalloc's default) instead of never (allocator.rs), or the process would hold every
    // pair's peak at once and overshoot --max-memory (2.25 GB for 12 dev pairs at 2 GiB).
    crate::allocator::return_freed_pages_after(10);
    let options = a.options()?;
    let s = reconstruct_many(&options, progress)?;
    print_pairs(&s.chosen, &s.views, s.candidates);
    if s.pairs.is_empty() {
        return Ok(());
    }
    for p in &s.pairs {
        println!("{}", pair_line(p));
    }
    for w in s.warnings() {
        eprintln!("warning: {w}");
    }
    s.check_produced()?;
    if let Some(shard) = &s.shard {
        println!(
            "shard {shard}: its tiles of {} pairs ran; once every shard has finished, run the same \
             command without --shard to assemble the pairs and fuse them",
            s.pairs.len()
        );
    }
    let Some(f) = &s.fused else {
        return partial_if_incomplete(&s);
    };
    println!("{}", fused_line(&s, f));
    print_products_and_scores(&options.products, s.products.as_ref(), s.scores.as_ref());
    if let Some(r) = &s.report {
        println!("report: {}", r.display());
    }
    partial_if_incomplete(&s)
}

/// Exit code 2 naming the pairs that failed or lost tiles.
fn partial_if_incomplete(s: &ReconstructManySummary) -> Result<()> {
    let incomplete: Vec<String> = s
        .incomplete_pairs()
        .iter()
        .map(|p| p.stem.clone())
        .collect();
    crate::exit::partial_if_any(
        "pairs",
        s.pairs.len(),
        incomplete,
        "rerun the same command after fixing them (finished pairs and tiles are kept)",
    )
}

impl ReconstructManyArgs {
    /// The library's options for these flags.
    fn options(self) -> Result<ReconstructManyOptions> {
        let grid = self.grid.choice();
        let mut o = ReconstructManyOptions::new(
            self.images,
            self.rpc_dir,
            self.matcher.matcher()?,
            grid,
            self.output,
        );
        o.work_dir = self.work;
        o.pairs = self.pairs;
        o.dry_run = self.dry_run;
        o.cluster_tolerance = self.cluster_tolerance;
        o.min_support = self.min_support;
        o.min_confidence = self.min_confidence;
        o.co_register = self.register;
        o.weight_pairs = self.pair_weights;
        o.finishing = seasonstereo::Finishing::new(
            self.gridding.into(),
            flags::fill_cells(self.fill_holes),
            None,
            flags::median_cells(self.median_filter),
        );
        o.pair_median_filter = flags::median_cells(self.pair_median_filter);
        o.both_views = !self.single_view;
        o.truth = self.truth;
        o.alt_range = self.alt_range;
        o.adjust_pointing = !self.no_pointing_correction;
        o.products = self.products.products();
        (o.tile, o.collar) = (self.tiling.tile, self.tiling.collar);
        o.max_memory = self.tiling.max_memory_bytes()?;
        o.shard = self.shard.shard;
        o.overwrite = crate::exit::overwrite();
        Ok(o)
    }
}

/// The chosen pairs with the terms of their scores.
fn print_pairs(chosen: &[PairChoice], views: &[View], candidates: usize) {
    let undated = views.iter().filter(|v| v.day.is_none()).count();
    if undated > 0 {
        eprintln!(
            "warning: {undated} of {} images have no acquisition date (from the JSON cameras of \
             --rpc-dir, an .IMD or DIMAP file beside the image, or the NITF date in its tags): \
             their pairs get the date term 0.5",
            views.len()
        );
    }
    println!(
        "{} images, {candidates} overlapping pairs; chosen {}:",
        views.len(),
        chosen.len()
    );
    for p in chosen {
        let t = &p.terms;
        let opt = |v: Option<f64>, unit: &str| v.map_or("?".into(), |v| format!("{v:.1}{unit}"));
        println!(
            "  {:<36} score {:.3} = date {:.2} ({} apart) × convergence {:.2} ({:.1}°) × \
             incidence {:.2} ({:.1}°, {:.1}°) × sun {:.2} ({} apart)",
            p.stem,
            t.score,
            t.date_term,
            opt(t.days, " d"),
            t.convergence_term,
            t.convergence_deg,
            t.incidence_term,
            t.incidence_deg.0,
            t.incidence_deg.1,
            t.sun_term,
            opt(t.sun_deg, "°")
        );
    }
}

/// One pair's line: status, measured share, scores.
fn pair_line(p: &seasonstereo::PairOutcome) -> String {
    if p.status == seasonstereo::PairStatus::Tiles {
        return format!("pair {} {}, {:.1} s", p.stem, p.status.word(), p.seconds);
    }
    let scores = p.scores.as_ref().map_or(String::new(), |s| {
        format!(", vs truth: {}", crate::score::format_scores(s))
    });
    let status = p.status.word();
    let fusion = match (p.agreement, p.weight) {
        (Some(a), Some(w)) => format!(
            ", agrees with the fusion on {:.1} % of its cells (weight {w:.3})",
            100.0 * a.share()
        ),
        _ => String::new(),
    };
    format!(
        "pair {} {status}: {:.1} % of the grid measured{fusion}, {:.1} s{scores}",
        p.stem,
        100.0 * p.measured_share,
        p.seconds
    )
}

/// The fused DSM's line.
fn fused_line(s: &ReconstructManySummary, f: &seasonstereo::FusedOutcome) -> String {
    let cells = (f.grid.width * f.grid.height) as f64;
    format!(
        "wrote {} ({}; {} pairs fused, {:.1} % measured, {:.1} % with a height; count {}, \
         spread {}, confidence {}) in {:.1} s",
        f.dsm.display(),
        f.grid,
        f.pairs,
        100.0 * f.measured_cells as f64 / cells,
        100.0 * f.filled_cells as f64 / cells,
        name(&f.count),
        name(&f.spread),
        name(&f.confidence),
        s.seconds
    )
}

fn name(p: &Path) -> String {
    p.file_name().map_or(p.display().to_string(), |n| {
        n.to_string_lossy().into_owned()
    })
}

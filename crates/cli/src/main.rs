//! `seasonstereo`: dense stereo matching of multi-date satellite imagery.
//!
//! This binary only parses arguments and draws progress; the work lives in the library crates.

mod bars;
mod bench;
mod dataset;
mod demo;
mod dsm;
mod reconstruct;
mod stages;
mod train;

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{bail, Context, Result};
use clap::{Args, Parser, Subcommand, ValueEnum};
use matching::{Paths, SgmParams};
use pipeline::predict::{predict_monster, predict_sgm, read_pair, write_disparity};
use pipeline::progress::track;

#[derive(Parser)]
#[command(
    name = "seasonstereo",
    version,
    about = "Dense stereo matching of multi-date satellite imagery: disparity maps and DSMs",
    long_about = "Dense stereo matching of multi-date satellite imagery.\n\n\
        Conventions: pairs are rectified (epipolar lines are rows); disparity lives on the left view, \
        x_R = x_L − d, positive and growing with altitude; invalid pixels are NaN.\n\n\
        Start with `seasonstereo demo`: it renders a procedural satellite world with exact ground truth, \
        matches it and writes an HTML report."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render a procedural satellite world (rectified pair, exact disparity, heights, classes,
    /// homographies and RPC cameras) in the public release's folder layout.
    World(WorldArgs),
    /// Rectify a raw satellite pair from its RPC cameras (epipolar lines become rows) and give the
    /// disparity search range implied by the scene's altitudes.
    Rectify(RectifyArgs),
    /// Predict the disparity of a rectified pair.
    Predict(PredictArgs),
    /// From a raw pair to a DSM in one command: rectify from the RPCs, match over the range the
    /// cameras imply, triangulate and grid (optionally scored against a ground truth).
    Reconstruct(reconstruct::ReconstructArgs),
    /// Score DSMs on a ground truth's grid with the benchmark's metric (MAE and coverage).
    Score(reconstruct::ScoreArgs),
    /// Time the networks (MonSter++, SegFormer, DINOv3, a training step) with random weights:
    /// median and min over N runs after a warm-up, peak RSS, --json.
    Bench(bench::BenchArgs),
    /// Turn a rectified disparity into a georeferenced DSM (RPC triangulation, highest point per
    /// cell), on a ground truth's grid or on a UTM grid of your choosing.
    Dsm(dsm::DsmArgs),
    /// SeasonStereo's story on a procedural world: four seasons, a synchronic and a winter ↔ summer
    /// pair matched, triangulated to DSMs and scored against the truth; an HTML report (offline, CPU).
    Demo(demo::DemoArgs),
    /// Altitude MAE of the DSMs from predicted disparities, as the benchmark's code computes it
    /// (RPC triangulation, max-per-cell DSM on the ground truth's grid, NCC registration, foliage
    /// and water masked); prints the paper's Table 1. Resumable: pairs already in OUT/pairs.csv
    /// are skipped.
    Eval(EvalArgs),
    /// Teacher disparities (SGM, or MonSter++ with weights) for every real synchronic pair;
    /// resumable and shardable.
    Teacher(stages::TeacherArgs),
    /// Score the consistency of synchronic pairs (colour, SSIM, image features) and select the
    /// intersection of the two top-K rankings; resumable and shardable.
    Curate(stages::CurateArgs),
    /// Water, tree and building masks from one segmentation per image (SegFormer with weights,
    /// or the offline rules on colour and height above ground); resumable and shardable.
    Masks(stages::MasksArgs),
    /// Score a `masks` folder against DFC2019 classes (tree, building, ground IoU / precision /
    /// recall), the truth projected into each image through its DSM and RPCs.
    MasksScore(stages::MasksScoreArgs),
    /// Four seasonal variants of every image of the selected pairs (centre crop, built-in model
    /// or a generative API), checked for geometric fidelity and rectified; resumable, shardable.
    Synthesize(dataset::SynthesizeArgs),
    /// Training sets: `dataset build` assembles the 25 season combinations per pair, masks,
    /// subsets S1/S2/S3 and manifest; `dataset world` makes one from procedural worlds.
    Dataset(dataset::DatasetArgs),
    /// Fine-tune MonSter++ with the SeasonStereo loss from a TOML configuration or a preset
    /// (tiny, a-lidar, b-disp, c-photo, d-full, s1, s2, s3); checkpoints, exact --resume, Ctrl-C
    /// saves and exits.
    Train(train::TrainArgs),
}

#[derive(Args)]
struct WorldArgs {
    /// Output folder (L/, R/, homography/, disparity/, occlusion/, height/, classes/, rpc/, world.json).
    #[arg(short, long, default_value = "out/world")]
    output: PathBuf,
    /// Image width and height, pixels (64 for tests … 2048 for benchmarks).
    #[arg(long, default_value_t = 512)]
    size: usize,
    /// Random seed: the same seed always gives the same world.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Name of the world; images are <NAME>_A and <NAME>_B, the pair <NAME>_A-<NAME>_B.
    /// Default: WORLD_<SEED>.
    #[arg(long)]
    name: Option<String>,
    /// Also write the raw (unrectified) views as tiled uint8 GeoTIFFs raw/<ID>.tif, the input of
    /// `seasonstereo reconstruct` (with --rpc-left/--rpc-right rpc/<ID>.json).
    #[arg(long)]
    raw: bool,
}

/// The classical matcher: census costs aggregated by MGM or SGM, then the left-right check,
/// uniqueness, median and speckle filters.
#[derive(Clone, Copy, ValueEnum)]
enum Method {
    /// More Global Matching (Facciolo et al. 2015, as s2p): the default, best on real pairs.
    Mgm,
    /// Semi-Global Matching over 8 (or --four-paths 4) straight paths: faster.
    Sgm,
}

impl Method {
    fn aggregation(self) -> matching::Aggregation {
        match self {
            Method::Mgm => matching::Aggregation::Mgm,
            Method::Sgm => matching::Aggregation::Sgm,
        }
    }
}

#[derive(Args)]
#[command(
    after_help = "Writes OUT/L/<stem>.iio and OUT/R/<stem>.iio (NPY float32, NaN outside the \
    raw images), OUT/homography/<stem>.npz (Hleft, Hright: raw → rectified, flip included) and \
    OUT/rectify/<STEM>.json (ranges, region, sizes). Disparity x_L − x_R is positive and grows with \
    altitude; pass the printed range to `seasonstereo predict --range`.\n\n\
    Example (s2p's Pléiades test pair):\n  seasonstereo rectify img_01.tif img_02.tif -o out/s2p \
    --roi 150,150,700,700 --alt-range 2200:2450"
)]
struct RectifyArgs {
    /// Left raw image: a GeoTIFF carrying its RPC (tag 50844), or any raster with --rpc-left.
    left: PathBuf,
    /// Right raw image, idem with --rpc-right.
    right: PathBuf,
    /// Output folder.
    #[arg(short, long)]
    output: PathBuf,
    /// Region of interest X,Y,W,H in the left raw image, pixels. Default: the whole image.
    #[arg(long, value_name = "X,Y,W,H", value_parser = RectifyArgs::parse_roi)]
    roi: Option<camera::rectify::Roi>,
    /// Left camera as SatNeRF/rpcm JSON (instead of the TIFF's RPC tag).
    #[arg(long, value_name = "JSON")]
    rpc_left: Option<PathBuf>,
    /// Right camera as SatNeRF/rpcm JSON (instead of the TIFF's RPC tag).
    #[arg(long, value_name = "JSON")]
    rpc_right: Option<PathBuf>,
    /// Altitudes of the scene MIN:MAX, metres; the disparity range is derived from it. Default:
    /// min_alt/max_alt of the JSON cameras, else the RPCs' altitude offset ± scale (often
    /// thousands of metres: a slow, huge search).
    #[arg(long, value_name = "MIN:MAX", value_parser = RectifyArgs::parse_alt_range, allow_hyphen_values = true)]
    alt_range: Option<(f64, f64)>,
    /// Pair name <stem> of the output files. Default: <LEFT file stem>-<RIGHT file stem>.
    #[arg(long, value_name = "NAME")]
    stem: Option<String>,
}

impl RectifyArgs {
    fn parse_roi(s: &str) -> Result<camera::rectify::Roi, String> {
        let v: Vec<usize> = s
            .split(',')
            .map(|t| {
                t.trim()
                    .parse::<usize>()
                    .map_err(|e| format!("{t:?} in {s:?}: {e}"))
            })
            .collect::<Result<_, _>>()?;
        match v[..] {
            [x, y, w, h] if w > 0 && h > 0 => Ok(camera::rectify::Roi::new(x, y, w, h)),
            _ => Err(format!(
                "expected X,Y,W,H with W, H > 0, e.g. 150,150,700,700, got {s:?}"
            )),
        }
    }

    fn parse_alt_range(s: &str) -> Result<(f64, f64), String> {
        let (a, b) = s
            .split_once(':')
            .ok_or_else(|| format!("expected MIN:MAX in metres, e.g. -30:120, got {s:?}"))?;
        let parse = |v: &str| {
            v.trim()
                .parse::<f64>()
                .map_err(|e| format!("{v:?} in {s:?}: {e}"))
        };
        let (lo, hi) = (parse(a)?, parse(b)?);
        if !(lo.is_finite() && hi.is_finite() && lo < hi) {
            return Err(format!("MIN must be below MAX in {s:?}"));
        }
        Ok((lo, hi))
    }
}

#[derive(Clone, Copy, ValueEnum)]
enum Model {
    /// MonSter++ (accuracy model), weights from --weights.
    Monsterpp,
}

#[derive(Args)]
#[command(
    after_help = "Methods: census + SGM by default (--method sgm, needs a disparity range); the \
    MonSter++ network with --model monsterpp --weights FILE (the released .pth checkpoints are \
    --config vitl; no range needed, disparities up to --max-disp).\n\n\
    MonSter++ expects 8-bit RGB values (0–255): grey images are repeated to RGB, alpha is dropped; \
    rescale uint16 satellite images with --normalise percentile (2–98th percentile → 0–255). \
    Pixels with NaN in the left image are NaN in the output. Sizes are padded to multiples of 32 \
    (replicate, as upstream). One forward pass may use at most --net-memory; larger pairs are cut \
    into overlapping strips of full rows (epipolar lines) that are blended.\n\n\
    Examples:\n  seasonstereo predict --method sgm --range 0:48 L.iio R.iio -o d.iio\n  \
    seasonstereo predict --model monsterpp --weights mix_all.pth --config vitl --iters 32 \
    L.iio R.iio -o d.iio --color d.png"
)]
struct PredictArgs {
    /// Left image of the rectified pair (.iio/.npy, .tif, .png, .pfm).
    left: PathBuf,
    /// Right image of the rectified pair, same size as the left one.
    right: PathBuf,
    /// Output disparity; the extension picks the format: .iio/.npy, .tif, .pfm keep the values
    /// (NaN = invalid); .png writes a colour-mapped picture.
    #[arg(short, long)]
    output: PathBuf,
    /// Classical matching method (when no --model is given).
    #[arg(long, value_enum, default_value_t = Method::Mgm)]
    method: Method,
    #[command(flatten)]
    net: NetworkArgs,
    /// Disparity search range MIN:MAX (inclusive, pixels), e.g. from the cameras and an altitude
    /// range. Estimated from the images when absent (less reliable on multi-date pairs). SGM only.
    #[arg(long, value_parser = parse_range, allow_hyphen_values = true, conflicts_with = "model")]
    range: Option<(i32, i32)>,
    /// Also write a colour-mapped picture of the disparity to this PNG.
    #[arg(long)]
    color: Option<PathBuf>,
    #[command(flatten)]
    sgm: SgmArgs,
}

/// The stereo network options shared by `predict` and `eval`.
#[derive(Args)]
struct NetworkArgs {
    /// Use a stereo network instead of the classical matcher.
    #[arg(long, value_enum, requires = "weights")]
    model: Option<Model>,
    /// Network weights: an upstream MonSter++ .pth checkpoint or safetensors.
    #[arg(long, value_name = "FILE", requires = "model")]
    weights: Option<PathBuf>,
    /// Network configuration matching the weights: vitl (released checkpoints), vitb, vits, tiny.
    #[arg(long = "config", value_name = "PRESET", default_value = "vitl",
          value_parser = ["vitl", "vitb", "vits", "tiny"])]
    net_config: String,
    /// Refinement iterations of the network (≥ 7). Default: 32 (8 for tiny).
    #[arg(long, value_name = "N")]
    iters: Option<usize>,
    /// Maximum disparity of the network, a multiple of 32, pixels. Default: 416 (64 for tiny).
    #[arg(long, value_name = "PX")]
    max_disp: Option<usize>,
    /// Input values for the network: as-is (0–255 data), percentile (2–98th percentile of each
    /// image → 0–255, for uint16 imagery) or percentile:LO:HI.
    #[arg(long, value_name = "MODE", default_value = "as-is",
          value_parser = nn::infer::Normalisation::parse)]
    normalise: nn::infer::Normalisation,
    /// Peak memory of one network pass, GiB; larger pairs are cut into strips of rows.
    #[arg(long, value_name = "GIB", default_value_t = 8.0)]
    net_memory: f64,
    /// Cut the pair into strips of ROWS rows for the network, whatever the memory budget.
    #[arg(long, value_name = "ROWS")]
    strip_rows: Option<usize>,
    /// Overlap of consecutive strips, rows (blended linearly).
    #[arg(long, value_name = "ROWS", default_value_t = nn::infer::DEFAULT_TILE_OVERLAP)]
    strip_overlap: usize,
    #[command(flatten)]
    device: stages::DeviceArg,
}

impl NetworkArgs {
    fn monster_options(&self) -> Result<pipeline::predict::MonsterOptions> {
        let weights = self
            .weights
            .clone()
            .context("--weights is required with --model")?;
        if self.net_memory.is_nan() || self.net_memory <= 0.0 {
            bail!("--net-memory must be positive (got {})", self.net_memory);
        }
        let mut o = pipeline::predict::MonsterOptions::new(weights, &self.net_config);
        o.iters = self.iters;
        o.max_disp = self.max_disp;
        o.normalisation = self.normalise;
        o.memory_budget = (self.net_memory * (1u64 << 30) as f64) as u64;
        o.tile_rows = self.strip_rows;
        o.tile_overlap = self.strip_overlap;
        o.device = self.device.name.clone();
        Ok(o)
    }
}

#[derive(Args)]
struct SgmArgs {
    /// SGM penalty of ±1 px disparity changes (census bits).
    #[arg(long, default_value_t = SgmParams::default().p1)]
    p1: u16,
    /// SGM penalty of larger disparity jumps (census bits).
    #[arg(long, default_value_t = SgmParams::default().p2)]
    p2: u16,
    /// Use 4 aggregation paths instead of 8 (faster, slightly less accurate).
    #[arg(long)]
    four_paths: bool,
    /// Left-right consistency tolerance, pixels; 0 disables the check.
    #[arg(long, default_value_t = SgmParams::default().lr_tolerance.unwrap_or(0.0))]
    lr_tolerance: f32,
    /// Gradient adaptation of P2 (jumps are cheaper across intensity edges; smaller = stronger);
    /// 0 keeps P2 constant.
    #[arg(long, value_name = "K", default_value_t = SgmParams::default().p2_adaptive.unwrap_or(0.0))]
    p2_adaptive: f32,
    /// Census window WxH (odd sides, at most 65 pixels).
    #[arg(long, value_name = "WxH", value_parser = parse_census,
          default_value_t = format_census(SgmParams::default().census))]
    census: String,
    /// Uniqueness ratio: the best cost must beat the best one more than 1 px away by this share;
    /// 0 disables the test.
    #[arg(long, value_name = "U", default_value_t = SgmParams::default().uniqueness.unwrap_or(0.0))]
    uniqueness: f32,
    /// Speckle filter: connected regions of disparity smaller than this many pixels are removed
    /// (they survive the left-right check on real pairs and dominate a highest-point DSM); 0
    /// keeps them.
    #[arg(long, value_name = "PX", default_value_t = SgmParams::default().speckle.map_or(0, |s| s.min_area))]
    speckle: usize,
    /// Largest disparity step between neighbours of one speckle region, pixels.
    #[arg(long, value_name = "PX", default_value_t = SgmParams::default().speckle.map_or(1.0, |s| s.max_diff))]
    speckle_diff: f32,
}

fn format_census(c: matching::CensusWindow) -> String {
    format!("{}x{}", c.width, c.height)
}

fn parse_census(s: &str) -> Result<String, String> {
    census_window(s).map(|_| s.to_string())
}

fn census_window(s: &str) -> Result<matching::CensusWindow, String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("expected WxH, e.g. 9x7, got {s:?}"))?;
    let parse = |v: &str| {
        v.trim()
            .parse::<usize>()
            .map_err(|e| format!("{v:?} in {s:?}: {e}"))
    };
    let c = matching::CensusWindow {
        width: parse(w)?,
        height: parse(h)?,
    };
    if !c.is_valid() {
        return Err(format!(
            "census window {s:?} needs odd sides and at most 65 pixels"
        ));
    }
    Ok(c)
}

impl SgmArgs {
    /// The matcher's parameters with the default aggregation (MGM).
    fn params(&self) -> Result<SgmParams> {
        self.params_for(Method::Mgm)
    }

    /// The matcher's parameters for `method`.
    fn params_for(&self, method: Method) -> Result<SgmParams> {
        if self.p1 == 0 || self.p2 <= self.p1 {
            bail!(
                "SGM penalties must satisfy 0 < --p1 < --p2 (got {} and {})",
                self.p1,
                self.p2
            );
        }
        Ok(SgmParams {
            p1: self.p1,
            p2: self.p2,
            aggregation: method.aggregation(),
            paths: if self.four_paths {
                Paths::Four
            } else {
                Paths::Eight
            },
            lr_tolerance: (self.lr_tolerance > 0.0).then_some(self.lr_tolerance),
            p2_adaptive: (self.p2_adaptive > 0.0).then_some(self.p2_adaptive),
            census: census_window(&self.census).map_err(anyhow::Error::msg)?,
            uniqueness: (self.uniqueness > 0.0).then_some(self.uniqueness),
            speckle: (self.speckle > 1).then_some(matching::Speckle {
                min_area: self.speckle,
                max_diff: self.speckle_diff,
            }),
            ..SgmParams::default()
        })
    }
}

#[derive(Clone, Copy, ValueEnum)]
enum EvalMethod {
    /// Census + MGM on each (cropped) rectified pair, range from the cameras.
    Mgm,
    /// Census + SGM on each (cropped) rectified pair, range from the cameras.
    Sgm,
    /// The split's own disparity/<stem>.iio (LiDAR-derived): the error of the chain itself.
    GroundTruth,
}

#[derive(Args)]
#[command(
    after_help = "Layout: SPLIT_DIR/{L,R}/<stem>.iio, SPLIT_DIR/homography/<stem>.npz, optional \
    SPLIT_DIR/disparity/<stem>.iio; <stem> = <LEFTID>-<RIGHTID>; RPC_DIR/<IMAGEID>.json (SatNeRF/rpcm); \
    TRUTH_DIR/<AOI>_DSM.tif, <AOI>_CLS.tif, optional <AOI>_WATER.png. Outputs: OUT/pairs.csv (one row \
    per method, split and pair), OUT/table1.md, OUT/dsm/<method>/<split>/<stem>.tif with --save-dsm.\n\n\
    Example: seasonstereo eval --split Jacksonville=test/jax --split \"Omaha Diach.\"=test/oma_dia \
    --rpc-dir root_dir --truth-dir Track3-Truth --predictions preds/monster -o out/eval"
)]
struct EvalArgs {
    /// A test split NAME=DIR (repeat). Table 1's names: Jacksonville, "Buenos Aires",
    /// "Omaha Synch.", "Omaha Diach." (aliases jax, ba, omaha-sync, omaha-dia); other names get
    /// columns of their own. Omaha splits drop pairs whose true disparity exceeds the limit.
    #[arg(long = "split", value_name = "NAME=DIR", value_parser = pipeline::eval::Split::parse,
          required_unless_present = "world")]
    splits: Vec<pipeline::eval::Split>,
    /// Evaluate a folder written by `seasonstereo world` (split "World", DIR/rpc, DIR/truth).
    #[arg(long, value_name = "DIR", conflicts_with_all = ["splits", "rpc_dir", "truth_dir"])]
    world: Option<PathBuf>,
    /// Folder of the cameras <IMAGEID>.json (SatNeRF/rpcm JSON, the `root_dir`).
    #[arg(long, value_name = "DIR", required_unless_present = "world")]
    rpc_dir: Option<PathBuf>,
    /// Folder of the ground truth <AOI>_DSM.tif (GeoTIFF, or the DFC2019 plain TIFF with its
    /// <AOI>_DSM.txt georeference beside it: the UTM zone is taken from the pair's cameras),
    /// <AOI>_CLS.tif, <AOI>_WATER.png.
    #[arg(long, value_name = "DIR", required_unless_present = "world")]
    truth_dir: Option<PathBuf>,
    /// Compute the disparities with this method (or with --model)...
    #[arg(long, value_enum, default_value_t = EvalMethod::Mgm)]
    method: EvalMethod,
    /// ...or read them from DIR/[<SPLIT>/]<stem>.{iio,npy,tif,pfm} (full rectified or crop size).
    #[arg(long, value_name = "DIR", conflicts_with_all = ["method", "model"])]
    predictions: Option<PathBuf>,
    /// Row name of the method in the CSV and Table 1 (default: from the method or DIR).
    #[arg(long)]
    name: Option<String>,
    /// Output folder.
    #[arg(short, long, default_value = "out/eval")]
    output: PathBuf,
    /// Also write each predicted DSM as a GeoTIFF on the ground truth's grid.
    #[arg(long)]
    save_dsm: bool,
    /// Evaluate at most the first N pairs (by stem) of each split.
    #[arg(long, value_name = "N")]
    max_pairs: Option<usize>,
    /// AOI of an image id = its first N '_'-separated fields (JAX_068_001_RGB → JAX_068 with 2).
    #[arg(long, value_name = "N", default_value_t = 2, value_parser = clap::value_parser!(u16).range(1..))]
    aoi_fields: u16,
    /// Put every pair in this AOI instead (one ground-truth DSM for all).
    #[arg(long, value_name = "AOI", conflicts_with = "aoi_fields")]
    aoi: Option<String>,
    /// Centre-crop rectified pairs larger than this, pixels.
    #[arg(long, default_value_t = 1024)]
    crop: usize,
    /// Omaha pairs whose ground-truth disparity exceeds this are dropped, pixels.
    #[arg(long, default_value_t = pipeline::eval::aggregate::OMAHA_MAX_DISPARITY)]
    omaha_max_disparity: f64,
    /// Scoring rules: `release` = the benchmark's released evaluator exactly (per-score
    /// registration on the masked truth, its NCC pyramid, _WATER.png 0 = water, truth nodata not
    /// masked); `robust` = one registration on the whole truth, NaN for the truth's nodata, a
    /// centre-preferring NCC with a minimum overlap (rows named "<method> [robust]").
    #[arg(long, value_name = "release|robust", default_value = "release",
          value_parser = pipeline::eval::Protocol::parse)]
    protocol: pipeline::eval::Protocol,
    #[command(flatten)]
    sgm: SgmArgs,
    #[command(flatten)]
    net: NetworkArgs,
}

fn parse_range(s: &str) -> Result<(i32, i32), String> {
    let (a, b) = s
        .split_once(':')
        .ok_or_else(|| format!("expected MIN:MAX, e.g. -10:54, got {s:?}"))?;
    let parse = |v: &str| {
        v.trim()
            .parse::<i32>()
            .map_err(|e| format!("{v:?} in {s:?}: {e}"))
    };
    let (lo, hi) = (parse(a)?, parse(b)?);
    if lo > hi {
        return Err(format!("MIN must not exceed MAX in {s:?}"));
    }
    Ok((lo, hi))
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> Result<()> {
    let progress = bars::Bars::default();
    match cli.command {
        Command::World(a) => {
            let params = world::WorldParams::new(a.size, a.seed);
            let world = track(&progress, "rendering the world", a.size, |cb| {
                world::generate(&params, &world::Neutral, cb)
            })
            .map_err(anyhow::Error::msg)?;
            let name = a.name.unwrap_or_else(|| format!("WORLD_{}", a.seed));
            let paths = pipeline::world_io::save_world(&world, &a.output, &name)?;
            if a.raw {
                let (l, r) = pipeline::world_io::save_raw_views(&world, &a.output, &name)?;
                println!("raw views: {} {}", l.display(), r.display());
            }
            let (lo, hi) = world.disparity_range();
            println!(
                "wrote pair {} to {} ({}x{} px, disparity range {lo}..{hi} px, {:.1} % occluded)",
                paths.stem,
                a.output.display(),
                a.size,
                a.size,
                100.0 * world.occluded.count() as f64 / (a.size * a.size) as f64
            );
        }
        Command::Rectify(a) => {
            let opts = pipeline::rectify::RectifyOptions {
                left: a.left,
                right: a.right,
                out_dir: a.output,
                roi: a.roi,
                rpc_left: a.rpc_left,
                rpc_right: a.rpc_right,
                alt_range: a.alt_range,
                stem: a.stem,
            };
            let s = pipeline::rectify::rectify(&opts, &progress)?;
            let (lo, hi) = s.disparity_range;
            println!(
                "wrote pair {} ({}x{} px) to {}: disparity range {lo}:{hi} px for altitudes {}:{} m ({}, {:.3} px/m), rows aligned to {:.3} px",
                s.stem, s.size.0, s.size.1, opts.out_dir.display(), s.alt_range.0, s.alt_range.1,
                s.alt_source, s.pixels_per_metre, s.max_row_error
            );
            if s.right_coverage < 0.5 {
                println!(
                    "warning: the right image covers only {:.0} % of the region",
                    100.0 * s.right_coverage
                );
            }
            println!(
                "next: seasonstereo predict --range {lo}:{hi} {} {} -o {}",
                s.left.display(),
                s.right.display(),
                opts.out_dir
                    .join("disparity")
                    .join(format!("{}.iio", s.stem))
                    .display()
            );
        }
        Command::Predict(a) => {
            let (left, right) = read_pair(&a.left, &a.right)?;
            let (disparity, what) = match a.net.model {
                Some(Model::Monsterpp) => {
                    let opts = a.net.monster_options()?;
                    eprintln!(
                        "loading MonSter++ `{}` from {}",
                        opts.preset,
                        opts.weights.display()
                    );
                    let predictor = opts.load()?;
                    let d = predict_monster(&predictor, &left, &right, &progress)?;
                    (
                        d,
                        format!("MonSter++ {}, {} iterations", opts.preset, predictor.iters),
                    )
                }
                None => {
                    let params = a.sgm.params_for(a.method)?;
                    let (d, (lo, hi)) = predict_sgm(&left, &right, a.range, &params, &progress)?;
                    (d, format!("range {lo}..{hi} px"))
                }
            };
            write_disparity(&a.output, &disparity)
                .with_context(|| format!("writing {}", a.output.display()))?;
            if let Some(c) = &a.color {
                write_disparity(c, &disparity)
                    .with_context(|| format!("writing {}", c.display()))?;
            }
            let valid = disparity.data().iter().filter(|v| v.is_finite()).count();
            println!(
                "wrote {} ({what}, {:.1} % of pixels matched)",
                a.output.display(),
                100.0 * valid as f64 / disparity.data().len().max(1) as f64
            );
        }
        Command::Dsm(a) => dsm::run(a)?,
        Command::Reconstruct(a) => reconstruct::run(a, &progress)?,
        Command::Score(a) => reconstruct::run_score(a)?,
        Command::Bench(a) => bench::run(a)?,
        Command::Teacher(a) => stages::run_teacher(a, &progress)?,
        Command::Curate(a) => stages::run_curate(a, &progress)?,
        Command::Masks(a) => stages::run_masks(a, &progress)?,
        Command::MasksScore(a) => stages::run_masks_score(a)?,
        Command::Synthesize(a) => dataset::run_synthesize_command(a, &progress)?,
        Command::Dataset(a) => dataset::run_dataset(a, &progress)?,
        Command::Train(a) => train::run(a)?,
        Command::Demo(a) => demo::run(a, &progress)?,
        Command::Eval(a) => {
            use pipeline::eval::{evaluate, AoiRule, EvalOptions, Method as M};
            let method = match (&a.predictions, a.method) {
                (Some(dir), _) => M::Predictions(dir.clone()),
                (None, _) if a.net.model.is_some() => {
                    let o = a.net.monster_options()?;
                    eprintln!(
                        "loading MonSter++ `{}` from {}",
                        o.preset,
                        o.weights.display()
                    );
                    M::Network(pipeline::eval::Network {
                        name: format!("MonSter++ ({})", o.preset),
                        predictor: std::sync::Arc::new(o.load()?),
                    })
                }
                (None, EvalMethod::Mgm) => M::Sgm(a.sgm.params_for(Method::Mgm)?),
                (None, EvalMethod::Sgm) => M::Sgm(a.sgm.params_for(Method::Sgm)?),
                (None, EvalMethod::GroundTruth) => M::GroundTruth,
            };
            let mut opts = match &a.world {
                Some(dir) => EvalOptions::world(dir, "World", method, &a.output),
                None => EvalOptions::new(
                    a.splits,
                    a.rpc_dir.context("--rpc-dir is required")?,
                    a.truth_dir.context("--truth-dir is required")?,
                    method,
                    &a.output,
                ),
            };
            match a.name {
                Some(n) => opts.method_name = n,
                None if a.protocol != pipeline::eval::Protocol::Release => {
                    opts.method_name = format!("{} [{}]", opts.method_name, a.protocol.name());
                }
                None => {}
            }
            opts.protocol = a.protocol;
            opts.save_dsm = a.save_dsm;
            opts.max_pairs = a.max_pairs;
            opts.aoi_rule = a
                .aoi
                .map_or(AoiRule::Fields(a.aoi_fields as usize), AoiRule::Fixed);
            opts.crop = a.crop;
            opts.omaha_max_disparity = a.omaha_max_disparity;
            let r = evaluate(&opts, &progress)?;
            println!("{}", r.table.to_text());
            println!(
                "{} pairs scored, {} already scored (skipped), {} dropped (Omaha disparity > {}); per pair: {}; table: {}",
                r.scored, r.skipped, r.dropped, opts.omaha_max_disparity, r.csv.display(), r.markdown.display()
            );
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use clap::CommandFactory;

    /// clap's consistency checks (unique argument ids, valid defaults, …) of every subcommand,
    /// which otherwise only fire when that subcommand is parsed.
    #[test]
    fn command_line_definition_is_consistent() {
        super::Cli::command().debug_assert();
    }
}

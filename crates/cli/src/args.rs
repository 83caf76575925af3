//! Arguments shared by several subcommands: the matcher (classical parameters, the network and
//! its device), `--shard`, and the value parsers of ranges, regions and boxes.
//!
//! Help layout: a doc comment's first paragraph is the option's line in `-h` (one short
//! sentence), the whole comment its entry in `--help`. Options are grouped under the headings of
//! [`heading`]; the tuning knobs are `hide_short_help` (listed by `--help` only, under headings of
//! their own).

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use clap::builder::TypedValueParser;
use clap::{Args, ValueEnum};
use seasonstereo::defaults;
use seasonstereo::flags::{self, census_window, format_census, ClassicalFlags};
use seasonstereo::stages::BatchSummary;
use seasonstereo::{
    Aggregation, DeviceChoice, GridChoice, Gridding, Matcher, MonsterOptions, Normalisation, Roi,
    SgmParams, Shard,
};

/// The headings of the options in `-h` and `--help`. The first six group what most runs need
/// (all that `reconstruct -h` shows); the others the tuning knobs, which `reconstruct -h` leaves
/// to `--help` (a test checks both).
pub mod heading {
    pub const INPUTS: &str = "Inputs";
    pub const OUTPUTS: &str = "Outputs";
    pub const REGION: &str = "Region";
    pub const QUALITY: &str = "Quality";
    pub const PERFORMANCE: &str = "Performance";
    pub const CLUSTER: &str = "Cluster";
    /// The matcher, the network and the cameras' correction (`-h` shows the matcher's choice
    /// in `predict`, `teacher` and `eval`; `reconstruct -h` none of it).
    pub const MATCHING: &str = "Matching and network";
    /// The classical matcher's parameters (`--help` only).
    pub const CLASSICAL: &str = "Classical matcher tuning";
    /// How points become heights, and their vertical reference (`--help` only).
    pub const GRID: &str = "Grid and heights";
    /// How `reconstruct-many` fuses the pairs' heights (`--help` only).
    pub const FUSION: &str = "Fusion";
    /// Hole filling and smoothing of the DSM (`--help` only).
    pub const FINISHING: &str = "Finishing";
    /// The orthoimage's colours and the kept intermediates (`--help` only).
    pub const PRODUCTS: &str = "Products";
}

/// The classical matcher: census costs aggregated by MGM or SGM, then the left-right check,
/// uniqueness, median and speckle filters.
#[derive(Clone, Copy, ValueEnum)]
pub enum Method {
    /// More Global Matching (Facciolo et al. 2015, as s2p): the default, best on real pairs.
    Mgm,
    /// Semi-Global Matching over 8 (or --four-paths 4) straight paths: faster.
    Sgm,
}

impl Method {
    pub fn aggregation(self) -> Aggregation {
        match self {
            Method::Mgm => Aggregation::Mgm,
            Method::Sgm => Aggregation::Sgm,
        }
    }
}

#[derive(Clone, Copy, ValueEnum)]
pub enum Model {
    /// MonSter++ (accuracy model), weights from --weights.
    Monsterpp,
}

/// How the points of one DSM cell become its height.
#[derive(Clone, Copy, ValueEnum)]
pub enum GriddingArg {
    /// Highest point per cell: the benchmark's protocol; one wrong point above a roof decides
    /// the cell.
    Max,
    /// Median of the points per cell: robust to isolated wrong points.
    Median,
}

impl From<GriddingArg> for Gridding {
    fn from(g: GriddingArg) -> Self {
        match g {
            GriddingArg::Max => Gridding::Max,
            GriddingArg::Median => Gridding::Median,
        }
    }
}

/// The matcher of a stage: census + MGM/SGM, or MonSter++ with weights.
#[derive(Args)]
pub struct MatcherArgs {
    /// Classical matching method (when no --model is given).
    #[arg(long, value_enum, default_value_t = Method::Mgm, help_heading = heading::MATCHING)]
    pub method: Method,
    #[command(flatten)]
    pub net: NetworkArgs,
    #[command(flatten)]
    pub sgm: SgmArgs,
}

impl MatcherArgs {
    /// The matcher the flags choose (the network loaded).
    pub fn matcher(&self) -> Result<Matcher> {
        match self.net.network()? {
            Some(network) => Ok(network),
            None => Ok(Matcher::Classical(
                self.sgm.params(self.method.aggregation())?,
            )),
        }
    }
}

/// The stereo network options shared by `predict` and `eval`: `--model` and `--weights` show in
/// `-h`, the network's tuning (and `--device`) only in `--help`.
#[derive(Args)]
#[command(mut_arg("device", |a| a.help_heading(heading::MATCHING).hide_short_help(true)))]
pub struct NetworkArgs {
    /// Use a stereo network instead of the classical matcher.
    #[arg(long, value_enum, requires = "weights", help_heading = heading::MATCHING)]
    pub model: Option<Model>,
    /// Network weights: an upstream MonSter++ .pth checkpoint or safetensors.
    #[arg(long, value_name = "FILE", requires = "model", help_heading = heading::MATCHING)]
    weights: Option<PathBuf>,
    /// Network configuration matching the weights.
    ///
    /// vitl (the released checkpoints), vitb, vits or tiny.
    #[arg(long = "config", value_name = "PRESET", default_value = "vitl",
          value_parser = ["vitl", "vitb", "vits", "tiny"],
          help_heading = heading::MATCHING, hide_short_help = true)]
    net_config: String,
    /// Refinement iterations of the network (≥ 7).
    ///
    /// Default: 32 (8 for tiny).
    #[arg(long, value_name = "N", help_heading = heading::MATCHING, hide_short_help = true)]
    iters: Option<usize>,
    /// Maximum disparity of the network, pixels.
    ///
    /// A multiple of 32. Default: 416 (64 for tiny).
    #[arg(long, value_name = "PX", help_heading = heading::MATCHING, hide_short_help = true)]
    max_disp: Option<usize>,
    /// Input values for the network.
    ///
    /// as-is (0–255 data), percentile (2–98th percentile of each image → 0–255, for uint16
    /// imagery) or percentile:LO:HI.
    #[arg(long, value_name = "MODE", default_value = "as-is",
          value_parser = Normalisation::parse,
          help_heading = heading::MATCHING, hide_short_help = true)]
    normalise: Normalisation,
    /// Peak memory of one network pass, GiB.
    ///
    /// Larger pairs are cut into strips of rows.
    #[arg(long, value_name = "GIB", default_value_t = 8.0,
          help_heading = heading::MATCHING, hide_short_help = true)]
    net_memory: f64,
    /// Cut the pair into strips of ROWS rows for the network, whatever the memory budget.
    #[arg(long, value_name = "ROWS", help_heading = heading::MATCHING, hide_short_help = true)]
    strip_rows: Option<usize>,
    /// Overlap of consecutive strips, rows (blended linearly).
    #[arg(long, value_name = "ROWS", default_value_t = defaults::NETWORK_TILE_OVERLAP,
          help_heading = heading::MATCHING, hide_short_help = true)]
    strip_overlap: usize,
    #[command(flatten)]
    pub device: DeviceArg,
}

impl NetworkArgs {
    /// MonSter++ loaded from --weights, when --model is given.
    pub fn network(&self) -> Result<Option<Matcher>> {
        if self.model.is_none() {
            return Ok(None);
        }
        let o = self.monster_options()?;
        eprintln!(
            "loading MonSter++ `{}` from {}",
            o.preset,
            o.weights.display()
        );
        Ok(Some(Matcher::Network(o.load()?)))
    }

    fn monster_options(&self) -> Result<MonsterOptions> {
        let weights = self
            .weights
            .clone()
            .context("--weights is required with --model")?;
        if self.net_memory.is_nan() || self.net_memory <= 0.0 {
            bail!("--net-memory must be positive (got {})", self.net_memory);
        }
        let mut o = MonsterOptions::new(weights, &self.net_config);
        o.iters = self.iters;
        o.max_disp = self.max_disp;
        o.normalisation = self.normalise;
        o.memory_budget = (self.net_memory * (1u64 << 30) as f64) as u64;
        o.tile_rows = self.strip_rows;
        o.tile_overlap = self.strip_overlap;
        o.device = self.device.device;
        Ok(o)
    }
}

/// The classical matcher's parameters: tuning knobs, listed by `--help` only.
#[derive(Args)]
pub struct SgmArgs {
    /// SGM penalty of ±1 px disparity changes (census bits).
    #[arg(long, default_value_t = SgmParams::default().p1,
          help_heading = heading::CLASSICAL, hide_short_help = true)]
    p1: u16,
    /// SGM penalty of larger disparity jumps (census bits).
    ///
    /// `reconstruct` and `reconstruct-many` scale it by the square of the disparity per metre of
    /// altitude on tiles under 1 px/m (narrow baselines, where roof edges are jumps of a few
    /// pixels; each tile record says the P2 it used).
    #[arg(long, default_value_t = SgmParams::default().p2,
          help_heading = heading::CLASSICAL, hide_short_help = true)]
    p2: u16,
    /// Use 4 aggregation paths instead of 8 (faster, slightly less accurate).
    #[arg(long, help_heading = heading::CLASSICAL, hide_short_help = true)]
    four_paths: bool,
    /// Left-right consistency tolerance, pixels; 0 disables the check.
    #[arg(long, default_value_t = SgmParams::default().lr_tolerance.unwrap_or(0.0),
          help_heading = heading::CLASSICAL, hide_short_help = true)]
    lr_tolerance: f32,
    /// Gradient adaptation of P2; 0 keeps P2 constant.
    ///
    /// Jumps are cheaper across intensity edges; smaller = stronger.
    #[arg(long, value_name = "K", default_value_t = SgmParams::default().p2_adaptive.unwrap_or(0.0),
          help_heading = heading::CLASSICAL, hide_short_help = true)]
    p2_adaptive: f32,
    /// Census window WxH (odd sides, at most 65 pixels).
    #[arg(long, value_name = "WxH", value_parser = parse_census,
          default_value_t = format_census(SgmParams::default().census),
          help_heading = heading::CLASSICAL, hide_short_help = true)]
    census: String,
    /// Uniqueness ratio; 0 disables the test.
    ///
    /// The best cost must beat the best one more than 1 px away by this share.
    #[arg(long, value_name = "U", default_value_t = SgmParams::default().uniqueness.unwrap_or(0.0),
          help_heading = heading::CLASSICAL, hide_short_help = true)]
    uniqueness: f32,
    /// Speckle filter: smallest region of disparity kept, pixels; 0 keeps every region.
    ///
    /// Connected regions of disparity smaller than this are removed: they survive the
    /// left-right check on real pairs and dominate a highest-point DSM.
    #[arg(long, value_name = "PX", default_value_t = SgmParams::default().speckle.map_or(0, |s| s.min_area),
          help_heading = heading::CLASSICAL, hide_short_help = true)]
    speckle: usize,
    /// Largest disparity step between neighbours of one speckle region, pixels.
    #[arg(long, value_name = "PX", default_value_t = SgmParams::default().speckle.map_or(1.0, |s| s.max_diff),
          help_heading = heading::CLASSICAL, hide_short_help = true)]
    speckle_diff: f32,
}

fn parse_census(s: &str) -> Result<String, String> {
    census_window(s).map(|_| s.to_string())
}

impl SgmArgs {
    /// The classical matcher's parameters with `aggregation`.
    pub fn params(&self, aggregation: Aggregation) -> Result<SgmParams> {
        ClassicalFlags {
            method: aggregation,
            p1: self.p1,
            p2: self.p2,
            four_paths: self.four_paths,
            lr_tolerance: self.lr_tolerance,
            p2_adaptive: self.p2_adaptive,
            census: census_window(&self.census).map_err(anyhow::Error::msg)?,
            uniqueness: self.uniqueness,
            speckle: self.speckle,
            speckle_diff: self.speckle_diff,
        }
        .params()
    }
}

/// `MIN:MAX`, an inclusive disparity range in pixels.
pub fn parse_range(s: &str) -> Result<(i32, i32), String> {
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

/// `X,Y,W,H`, a region of a raw image in pixels.
pub fn parse_roi(s: &str) -> Result<Roi, String> {
    let v: Vec<usize> = s
        .split(',')
        .map(|t| {
            t.trim()
                .parse::<usize>()
                .map_err(|e| format!("{t:?} in {s:?}: {e}"))
        })
        .collect::<Result<_, _>>()?;
    match v[..] {
        [x, y, w, h] if w > 0 && h > 0 => Ok(Roi::new(x, y, w, h)),
        _ => Err(format!(
            "expected X,Y,W,H with W, H > 0, e.g. 150,150,700,700, got {s:?}"
        )),
    }
}

/// `MIN:MAX`, the scene's altitudes in metres.
pub fn parse_alt_range(s: &str) -> Result<(f64, f64), String> {
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

/// `--shard i/n`, shared by the stages.
#[derive(Args)]
pub struct ShardArg {
    /// Process only shard I of N (0 ≤ I < N), for array jobs.
    ///
    /// The items at positions ≡ I mod N of the sorted list (Slurm: --shard
    /// $SLURM_ARRAY_TASK_ID/$N; Kubernetes indexed jobs: --shard $JOB_COMPLETION_INDEX/$N).
    /// Default: everything.
    #[arg(long, value_name = "I/N", default_value = "0/1", help_heading = heading::CLUSTER)]
    pub shard: Shard,
}

/// `--device`, shared by the commands that run a network.
#[derive(Args)]
pub struct DeviceArg {
    /// Where the network runs.
    ///
    /// auto (the best backend compiled in: cuda, then wgpu, then cpu), cpu, wgpu or cuda (GPU
    /// backends need the build features `wgpu` / `cuda`).
    #[arg(
        id = "device",
        long = "device",
        value_name = "DEVICE",
        default_value = "auto",
        value_parser = clap::builder::PossibleValuesParser::new(DeviceChoice::NAMES)
            .try_map(|s| s.parse::<DeviceChoice>())
    )]
    pub device: DeviceChoice,
}

/// The line every stage prints at its end.
pub fn report(what: &str, s: &BatchSummary) {
    println!(
        "{what}: {} processed, {} already done (skipped), {} in this shard of {} items",
        s.done, s.skipped, s.in_shard, s.total
    );
}

/// `XMIN,YMIN,XMAX,YMAX` with MIN < MAX: UTM bounds here, lon/lat bounds for `reconstruct
/// --roi-lonlat`; `names` spells the four values in the messages.
pub fn parse_box(s: &str, names: &str) -> Result<[f64; 4], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|p| {
            p.trim()
                .parse::<f64>()
                .map_err(|e| format!("{p:?} in {s:?}: {e}"))
        })
        .collect::<Result<_, _>>()?;
    match v[..] {
        [a, b, c, d] if a < c && b < d => Ok([a, b, c, d]),
        [_, _, _, _] => Err(format!("{names} {s:?} must have each MIN < MAX")),
        _ => Err(format!("expected {names}, got {s:?}")),
    }
}

/// A tile side: 64 pixels at least, as the library requires, refused here so that
/// `reconstruct-many` does not start its pairs to see each one fail.
fn parse_tile(s: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(t) if t >= 64 => Ok(t),
        Ok(t) => Err(format!("{t} is too small: tiles need at least 64 pixels")),
        Err(e) => Err(format!("expected a number of pixels, got {s:?}: {e}")),
    }
}

/// A cell size in metres: positive and finite (0 would make a grid of infinitely many cells).
pub fn parse_resolution(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(r) if r.is_finite() && r > 0.0 => Ok(r),
        Ok(r) => Err(format!(
            "the cell size must be a positive number of metres, got {r}"
        )),
        Err(e) => Err(format!("expected a cell size in metres, got {s:?}: {e}")),
    }
}

/// How a pair is cut into tiles and how many run at once.
#[derive(Args)]
pub struct TilingArgs {
    /// Tile side, pixels of the left image.
    ///
    /// Each tile is rectified, matched and triangulated on its own (an affine rectification
    /// holds only over a small area) and the tiles are merged.
    #[arg(long, value_name = "PX", default_value_t = defaults::TILE,
          value_parser = parse_tile, help_heading = heading::PERFORMANCE)]
    pub tile: usize,
    /// Overlap collar around each tile, pixels.
    ///
    /// Context for the matcher: only the points of each tile's core are kept, so the collar
    /// never shows as a seam.
    #[arg(long, value_name = "PX", default_value_t = defaults::COLLAR,
          help_heading = heading::PERFORMANCE)]
    pub collar: usize,
    /// Memory budget of the process, GiB.
    ///
    /// Each tile's peak memory is estimated before it runs and only as many tiles as fit run
    /// at once (at most one per core).
    #[arg(long, value_name = "GIB", default_value_t = defaults::MEMORY_GIB,
          help_heading = heading::PERFORMANCE)]
    pub max_memory: f64,
}

impl TilingArgs {
    /// The memory budget in bytes.
    pub fn max_memory_bytes(&self) -> Result<u64> {
        flags::memory_bytes(self.max_memory)
    }
}

/// The DSM's grid: a reference DSM's, or a grid of a resolution over the scene in any CRS.
#[derive(Args)]
pub struct GridArgs {
    /// Use the grid of this DSM (e.g. the ground truth).
    ///
    /// Its origin, cell size, extent and CRS; a DFC2019 plain TIFF with its .txt georeference
    /// is accepted.
    #[arg(long, value_name = "DSM", conflicts_with_all = ["resolution", "epsg"],
          help_heading = heading::REGION)]
    pub like: Option<PathBuf>,
    /// Cell size on the ground, metres.
    ///
    /// Without --like; the grid then covers the scene. In a CRS whose unit is not a ground metre
    /// (degrees, Web Mercator, feet) it is converted at the scene's centre; the log says the
    /// size in the CRS's unit.
    #[arg(long, value_name = "M", default_value_t = flags::RESOLUTION,
          value_parser = parse_resolution, help_heading = heading::REGION)]
    pub resolution: f64,
    /// EPSG code of the DSM's CRS (default: the scene's UTM zone).
    ///
    /// Projected or geographic: 32617 (UTM 17N), 4326 (longitude/latitude), 3857 (Web
    /// Mercator), a national grid; without --like. Heights are above the WGS84 ellipsoid (the
    /// geoid with --heights egm96) in any CRS.
    #[arg(long, value_name = "CODE", help_heading = heading::REGION)]
    pub epsg: Option<u32>,
}

impl GridArgs {
    /// The library's grid choice.
    pub fn choice(&self) -> GridChoice {
        flags::grid(self.like.clone(), self.resolution, None, self.epsg)
    }
}

/// How the orthoimage picks a cell's colour among the views.
#[derive(Clone, Copy, ValueEnum)]
pub enum OrthoBlendArg {
    /// The most nadir view that sees the cell (the sharpest).
    Nadir,
    /// Per channel, the median of the views that see it (evens out the dates' lighting).
    Median,
}

/// The products written beside the DSM.
#[derive(Args)]
pub struct ProductArgs {
    /// Also write a true orthoimage on the DSM's grid here.
    ///
    /// An RGB GeoTIFF (uint8, nodata 0) with the DSM's georeference, each cell coloured from a
    /// view that sees it (occlusions found with the DSM), so roofs sit on their footprints.
    #[arg(long, value_name = "FILE.tif", help_heading = heading::OUTPUTS)]
    pub ortho: Option<PathBuf>,
    /// How the orthoimage picks a colour among the views (reconstruct-many: every image).
    #[arg(long, value_enum, default_value_t = OrthoBlendArg::Nadir,
          help_heading = heading::PRODUCTS, hide_short_help = true)]
    pub ortho_blend: OrthoBlendArg,
    /// Also write a point cloud here: .las, .laz or .ply.
    ///
    /// One point per measured cell (filled cells left out) at the cell's centre in the DSM's
    /// CRS, coloured from the views: `.las` (LAS 1.2, EPSG in its GeoTIFF keys), `.laz`
    /// (compressed) or `.ply` (binary, s2p's layout).
    #[arg(long, value_name = "FILE", help_heading = heading::OUTPUTS)]
    pub points: Option<PathBuf>,
    /// Also write a quicklook of the DSM here (PNG).
    ///
    /// The heights in colour over a hillshade (transparent where no height), at most 2048
    /// pixels a side.
    #[arg(long, value_name = "FILE.png", help_heading = heading::OUTPUTS)]
    pub preview: Option<PathBuf>,
    /// Vertical reference of the DSM's heights.
    ///
    /// `ellipsoid` (WGS84, as the cameras give them) or `egm96` (above the EGM96 geoid, ≈ mean
    /// sea level; computed from its degree-360 coefficients, nothing to download). --truth
    /// scores the ellipsoidal heights (the truth's), before the conversion. The GeoTIFF's
    /// metadata says which.
    #[arg(long, value_enum, default_value_t = HeightsArg::Ellipsoid,
          help_heading = heading::GRID, hide_short_help = true)]
    pub heights: HeightsArg,
}

/// The vertical reference of a DSM's heights.
#[derive(Clone, Copy, ValueEnum)]
pub enum HeightsArg {
    /// Above the WGS84 ellipsoid (EPSG:4979).
    Ellipsoid,
    /// Above the EGM96 geoid (EPSG:5773).
    Egm96,
}

impl ProductArgs {
    /// The library's products.
    pub fn products(&self) -> seasonstereo::Products {
        seasonstereo::Products {
            ortho: self.ortho.clone(),
            ortho_blend: match self.ortho_blend {
                OrthoBlendArg::Nadir => seasonstereo::OrthoBlend::MostNadir,
                OrthoBlendArg::Median => seasonstereo::OrthoBlend::Median,
            },
            points: self.points.clone(),
            preview: self.preview.clone(),
            heights: match self.heights {
                HeightsArg::Ellipsoid => seasonstereo::Heights::Ellipsoid,
                HeightsArg::Egm96 => seasonstereo::Heights::Egm96,
            },
        }
    }
}

/// The closing lines of `reconstruct` and `reconstruct-many`: the products written (when any
/// were asked for) and the DSM's scores against the truth (with `--truth`).
pub fn print_products_and_scores(
    products: &seasonstereo::Products,
    written: Option<&seasonstereo::ProductsWritten>,
    scores: Option<&seasonstereo::DsmScores>,
) {
    if let Some(written) = written {
        println!("{}", products_line(products, written));
    }
    if let Some(sc) = scores {
        println!("vs truth: {}", crate::score::format_scores(sc));
    }
}

/// What the log says of the products written: `wrote o.tif, p.las (1234 points) in 1.2 s`,
/// after the geoid conversion when asked.
pub fn products_line(
    products: &seasonstereo::Products,
    written: &seasonstereo::ProductsWritten,
) -> String {
    let names: Vec<String> = products
        .paths()
        .iter()
        .map(|p| match (&products.points, written.points) {
            (Some(points), Some(n)) if points == p => format!("{} ({n} points)", p.display()),
            _ => p.display().to_string(),
        })
        .collect();
    let mut done = Vec::new();
    if products.heights == seasonstereo::Heights::Egm96 {
        done.push("converted the DSM's heights to the EGM96 geoid".to_string());
    }
    if !names.is_empty() {
        done.push(format!("wrote {}", names.join(", ")));
    }
    format!("{} in {:.1} s", done.join("; "), written.seconds)
}

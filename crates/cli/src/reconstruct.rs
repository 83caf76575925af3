//! `seasonstereo reconstruct`: from a raw pair to a DSM, tile by tile.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use seasonstereo::{defaults, flags};
use seasonstereo::{
    reconstruct, DsmSummary, Progress, ReconstructOptions, ReconstructSummary, Roi, Shard,
    TileStatus,
};

use crate::args::{
    heading, parse_alt_range, parse_box, parse_roi, print_products_and_scores, GridArgs,
    GriddingArg, MatcherArgs, ProductArgs, ShardArg, TilingArgs,
};

/// `reconstruct -h`'s epilogue: the principal use, as it pastes.
const AFTER_HELP: &str = "\
Example (a vendor delivery: each image with its .RPB camera and .IMD beside it):
  D=../shared/data/dfc2019-jax068-dev
  seasonstereo reconstruct $D/vendor/JAX_068_006_RGB.TIF \\
      $D/vendor/JAX_068_020_RGB.TIF -o out/jax/006-020.tif

Every option, the steps and the files written: seasonstereo reconstruct --help";

/// `reconstruct --help`'s epilogue: the steps, the files a default run writes, examples.
const AFTER_LONG_HELP: &str = "\
Steps: the pair's pointing error is measured from tie points and removed (not for JSON cameras \
that carry the scene's altitudes; --no-pointing-correction). Then, tile by tile (--tile), the \
pair is rectified from the RPCs, the right image sheared so that one altitude has one \
disparity, and matched over the disparities that the scene's altitudes span (--alt-range): \
census + MGM by default (--method sgm; --model monsterpp --weights W). On very narrow baselines \
the classical matcher works on rows stretched 2x under 0.4 px of disparity per metre of \
altitude, and under 0.63 px/m matches from both views (--single-view). The points are \
triangulated with the full RPCs (s2p's iteration) and gridded, the median per cell \
(--gridding). The merged DSM's holes are filled near data (--fill-holes, --fill-reach) and it \
is median-filtered (--median-filter).

Files: OUTPUT (float32 COG), OUTPUT_filled.tif (0 measured, 1 filled, NaN no height), with the \
classical matcher OUTPUT_confidence.tif, and the products asked for (--ortho, --points, \
--preview). The work folder (--work, default OUTPUT_work/) holds scene.json and tiles/ (each \
tile's record and cells): a rerun resumes there, and --shard/--merge share it. \
--keep-intermediates adds each tile's rectified pair and disparity (L/, R/, homography/, \
rectify/, disparity/), the layout `seasonstereo eval` reads.

Examples:
  D=../shared/data/dfc2019-jax068-dev
  # A vendor delivery: each image with its .RPB camera and .IMD metadata beside it
  seasonstereo reconstruct $D/vendor/JAX_068_006_RGB.TIF \\
      $D/vendor/JAX_068_020_RGB.TIF -o out/jax/006-020.tif
  # On the truth's grid and scored against it, with an orthoimage and points
  seasonstereo reconstruct $D/vendor/JAX_068_006_RGB.TIF \\
      $D/vendor/JAX_068_020_RGB.TIF -o out/jax/006-020.tif \\
      --like $D/truth/JAX_068_DSM.tif --truth $D/truth/JAX_068_DSM.tif \\
      --ortho out/jax/006-020_ortho.tif --points out/jax/006-020.laz
  # Bundle-adjusted JSON cameras, used as given
  seasonstereo reconstruct $D/images/JAX_068_006_RGB.tif \\
      $D/images/JAX_068_020_RGB.tif -o out/jax/006-020-ba.tif \\
      --rpc-left $D/rpcs/ba/JAX_068_006_RGB.json \\
      --rpc-right $D/rpcs/ba/JAX_068_020_RGB.json";

#[derive(Args)]
#[command(
    after_help = AFTER_HELP,
    after_long_help = AFTER_LONG_HELP,
    // The matcher's choice shows in `predict -h`; here the default is what most runs need.
    mut_arg("method", |a| a.hide_short_help(true)),
    mut_arg("model", |a| a.hide_short_help(true)),
    mut_arg("weights", |a| a.hide_short_help(true)),
)]
pub struct ReconstructArgs {
    /// Left raw image; its camera is found beside it or in it.
    ///
    /// A TIFF/GeoTIFF (read in windows), or another raster the program reads. Its camera:
    /// --rpc-left when given, else a vendor sidecar beside it found as GDAL does (<stem>.RPB,
    /// <stem>_RPC.TXT, DIMAP RPC_*.XML), else the TIFF's RPC tag 50844.
    #[arg(help_heading = heading::INPUTS, display_order = 0)]
    left: PathBuf,
    /// Right raw image, idem (or --rpc-right).
    #[arg(help_heading = heading::INPUTS, display_order = 0)]
    right: PathBuf,
    /// Left camera file, instead of the one found with the image.
    ///
    /// A SatNeRF/rpcm JSON (`.json`; with min_alt/max_alt it is used as given, see
    /// --no-pointing-correction), a vendor .RPB, _RPC.TXT or DIMAP RPC_*.XML, or another
    /// GeoTIFF carrying the RPC tag 50844.
    #[arg(long, value_name = "CAMERA", help_heading = heading::INPUTS, display_order = 1)]
    rpc_left: Option<PathBuf>,
    /// Right camera file, instead of the one found with the image.
    ///
    /// Same kinds as --rpc-left.
    #[arg(long, value_name = "CAMERA", help_heading = heading::INPUTS, display_order = 1)]
    rpc_right: Option<PathBuf>,
    /// Output DSM (.tif): heights above the WGS84 ellipsoid, float32 COG.
    ///
    /// In the scene's UTM zone (or --epsg, or --like's grid); the geoid's heights with
    /// --heights egm96. By default the holes near data are filled (--fill-holes, --fill-reach)
    /// and the DSM median-filtered (--median-filter); cells left without a height are NaN.
    /// Beside it, on the same grid: `<stem>_filled.tif` (0 = measured cell, 1 = filled by hole
    /// filling, NaN = no height) and, with the classical matcher, `<stem>_confidence.tif`: each
    /// measured cell's matching confidence, 1 − S1/S2 (the winner's aggregated cost against its
    /// best rival more than a pixel away), 0 to 1, NaN elsewhere.
    #[arg(short, long, help_heading = heading::OUTPUTS)]
    output: PathBuf,
    /// Work folder, to resume (default: OUTPUT without extension + "_work").
    ///
    /// It holds scene.json and tiles/ (each tile's record and cells); a rerun finishes only the
    /// unfinished tiles, and sharded runs share it. A folder made with other settings is
    /// refused (cleared with --overwrite).
    #[arg(long, value_name = "DIR", help_heading = heading::OUTPUTS)]
    work: Option<PathBuf>,
    /// Region of the left image X,Y,W,H, pixels (default: the whole image).
    #[arg(long, value_name = "X,Y,W,H", value_parser = parse_roi, conflicts_with = "roi_lonlat",
          help_heading = heading::REGION)]
    roi: Option<Roi>,
    /// Region as lon/lat bounds, degrees.
    ///
    /// The left image's pixels that see it at any altitude of the scene.
    #[arg(long, value_name = "LON_MIN,LAT_MIN,LON_MAX,LAT_MAX", value_parser = parse_lonlat,
          allow_hyphen_values = true, help_heading = heading::REGION)]
    roi_lonlat: Option<[f64; 4]>,
    #[command(flatten)]
    grid: GridArgs,
    /// Scene altitudes MIN:MAX, metres (default: from cameras or tie points).
    ///
    /// The disparity search covers them and little more: heights outside are not found; give
    /// them wide enough for the tallest building. Default: min_alt/max_alt of the JSON cameras,
    /// else the altitudes of the tie points found to correct the pointing (their 3rd and 97th
    /// percentiles, each point being seen twice; widened by 5 m and a tenth of their span).
    #[arg(long, value_name = "MIN:MAX", value_parser = parse_alt_range, allow_hyphen_values = true,
          help_heading = heading::QUALITY)]
    alt_range: Option<(f64, f64)>,
    /// Score the DSM against this ground truth (needs --like on it).
    ///
    /// A ground truth <AOI>_DSM.tif (the classes <AOI>_CLS.tif beside it), with the benchmark's
    /// metric (MAE and coverage); --like must name the same file.
    #[arg(long, value_name = "DSM", requires = "like", help_heading = heading::QUALITY)]
    truth: Option<PathBuf>,
    #[command(flatten)]
    tiling: TilingArgs,
    #[command(flatten)]
    shard: ShardArg,
    /// Only assemble the DSM from the tiles in --work (after sharded runs).
    ///
    /// Fails naming the missing tiles, and (exit code 3) the failed ones unless
    /// --allow-partial.
    #[arg(long, help_heading = heading::CLUSTER)]
    merge: bool,
    /// Run this shard's tiles and stop, never assembling the DSM.
    ///
    /// For cluster jobs, whose merge is a task of its own; exit code 2 when some of them
    /// failed.
    #[arg(long, conflicts_with = "merge", help_heading = heading::CLUSTER)]
    tiles_only: bool,
    #[command(flatten)]
    matcher: MatcherArgs,
    /// Match very narrow baselines from the left view only.
    ///
    /// By default the classical matcher measures a tile under 0.63 px of disparity per metre of
    /// altitude (a pixel is over 1.6 m of height) from both views, and a cell keeps their mean
    /// height only where both measured it within 2 m; the others are left to the hole filling
    /// (flagged in the _filled sidecar). The second match runs beside the first on those tiles
    /// (about 1.5x their time, twice their matching memory); `reconstruct-many` does the same
    /// for each pair.
    #[arg(long, help_heading = heading::MATCHING, hide_short_help = true)]
    single_view: bool,
    /// Use the cameras as given, without correcting their pointing.
    ///
    /// By default the pair's relative pointing error (vendor RPCs are off by a few to tens of
    /// pixels, one translation over the image) is measured from tie points between the images
    /// and removed by translating the right camera; the log says by how much. JSON cameras that
    /// carry the scene's altitudes (min_alt/max_alt: a curated, bundle-adjusted set, or those
    /// reconstruct-many writes) are always used as given. Without the correction and without
    /// such cameras, give --alt-range.
    #[arg(long, help_heading = heading::MATCHING, hide_short_help = true)]
    no_pointing_correction: bool,
    /// Height of a cell from its points (default median: the DSM to use).
    ///
    /// `median` is robust to isolated wrong points; `max` is the benchmark's protocol (what
    /// `seasonstereo eval` does).
    #[arg(long, value_enum, default_value_t = GriddingArg::Median,
          help_heading = heading::GRID, hide_short_help = true)]
    gridding: GriddingArg,
    /// Fill the holes enclosed by data within this many cells; 0 leaves them empty.
    ///
    /// A cell is filled when data lie on both sides of it along a row, column or diagonal
    /// within this distance, ground first (the ground hidden behind buildings, unmatched
    /// patches); 0 leaves every hole empty, as the benchmark's protocol does.
    #[arg(long, value_name = "CELLS", default_value_t = defaults::FILL_CELLS,
          help_heading = heading::FINISHING, hide_short_help = true)]
    fill_holes: usize,
    /// Fill only the cells within this many cells of a measured height.
    ///
    /// Along the filling's rays: the middle of a wider hole stays empty, because a height
    /// invented that far from any measurement is a guess (a courtyard at its roofs' height, a
    /// low roof at the ground's). The `_filled.tif` sidecar marks the filled cells either way.
    #[arg(long, value_name = "CELLS", default_value_t = defaults::FILL_REACH,
          help_heading = heading::FINISHING, hide_short_help = true)]
    fill_reach: usize,
    /// Median filter of the DSM over this odd window of cells; 0 or 1 disables it.
    ///
    /// After the filling: removes the roughness of single-pair matching on roofs and ground and
    /// keeps building edges (15 cells = 7.5 m at 0.5 m).
    #[arg(long, value_name = "CELLS", default_value_t = defaults::MEDIAN_CELLS,
          help_heading = heading::FINISHING, hide_short_help = true)]
    median_filter: usize,
    #[command(flatten)]
    products: ProductArgs,
    /// Keep every tile's rectified pair and disparity in --work.
    ///
    /// L/, R/, homography/, rectify/, disparity/: the layout `seasonstereo eval` reads. Off by
    /// default, as they take ~30 bytes per pixel.
    #[arg(long, help_heading = heading::PRODUCTS, hide_short_help = true)]
    keep_intermediates: bool,
}

pub fn run(a: ReconstructArgs, progress: &dyn Progress) -> Result<()> {
    let (tile, collar, output) = (a.tiling.tile, a.tiling.collar, a.output.clone());
    let (tiles_only, shard) = (a.tiles_only, a.shard.shard);
    let options = a.options()?;
    options.check_output(crate::exit::overwrite())?;
    let s = reconstruct(&options, progress)?;
    println!("{}", tiles_line(&s, tile, collar));
    for w in s.warnings(&options) {
        eprintln!("warning: {w}");
    }
    let Some(dsm) = &s.dsm else {
        if tiles_only {
            return failed_tiles(&s, shard);
        }
        println!(
            "{} tiles belong to other shards and are not finished (first: {}); the DSM is written \
             by the run that finds every tile done, or by `seasonstereo reconstruct ... --merge`",
            s.missing.len(),
            s.missing[0]
        );
        return Ok(());
    };
    println!("{}", dsm_line(&s, dsm, &output));
    print_products_and_scores(&options.products, s.products.as_ref(), s.scores.as_ref());
    failed_tiles(&s, Shard::ALL)
}

/// Exit code 2 when some tiles of `shard` failed (the DSM, if written, holds the others).
fn failed_tiles(s: &ReconstructSummary, shard: Shard) -> Result<()> {
    let failed: Vec<String> = s
        .records
        .iter()
        .filter(|r| r.status == TileStatus::Failed && shard.contains(r.tile.index))
        .map(|r| r.tile.id.clone())
        .collect();
    crate::exit::partial_if_any(
        "tiles",
        s.records.len(),
        failed,
        "rerun the same command to retry them",
    )
}

impl ReconstructArgs {
    /// The library's options for these flags.
    pub(crate) fn options(self) -> Result<ReconstructOptions> {
        Ok(ReconstructOptions {
            matcher: self.matcher.matcher()?,
            max_memory: self.tiling.max_memory_bytes()?,
            left: self.left,
            right: self.right,
            rpc_left: self.rpc_left,
            rpc_right: self.rpc_right,
            roi: self.roi,
            roi_lonlat: self.roi_lonlat,
            alt_range: self.alt_range,
            output: self.output,
            work_dir: self.work,
            grid: self.grid.choice(),
            finishing: seasonstereo::Finishing::new(
                self.gridding.into(),
                flags::fill_cells(self.fill_holes),
                Some(self.fill_reach),
                flags::median_cells(self.median_filter),
            ),
            border: 0,
            truth: self.truth,
            tile: self.tiling.tile,
            collar: self.tiling.collar,
            shard: self.shard.shard,
            merge_only: self.merge,
            tiles_only: self.tiles_only,
            complete_only: self.merge && !crate::exit::safety().allow_partial,
            keep_intermediates: self.keep_intermediates,
            both_views: !self.single_view,
            level_ground: true,
            adjust_pointing: !self.no_pointing_correction,
            products: self.products.products(),
        })
    }
}

/// The tiles' line: how many of each status, how many ran and at once.
fn tiles_line(s: &ReconstructSummary, tile: usize, collar: usize) -> String {
    let range = s
        .disparity_range()
        .map_or("-".into(), |(lo, hi)| format!("{lo}:{hi} px"));
    format!(
        "tiles: {} of {tile} px (collar {collar} px): {} done, {} empty, {} failed; {} run now ({} \
         at once, largest ~{:.2} GiB), disparity {range}, {:.1} % matched",
        s.records.len() + s.missing.len(),
        s.count(TileStatus::Done),
        s.count(TileStatus::Empty),
        s.count(TileStatus::Failed),
        s.ran,
        s.in_flight,
        s.tile_memory as f64 / (1u64 << 30) as f64,
        100.0 * s.matched().unwrap_or(0.0),
    )
}

/// The DSM's line: its grid, coverage and the steps' times.
fn dsm_line(s: &ReconstructSummary, dsm: &DsmSummary, output: &std::path::Path) -> String {
    let times: Vec<String> = s
        .seconds
        .iter()
        .map(|(k, t)| format!("{k} {t:.1} s"))
        .collect();
    let cells = (dsm.grid.width * dsm.grid.height) as f64;
    format!(
        "wrote {} ({}, {:.1} % measured, {:.1} % with a height) from pair {}; {}",
        output.display(),
        dsm.grid,
        100.0 * dsm.measured_cells as f64 / cells,
        100.0 * dsm.filled_cells as f64 / cells,
        s.stem,
        times.join(", ")
    )
}

/// `LON_MIN,LAT_MIN,LON_MAX,LAT_MAX`.
fn parse_lonlat(s: &str) -> Result<[f64; 4], String> {
    parse_box(s, "LON_MIN,LAT_MIN,LON_MAX,LAT_MAX")
}

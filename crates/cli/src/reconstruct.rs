//! `seasonstereo reconstruct`: from a raw pair to a DSM, tile by tile.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use dataset::Shard;
use seasonstereo::{
    reconstruct, DsmSummary, Progress, ReconstructOptions, ReconstructSummary, TileStatus,
};

use reconstruct::flags;

use crate::args::{
    parse_alt_range, parse_box, parse_roi, GridArgs, GriddingArg, MatcherArgs, ProductArgs,
    ShardArg, TilingArgs,
};

#[derive(Args)]
#[command(
    after_help = "Steps: rectify (RPCs; the right image is sheared so that one altitude has one \
    disparity over the tile, and the disparity range is then what the scene's altitudes span, \
    --alt-range or the cameras' min_alt/max_alt: give them wide enough for the tallest building), \
    match (census + MGM by default; --method sgm; or --model monsterpp --weights W; \
    on very narrow baselines, under 0.4 px of disparity per metre of altitude, the classical \
    matcher works on rows stretched 2x for half-pixel steps; under 0.63 px/m it matches from both \
    views and keeps the cells they agree on, see --single-view), triangulate with the full RPCs (s2p's iteration) and grid. Intermediate files stay in \
    --work (default OUTPUT_work/: L/, R/, homography/, rectify/, disparity/), in the layout \
    `seasonstereo eval` reads.\n\n\
    Example (DFC2019 Jacksonville, bundle-adjusted cameras, scored against the LiDAR truth):\n  \
    D=../shared/data/dfc2019-jax068-dev\n  seasonstereo reconstruct $D/images/JAX_068_006_RGB.tif \
    $D/images/JAX_068_020_RGB.tif --rpc-left $D/rpcs/ba/JAX_068_006_RGB.json --rpc-right \
    $D/rpcs/ba/JAX_068_020_RGB.json --like $D/truth/JAX_068_DSM.tif --truth \
    $D/truth/JAX_068_DSM.tif -o out/jax/006-020.tif"
)]
pub struct ReconstructArgs {
    /// Left raw image: a GeoTIFF with its RPC (tag 50844), or any raster with --rpc-left.
    left: PathBuf,
    /// Right raw image, idem with --rpc-right.
    right: PathBuf,
    /// Output DSM: float32 GeoTIFF (heights above the WGS84 ellipsoid; the scene's UTM zone or
    /// --epsg). Beside it `<stem>_filled.tif`,
    /// on the same grid: 0 = measured cell, 1 = filled by hole filling, NaN = no height; and,
    /// with the classical matcher, `<stem>_confidence.tif`: each measured cell's matching
    /// confidence, 1 − S1/S2 (the winner's aggregated cost against its best rival more than a
    /// pixel away), 0 to 1, NaN elsewhere.
    #[arg(short, long)]
    output: PathBuf,
    /// Left camera, instead of the image's RPC tag: SatNeRF/rpcm JSON (`.json`), or another
    /// GeoTIFF carrying the RPC tag 50844.
    #[arg(long, value_name = "CAMERA")]
    rpc_left: Option<PathBuf>,
    /// Right camera, instead of the image's RPC tag: SatNeRF/rpcm JSON (`.json`), or another
    /// GeoTIFF carrying the RPC tag 50844.
    #[arg(long, value_name = "CAMERA")]
    rpc_right: Option<PathBuf>,
    /// Region of interest X,Y,W,H in the left raw image, pixels. Default: the whole image.
    #[arg(long, value_name = "X,Y,W,H", value_parser = parse_roi, conflicts_with = "roi_lonlat")]
    roi: Option<camera::rectify::Roi>,
    /// Region of interest as lon/lat bounds (degrees): the left image's pixels that see it at
    /// any altitude of the scene.
    #[arg(long, value_name = "LON_MIN,LAT_MIN,LON_MAX,LAT_MAX", value_parser = parse_lonlat, allow_hyphen_values = true)]
    roi_lonlat: Option<[f64; 4]>,
    #[command(flatten)]
    tiling: TilingArgs,
    /// The tiles of the plan, all shards sharing one --work folder; the shard that finds every
    /// tile finished writes the DSM (or run --merge at the end).
    #[command(flatten)]
    shard: ShardArg,
    /// Only assemble the DSM from the tiles in --work (after sharded runs); fails naming the
    /// missing tiles, and (exit code 3) the failed ones unless --allow-partial.
    #[arg(long)]
    merge: bool,
    /// Run this shard's tiles and stop, never assembling the DSM (cluster jobs, whose merge is
    /// a task of its own); exit code 2 when some of them failed.
    #[arg(long, conflicts_with = "merge")]
    tiles_only: bool,
    /// Keep every tile's rectified pair and disparity in --work (L/, R/, homography/,
    /// disparity/, the layout `seasonstereo eval` reads); off by default, as they take ~30 bytes
    /// per pixel.
    #[arg(long)]
    keep_intermediates: bool,
    /// Match very narrow baselines from the left view only. By default the classical matcher
    /// measures a tile under 0.63 px of disparity per metre of altitude (a pixel is over 1.6 m
    /// of height) from both views, and a cell keeps their mean height only where both measured
    /// it within 2 m; the others are left to the hole filling (flagged in the _filled sidecar).
    /// The second match runs beside the first on those tiles (about 1.5x their time, twice their
    /// matching memory); `reconstruct-many` does the same for each pair.
    #[arg(long)]
    single_view: bool,
    /// Altitudes of the scene MIN:MAX, metres: the disparity search covers them and little more
    /// (heights outside are not found). Default: min_alt/max_alt of the JSON cameras, else the
    /// altitudes of the tie points found to correct the pointing (their 0.5 and 99.5
    /// percentiles, widened by 5 m and a tenth of their span).
    #[arg(long, value_name = "MIN:MAX", value_parser = parse_alt_range, allow_hyphen_values = true)]
    alt_range: Option<(f64, f64)>,
    /// Use the cameras as given. By default the pair's relative pointing error (vendor RPCs are
    /// off by a few to tens of pixels, one translation over the image) is measured from tie
    /// points between the images and removed by translating the right camera; the log says by
    /// how much. JSON cameras that carry the scene's altitudes (min_alt/max_alt: a curated,
    /// bundle-adjusted set, or those reconstruct-many writes) are always used as given. Without
    /// the correction and without such cameras, give --alt-range.
    #[arg(long)]
    no_pointing_correction: bool,
    /// Folder of the intermediate files (default: OUTPUT without extension + "_work").
    #[arg(long, value_name = "DIR")]
    work: Option<PathBuf>,
    #[command(flatten)]
    grid: GridArgs,
    #[command(flatten)]
    products: ProductArgs,
    /// Height of a cell from its points. Default median: robust, the DSM to use. `max` is the
    /// benchmark's protocol (what `seasonstereo eval` does).
    #[arg(long, value_enum, default_value_t = GriddingArg::Median)]
    gridding: GriddingArg,
    /// Fill the DSM's holes enclosed by data within this many cells (on both sides of the cell
    /// along a row, column or diagonal), ground first (the ground hidden behind buildings,
    /// unmatched patches); 0 leaves them empty, as the benchmark's protocol does.
    #[arg(long, value_name = "CELLS", default_value_t = reconstruct::dsm::DEFAULT_FILL_CELLS)]
    fill_holes: usize,
    /// Fill only the cells within this many cells of a measured height (along the filling's
    /// rays): the middle of a wider hole stays empty, because a height invented that far from
    /// any measurement is a guess (a courtyard at its roofs' height, a low roof at the ground's).
    /// The `_filled.tif` sidecar marks the filled cells either way.
    #[arg(long, value_name = "CELLS", default_value_t = reconstruct::dsm::DEFAULT_FILL_REACH)]
    fill_reach: usize,
    /// Median filter of the DSM over this odd window of cells, after the filling: removes the
    /// roughness of single-pair matching on roofs and ground and keeps building edges (15 cells
    /// = 7.5 m at 0.5 m); 0 or 1 disables it.
    #[arg(long, value_name = "CELLS", default_value_t = reconstruct::dsm::DEFAULT_MEDIAN_CELLS)]
    median_filter: usize,
    /// Score the DSM against this ground truth <AOI>_DSM.tif (classes <AOI>_CLS.tif beside it)
    /// with the benchmark's metric; needs --like on the same file.
    #[arg(long, value_name = "DSM", requires = "like")]
    truth: Option<PathBuf>,
    #[command(flatten)]
    matcher: MatcherArgs,
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
    if let Some(written) = &s.products {
        println!("{}", crate::args::products_line(&options.products, written));
    }
    if let Some(sc) = &s.scores {
        println!("vs truth: {}", crate::score::format_scores(sc));
    }
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
    if failed.is_empty() {
        return Ok(());
    }
    Err(crate::exit::partial(
        "tiles",
        s.records.len(),
        failed,
        "rerun the same command to retry them",
    ))
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
            gridding: self.gridding.into(),
            fill_holes: flags::fill_cells(self.fill_holes),
            fill_reach: self.fill_reach,
            median_filter: flags::median_cells(self.median_filter),
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

//! Satellite images to DSMs: the single-pair steps ([`rectify`] a raw pair, [`dsm`] a
//! disparity to a DSM), the whole-scene `reconstruct` and the many-date `reconstruct-many`
//! (below), the camera correction ([`pointing`]), the run records that let a work folder resume
//! ([`provenance`]), and the command-line and Python spellings of their options ([`flags`]).
//!
//! From a raw satellite pair to a DSM in one call, at any scene size: the left image's region
//! is cut into tiles with overlap collars ([`plan`]); each tile is rectified on its own from the
//! RPCs, matched over the disparity range its cameras and the scene's altitudes imply,
//! triangulated and gridded ([`tile`]); the tiles' cells are merged into one DSM on a common UTM
//! grid ([`mosaic`]), hole-filled, filtered and written as a Cloud-Optimized GeoTIFF, a block of
//! rows at a time ([`merge`]).
//!
//! Memory stays bounded: the raw images are read by windows ([`raw`]), each tile's peak memory
//! is estimated before it runs, and only as many tiles run at once as fit in the budget.
//! The run is resumable and shardable: every tile leaves `tiles/<id>.json` (status, time,
//! disparity range, coverage) and `tiles/<id>.tif` (its cells) in the work folder; a rerun skips
//! finished tiles, retries failed ones, and `--shard I/N` runs the tiles ≡ I mod N, the DSM being
//! assembled once every tile has a record (by the last shard, or a final merge-only run).
//!
//! Many acquisitions of one area become one DSM in [`many`]: the pairs chosen by [`select`] run
//! through [`reconstruct`] on one grid and [`fuse`] merges their measured cells.

pub mod both_views;
pub mod dsm;
pub mod fabricated;
pub mod finishing;
pub mod flags;
pub mod folder;
pub mod fuse;
pub mod many;
pub mod merge;
pub mod mosaic;
pub mod options;
pub mod plan;
pub mod pointing;
pub mod provenance;
pub mod raw;
pub mod rectify;
pub mod sanity;
pub mod scene;
pub mod select;
pub mod tile;
pub mod workers;

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use camera::rectify::{Rectification, Roi, Shear};
use camera::{Crs, DsmGrid, RpcModel, UtmZone};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::dsm::{DsmSummary, GridChoice};
use crate::rectify::{altitude_range, camera_of, file_stem, given_altitude_range};
use eval::metrics::DsmScores;
use folder::TileFolder;
use merge::{check_merge_memory, merge_tiles, MERGE_BLOCK_ROWS};
use plan::{plan_tiles, Tile};
use raw::RawImage;
use scene::Scene;
use tile::{run_tile, tile_memory, tile_rectification, TileRecord, TileStatus};
use workers::run_on_workers;
use workflow::matcher::Matcher;
use workflow::progress::Progress;
use workflow::stage::write_json;

pub use options::{default_work_dir, ReconstructOptions};

/// What [`reconstruct`] did.
#[derive(Clone, Debug)]
pub struct ReconstructSummary {
    /// `<left stem>-<right stem>`.
    pub stem: String,
    pub work: PathBuf,
    /// Every tile's record, in plan order (those of other shards may be missing).
    pub records: Vec<TileRecord>,
    /// Tiles run by this call (the others were finished before, or belong to other shards).
    pub ran: usize,
    /// Tiles without a record yet (other shards still running).
    pub missing: Vec<String>,
    /// Tiles run at once, and the largest tile's estimated memory, bytes.
    pub in_flight: usize,
    pub tile_memory: u64,
    /// Memory the assembly of the DSM needs, bytes: it holds a block of rows of the grid and its
    /// halo at a time ([`merge::merge_memory`]), outside the tiles' budget.
    pub merge_memory: u64,
    /// The DSM, once every tile has a record.
    pub dsm: Option<DsmSummary>,
    /// Benchmark scores against the truth, when one was given.
    pub scores: Option<DsmScores>,
    /// Wall time of each step, seconds.
    pub seconds: Vec<(&'static str, f64)>,
    /// The pointing correction of the right camera and the tie points' altitudes, when the
    /// pair was adjusted.
    pub pointing: Option<pointing::Pointing>,
    /// The products written beside the DSM, when asked for.
    pub products: Option<products::ProductsWritten>,
}

impl ReconstructSummary {
    /// Records with `status`.
    pub fn count(&self, status: TileStatus) -> usize {
        self.records.iter().filter(|r| r.status == status).count()
    }

    /// Union of the tiles' disparity ranges.
    pub fn disparity_range(&self) -> Option<(i32, i32)> {
        self.records
            .iter()
            .filter_map(|r| r.disparity_range)
            .reduce(|a, b| (a.0.min(b.0), a.1.max(b.1)))
    }

    /// Mean share of matched rectified pixels over the finished tiles.
    pub fn matched(&self) -> Option<f64> {
        let m: Vec<f64> = self.records.iter().filter_map(|r| r.matched).collect();
        (!m.is_empty()).then(|| m.iter().sum::<f64>() / m.len() as f64)
    }

    /// Median over the tiles of their residual vertical parallax, pixels.
    pub fn vertical_parallax(&self) -> Option<f32> {
        let mut v: Vec<f32> = self
            .records
            .iter()
            .filter_map(|r| r.vertical_parallax)
            .collect();
        v.sort_by(f32::total_cmp);
        v.get(v.len() / 2).copied()
    }

    /// The run's warnings, one line each: every failed tile with its error, and cameras that do
    /// not fit their images ([`Self::camera_warning`], naming them as `opts` gives them).
    pub fn warnings(&self, opts: &ReconstructOptions) -> Vec<String> {
        let failed = self
            .records
            .iter()
            .filter(|r| r.status == TileStatus::Failed);
        let mut lines: Vec<String> = failed
            .map(|r| {
                format!(
                    "tile {} failed (rerun the same command to retry it): {}",
                    r.tile.id,
                    r.error.as_deref().unwrap_or("no message")
                )
            })
            .collect();
        let cameras = opts.camera_names();
        lines.extend(self.camera_warning([&cameras[0], &cameras[1]]));
        lines
    }

    /// A warning when the cameras look wrong for their images (swapped, another acquisition's
    /// bundle adjustment): the rectified views disagree by rows, or, where too few patches match
    /// to measure that, matching along the rows found almost nothing. `cameras` names them.
    pub fn camera_warning(&self, cameras: [&str; 2]) -> Option<String> {
        let check = format!(
            "check that {} belongs to the left image and {} to the right one (swapped?)",
            cameras[0], cameras[1]
        );
        if let Some(rows) = self.vertical_parallax() {
            return (rows > MAX_VERTICAL_PARALLAX).then(|| {
                format!(
                    "the rectified views disagree by {rows:.0} px across the epipolar lines \
                     (median over the tiles; 0–2 px when each camera is its image's): {check}"
                )
            });
        }
        let matched = self.matched()?;
        (matched < MIN_MATCHED_SHARE).then(|| {
            format!(
                "only {:.1} % of the rectified pixels matched along the rows (20–80 % when each \
                 camera is its image's, also across seasons), and too few patches matched to \
                 measure the views' row offset: {check}; or the images share little texture",
                100.0 * matched
            )
        })
    }
}

/// Residual vertical parallax above which the cameras are suspect, pixels (s2p corrects up to a
/// few pixels of pointing error; bundle-adjusted RPCs leave a fraction of a pixel). On the 45
/// JAX_068 dev pairs (BA cameras) the threshold separates every pair with each image's camera
/// from every pair with the cameras swapped, where the parallax could be measured
/// (BENCHMARKS.md, "Images as delivered", "Swapped cameras").
pub const MAX_VERTICAL_PARALLAX: f32 = 3.0;

/// Share of matched rectified pixels under which a pair whose row offset could not be measured
/// is suspect: on the 45 dev pairs it separates every pair with each image's camera from every
/// pair with the cameras swapped whose offset could not be measured (BENCHMARKS.md, "Images as
/// delivered", "Swapped cameras").
pub const MIN_MATCHED_SHARE: f64 = 0.10;

/// What the tiles of a work folder were computed with (`scene.json`): a rerun with other
/// settings must not mix its tiles with these.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct SceneSettings {
    left: PathBuf,
    right: PathBuf,
    roi: Roi,
    tile: usize,
    collar: usize,
    alt_range: (f64, f64),
    grid: (f64, f64, f64, usize, usize, u32),
    gridding: String,
    matcher: String,
    border: usize,
    /// Absent from folders made before both views existed, whose tiles were matched from the
    /// left view only.
    #[serde(default)]
    both_views: bool,
    /// Absent from folders made before the right image was sheared to level the ground.
    #[serde(default)]
    level_ground: bool,
}

/// What a run of these options will do, known before any tile runs: the tiles, the DSM grid and
/// the memory each step needs. Cluster jobs size their arrays and requests from it.
#[derive(Clone, Debug)]
pub struct ScenePlan {
    /// The work folder (the tiles' records and cells).
    pub work: PathBuf,
    /// `<left stem>-<right stem>`.
    pub stem: String,
    /// The region of the left raw image and the scene's altitudes, metres.
    pub roi: Roi,
    pub alt_range: (f64, f64),
    /// The tiles, in plan order.
    pub tiles: Vec<Tile>,
    pub grid: DsmGrid,
    /// Memory the assembly of the DSM needs, bytes.
    pub merge_memory: u64,
    /// The largest tile's estimated peak memory, bytes (0 until estimated, see [`plan`]).
    pub tile_memory: u64,
    /// Held by a process besides its tiles, bytes.
    pub process_memory: u64,
}

/// The plan of a reconstruction: the inputs and outputs checked, the tiles cut, the grid chosen
/// and every tile's memory estimated; nothing is written.
pub fn plan(opts: &ReconstructOptions) -> Result<ScenePlan> {
    let (pair, mut plan) = prepare(opts, &workflow::progress::Silent)?;
    let scene = pair.scene(
        opts,
        &plan.grid,
        &plan.work,
        &plan.stem,
        plan.tiles.len() == 1,
    );
    let all: Vec<&Tile> = plan.tiles.iter().collect();
    let (rects, memory) = estimate_tiles(&scene, &all);
    plan.tile_memory = check_tile_memory(opts, &rects, &memory)?;
    Ok(plan)
}

/// The checks and choices before any work: outputs, inputs, region, tiles, grid, merge memory.
fn prepare(opts: &ReconstructOptions, progress: &dyn Progress) -> Result<(OpenPair, ScenePlan)> {
    opts.check_truth()?;
    check_tile_side(opts.tile)?;
    let work = opts.work();
    sanity::check_outputs(opts, &work)?;
    let pair = open_pair(opts, progress)?;
    let (w, h) = pair.left.size();
    let roi = region_of_interest(opts, &pair.rpc_left, pair.alt_range, (w, h))?;
    let stem = format!("{}-{}", file_stem(&opts.left)?, file_stem(&opts.right)?);
    let tiles = plan_tiles(roi, opts.tile, opts.collar, w, h);
    let grid = scene_grid(&opts.grid, &pair.rpc_left, roi, pair.alt_range)?;
    let merge_memory = merge::merge_memory(
        &grid,
        &opts.finishing,
        opts.matcher.gives_confidence(),
        MERGE_BLOCK_ROWS,
    );
    check_merge_memory(&grid, merge_memory, opts.max_memory)?;
    let plan = ScenePlan {
        work,
        stem,
        roi,
        alt_range: pair.alt_range,
        tiles,
        grid,
        merge_memory,
        tile_memory: 0,
        process_memory: PROCESS_BYTES,
    };
    Ok((pair, plan))
}

/// Runs the tiles (rectify → match → triangulate → grid), then merges them into the DSM (→
/// score).
pub fn reconstruct(
    opts: &ReconstructOptions,
    progress: &dyn Progress,
) -> Result<ReconstructSummary> {
    let (pair, plan) = prepare(opts, progress)?;
    let ScenePlan {
        work,
        stem,
        roi,
        alt_range,
        tiles,
        grid,
        merge_memory,
        ..
    } = plan;
    crate::provenance::claim(&work, &opts.run_record())?;
    claim_work_folder(&work, &scene_settings(opts, roi, alt_range, &grid))?;
    let folder = TileFolder::new(&work);
    let mut seconds = Vec::new();
    if let Some(p) = &pair.pointing {
        seconds.push(("pointing", p.seconds));
    }
    let run = if opts.merge_only {
        TilesRun::default()
    } else {
        let t = Instant::now();
        let scene = pair.scene(opts, &grid, &work, &stem, tiles.len() == 1);
        // A tile that cannot fit is refused before any tile runs: an error, not a partial run.
        let todo = tiles_to_run(opts, &scene, &tiles, &folder)?;
        // Work has begun: a failure now (a full disk) leaves no DSM, and finished tiles.
        let run = run_tiles(&scene, todo, &folder, progress).map_err(|e| {
            workflow::outputs::Incomplete::Nothing {
                message: format!(
                    "no DSM written: {}; the finished tiles stay in {}: fix the cause and rerun \
                     the same command",
                    workflow::outputs::one_line(&e),
                    work.display()
                ),
            }
        })?;
        seconds.push(("tiles", t.elapsed().as_secs_f64()));
        run
    };
    let (records, missing) = folder.records(&tiles);
    let mut summary = ReconstructSummary {
        stem,
        work: work.clone(),
        records,
        ran: run.ran,
        missing,
        in_flight: run.in_flight,
        tile_memory: run.largest,
        merge_memory,
        dsm: None,
        scores: None,
        seconds,
        pointing: pair.pointing.clone(),
        products: None,
    };
    if opts.tiles_only {
        return Ok(summary);
    }
    if !summary.missing.is_empty() {
        if opts.merge_only {
            bail!(
                "{} of {} tiles have no record in {} (first: {}): run the missing shards first",
                summary.missing.len(),
                tiles.len(),
                folder.dir().display(),
                summary.missing[0]
            );
        }
        return Ok(summary);
    }
    if summary.count(TileStatus::Done) == 0 {
        return Err(sanity::nothing_produced(&summary.records).into());
    }
    if opts.complete_only {
        sanity::check_complete(&summary.records, &work)?;
    }
    let t = Instant::now();
    summary.dsm = Some(merge_tiles(
        &opts.finishing,
        opts.matcher.gives_confidence(),
        &grid,
        &folder,
        &summary.records,
        &opts.output,
        MERGE_BLOCK_ROWS,
    )?);
    summary.seconds.push(("merge", t.elapsed().as_secs_f64()));
    if let Some(truth) = &opts.truth {
        summary.scores = Some(score_against_truth(&opts.output, truth, &grid)?);
    }
    let views = [
        (opts.left.as_path(), &pair.rpc_left),
        (opts.right.as_path(), &pair.rpc_right),
    ];
    let filled = crate::dsm::filled_path(&opts.output);
    summary.products = workflow::finished::write_products(
        &opts.products,
        &opts.output,
        &grid,
        &views,
        (&filled, products::MeasuredFrom::Filled),
        progress,
    )?;
    if let Some(p) = &summary.products {
        summary.seconds.push(("products", p.seconds));
    }
    Ok(summary)
}

/// A tile's collar and the matcher's windows need room: below 64 pixels a tile is mostly
/// border.
fn check_tile_side(tile: usize) -> Result<()> {
    if tile < 64 {
        bail!("--tile {tile} is too small: tiles need at least 64 pixels");
    }
    Ok(())
}

/// The raw pair as the tiles read it: the images by windows, their cameras and the scene's
/// altitude range.
struct OpenPair {
    left: RawImage,
    right: RawImage,
    rpc_left: RpcModel,
    rpc_right: RpcModel,
    alt_range: (f64, f64),
    alt_source: &'static str,
    /// The pointing correction applied to the right camera, when adjusted.
    pointing: Option<pointing::Pointing>,
}

/// Opens both raw images and their cameras (the RPC tags or the JSON files).
fn open_pair(opts: &ReconstructOptions, progress: &dyn Progress) -> Result<OpenPair> {
    let left = RawImage::open(&opts.left, "left")?;
    let right = RawImage::open(&opts.right, "right")?;
    let rpc_left = camera_of(
        &opts.left,
        left.rpc.clone(),
        opts.rpc_left.as_deref(),
        "left",
    )?;
    let mut rpc_right = camera_of(
        &opts.right,
        right.rpc.clone(),
        opts.rpc_right.as_deref(),
        "right",
    )?;
    let mut pointing = None;
    let adjust = opts.adjust_pointing && pointing::needs_adjustment([&rpc_left, &rpc_right]);
    let (alt_range, alt_source) = if adjust {
        let given = given_altitude_range(opts.alt_range, &rpc_left, &rpc_right)?;
        let alt = given.map_or(rpc_left.alt_offset, |((lo, hi), _)| 0.5 * (lo + hi));
        progress.note("pointing: tying the pair (tie points, then the right camera adjusted)");
        match pointing::adjust_pair((&left, &rpc_left), (&right, &rpc_right), alt) {
            Ok(p) => {
                let camera = pointing::camera_source(&opts.right, opts.rpc_right.as_deref());
                pointing::check_fit(&p.images[1], &opts.right, &camera)?;
                let names = [file_stem(&opts.left)?, file_stem(&opts.right)?];
                for line in pointing::describe(&p, &names).iter().skip(1) {
                    progress.note(&format!("pointing: {line}"));
                }
                rpc_right = p.corrected(&[rpc_left.clone(), rpc_right])[1].clone();
                let range = given.unwrap_or((p.alt_range, "tie points"));
                progress.note(&format!(
                    "altitudes: {:.1} to {:.1} m ({})",
                    range.0 .0, range.0 .1, range.1
                ));
                pointing = Some(p);
                range
            }
            Err(e) => match given {
                Some(range) => {
                    progress.note(&format!(
                        "warning: the pointing of the pair was not corrected ({}); the cameras \
                         are used as given",
                        workflow::outputs::one_line(&e)
                    ));
                    range
                }
                None => {
                    return Err(e.context(format!(
                        "{} and {}: the scene's altitudes could not be found from tie points: give \
                         them with --alt-range MIN:MAX (or --no-pointing-correction and the range)",
                        opts.left.display(),
                        opts.right.display()
                    )))
                }
            },
        }
    } else {
        if opts.adjust_pointing {
            progress.note(
                "pointing: the cameras carry the scene's altitudes (min_alt/max_alt: a curated or \
                 adjusted set) and are used as given",
            );
        }
        altitude_range(opts.alt_range, &rpc_left, &rpc_right)?
    };
    sanity::check_pair(opts, (&left, &right), (&rpc_left, &rpc_right), alt_range)?;
    Ok(OpenPair {
        left,
        right,
        rpc_left,
        rpc_right,
        alt_range,
        alt_source,
        pointing,
    })
}

impl OpenPair {
    /// What every tile of this run shares.
    fn scene<'a>(
        &'a self,
        opts: &'a ReconstructOptions,
        grid: &'a DsmGrid,
        work: &'a Path,
        stem: &'a str,
        single_tile: bool,
    ) -> Scene<'a> {
        Scene {
            left: &self.left,
            right: &self.right,
            rpc_left: &self.rpc_left,
            rpc_right: &self.rpc_right,
            rpc_files: [opts.rpc_left.as_deref(), opts.rpc_right.as_deref()],
            alt_range: self.alt_range,
            alt_source: self.alt_source,
            matcher: &opts.matcher,
            grid,
            gridding: opts.finishing.gridding,
            border: opts.border,
            keep: opts.keep_intermediates.then_some(work),
            stem,
            single_tile,
            both_views: opts.both_views,
            shear: if opts.level_ground {
                Shear::Level
            } else {
                Shear::None
            },
        }
    }
}

/// The region of the left raw image to reconstruct: given in pixels, in lon/lat, or the whole
/// image.
fn region_of_interest(
    opts: &ReconstructOptions,
    rpc_left: &RpcModel,
    alt_range: (f64, f64),
    (w, h): (usize, usize),
) -> Result<Roi> {
    let roi = match (opts.roi, opts.roi_lonlat) {
        (Some(_), Some(_)) => bail!("give the region in pixels or in lon/lat, not both"),
        (Some(roi), None) => roi,
        (None, Some(b)) => lonlat_roi(rpc_left, b, alt_range, (w, h))
            .with_context(|| format!("the lon/lat region in {}", opts.left.display()))?,
        (None, None) => Roi::full(w, h),
    };
    roi.check_inside(w, h)
        .with_context(|| format!("the region of interest of {}", opts.left.display()))?;
    Ok(roi)
}

/// The settings a work folder's tiles depend on.
fn scene_settings(
    opts: &ReconstructOptions,
    roi: Roi,
    alt_range: (f64, f64),
    grid: &DsmGrid,
) -> SceneSettings {
    SceneSettings {
        left: opts.left.clone(),
        right: opts.right.clone(),
        roi,
        tile: opts.tile,
        collar: opts.collar,
        alt_range,
        grid: (
            grid.x0,
            grid.y0,
            grid.resolution,
            grid.width,
            grid.height,
            grid.epsg,
        ),
        gridding: format!("{:?}", opts.finishing.gridding).to_lowercase(),
        matcher: opts.matcher.describe(),
        border: opts.border,
        both_views: opts.both_views,
        level_ground: opts.level_ground,
    }
}

/// Held by the process besides the tiles (images' headers, records, thread stacks), bytes.
pub(crate) const PROCESS_BYTES: u64 = 256 << 20;

/// What running the tiles did.
#[derive(Default)]
struct TilesRun {
    /// Tiles run.
    ran: usize,
    /// Tiles run at once.
    in_flight: usize,
    /// The largest tile's estimated memory, bytes.
    largest: u64,
}

/// This shard's unfinished tiles, each with its rectification and estimated peak memory, and
/// how many run at once.
struct TilesToRun<'a> {
    todo: Vec<&'a Tile>,
    rects: Vec<Result<Rectification>>,
    memory: Vec<u64>,
    in_flight: usize,
    largest: u64,
}

/// This shard's unfinished tiles, estimated; refused when even the largest does not fit in the
/// memory budget.
fn tiles_to_run<'a>(
    opts: &ReconstructOptions,
    scene: &Scene,
    tiles: &'a [Tile],
    folder: &TileFolder,
) -> Result<TilesToRun<'a>> {
    let todo: Vec<&Tile> = tiles
        .iter()
        .filter(|t| {
            opts.shard.contains(t.index)
                && folder
                    .record(t)
                    .is_none_or(|r| r.status == TileStatus::Failed)
        })
        .collect();
    // The network cuts a tile into strips of rows to stay within the budget.
    #[cfg(feature = "network")]
    if let Matcher::Network(n) = &opts.matcher {
        n.limit_memory(opts.max_memory.saturating_sub(2 * PROCESS_BYTES));
    }
    let (rects, memory) = estimate_tiles(scene, &todo);
    let largest = check_tile_memory(opts, &rects, &memory)?;
    let in_flight = tiles_at_once(scene.matcher, opts.max_memory, largest, todo.len());
    Ok(TilesToRun {
        todo,
        rects,
        memory,
        in_flight,
        largest,
    })
}

/// Runs the tiles, as many at once as the memory budget allows, saving each one's record and
/// cells as it ends.
fn run_tiles(
    scene: &Scene,
    tiles: TilesToRun,
    folder: &TileFolder,
    progress: &dyn Progress,
) -> Result<TilesRun> {
    let TilesToRun {
        todo,
        rects,
        memory,
        in_flight,
        largest,
    } = tiles;
    progress.begin(&format!("tiles ({in_flight} at once)"), todo.len());
    let ran = run_on_workers(
        &todo,
        in_flight,
        |i, tile| {
            let (record, cells) = match &rects[i] {
                Ok(rect) => run_tile(scene, tile, rect, memory[i]),
                Err(e) => (TileRecord::failed(tile, e), None),
            };
            folder.save(tile, &record, cells.as_ref())
        },
        progress,
    );
    progress.end();
    let ran = ran.map_err(|e| {
        e.context(format!(
            "saving a tile record under {}",
            folder.dir().display()
        ))
    })?;
    Ok(TilesRun {
        ran,
        in_flight,
        largest,
    })
}

/// Every tile's rectification and estimated peak memory (0 for a tile whose rectification
/// failed: it fails when run).
fn estimate_tiles(scene: &Scene, tiles: &[&Tile]) -> (Vec<Result<Rectification>>, Vec<u64>) {
    let rects: Vec<Result<Rectification>> = tiles
        .par_iter()
        .map(|t| tile_rectification(scene, t))
        .collect();
    let bands = scene.left.bands().max(1);
    let memory: Vec<u64> = tiles
        .iter()
        .zip(&rects)
        .map(|(t, r)| r.as_ref().map_or(0, |r| tile_memory(r, t, bands, scene)))
        .collect();
    (rects, memory)
}

/// Disparity ranges wider than this, pixels, come from altitudes far wider than a city's:
/// unknown altitudes or a camera of another image.
const IMPLAUSIBLE_RANGE_PX: i32 = 400;

/// The largest tile's estimated memory, refused when even that one tile does not fit in the
/// budget.
fn check_tile_memory(
    opts: &ReconstructOptions,
    rects: &[Result<Rectification>],
    memory: &[u64],
) -> Result<u64> {
    let largest = memory.iter().copied().max().unwrap_or(0);
    if !memory.is_empty() && largest + PROCESS_BYTES > opts.max_memory {
        let range = rects
            .iter()
            .zip(memory)
            .max_by_key(|(_, m)| **m)
            .and_then(|(r, _)| r.as_ref().ok().map(|r| r.disparity_range));
        let range = match range {
            None => "disparity range unknown".to_string(),
            Some((lo, hi)) if hi - lo > IMPLAUSIBLE_RANGE_PX => format!(
                "disparity range {lo}:{hi} px, too wide for real altitudes: give --alt-range, \
                 and check that each camera is its image's (--rpc-left, --rpc-right)"
            ),
            Some((lo, hi)) => format!("disparity range {lo}:{hi} px"),
        };
        bail!(
            "one tile needs about {:.2} GiB (plus {:.2} GiB for the process), more than \
             --max-memory {:.2} GiB: raise --max-memory, use a smaller --tile (now {} px) or a \
             narrower --alt-range ({range})",
            crate::flags::gib(largest),
            crate::flags::gib(PROCESS_BYTES),
            crate::flags::gib(opts.max_memory),
            opts.tile,
        );
    }
    Ok(largest)
}

/// How many of `todo` tiles run at once: as many of the largest as fit in the budget, at most
/// one per thread (the matchers that use every core run alone).
fn tiles_at_once(matcher: &Matcher, max_memory: u64, largest: u64, todo: usize) -> usize {
    let threads = rayon::current_num_threads().max(1);
    if matcher.one_at_a_time() {
        1
    } else {
        (((max_memory - PROCESS_BYTES) / largest.max(1)) as usize)
            .clamp(1, threads.min(todo.max(1)))
    }
}

/// The benchmark's scores of the written DSM against a ground-truth DSM on its grid.
pub(crate) fn score_against_truth(dsm: &Path, truth: &Path, grid: &DsmGrid) -> Result<DsmScores> {
    let truth = eval::score::read_truth(truth, grid.nearest_zone())?;
    eval::score::score_dsm_file(dsm, &truth)
}

/// Writes `scene.json`, or checks that the folder's tiles were made with the same settings.
fn claim_work_folder(work: &Path, settings: &SceneSettings) -> Result<()> {
    let path = work.join("scene.json");
    if let Ok(text) = std::fs::read_to_string(&path) {
        let theirs: Option<SceneSettings> = serde_json::from_str(&text).ok();
        if theirs.as_ref() == Some(settings) {
            return Ok(());
        }
        bail!(
            "{} holds tiles computed with other settings (inputs, region, tiling, grid or \
             matcher): give another --work folder, or delete this one to start over",
            work.display()
        );
    }
    write_json(&path, &serde_json::to_value(settings)?)
}

/// The DSM grid: the given DSM's, or `resolution` metres over `bounds` or over the ground
/// footprint of the region (its outline localized at the lowest and highest altitudes), in the
/// scene's UTM zone or the given CRS.
fn scene_grid(
    choice: &GridChoice,
    rpc_left: &RpcModel,
    roi: Roi,
    alt_range: (f64, f64),
) -> Result<DsmGrid> {
    // A DFC2019 truth (plain TIFF + .txt) has no zone: the left camera's is the AOI's.
    let camera_zone = UtmZone::from_lonlat(rpc_left.lon_offset, rpc_left.lat_offset);
    match choice {
        GridChoice::Like(path) => DsmGrid::read(path, Some(camera_zone))
            .with_context(|| format!("reading the grid of {}", path.display())),
        GridChoice::Exact(grid) => Ok(grid.clone()),
        GridChoice::Resolution {
            resolution,
            bounds,
            epsg,
        } => {
            let crs = Crs::from_epsg(epsg.unwrap_or(camera_zone.epsg()))?;
            let cell = crs.cell_size(*resolution, rpc_left.lon_offset, rpc_left.lat_offset);
            let [x_min, y_min, x_max, y_max] = match bounds {
                Some(b) => *b,
                None => snap_outwards(footprint(rpc_left, roi, alt_range, crs)?, cell),
            };
            Ok(DsmGrid::from_bounds(
                x_min,
                y_min,
                x_max,
                y_max,
                cell,
                crs.epsg(),
            )?)
        }
    }
}

/// Bounds `b` snapped outwards to multiples of `cell`, as GDAL's `-tap` aligns cells.
pub(crate) fn snap_outwards(b: [f64; 4], cell: f64) -> [f64; 4] {
    let snap = |v: f64, up: bool| {
        let k = v / cell;
        cell * if up { k.ceil() } else { k.floor() }
    };
    [
        snap(b[0], false),
        snap(b[1], false),
        snap(b[2], true),
        snap(b[3], true),
    ]
}

/// Bounds in `crs` of the region's outline localized at both ends of the altitude range.
pub(crate) fn footprint(
    rpc: &RpcModel,
    roi: Roi,
    alt_range: (f64, f64),
    crs: &Crs,
) -> Result<[f64; 4]> {
    let (x0, y0) = (roi.x as f64, roi.y as f64);
    let (x1, y1) = (x0 + roi.width as f64, y0 + roi.height as f64);
    let mut b = [
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    ];
    for k in 0..=8 {
        let f = k as f64 / 8.0;
        let (xs, ys) = (x0 + f * (x1 - x0), y0 + f * (y1 - y0));
        for (x, y) in [(xs, y0), (xs, y1), (x0, ys), (x1, ys)] {
            for alt in [alt_range.0, alt_range.1] {
                let (lon, lat) = rpc
                    .localization(x, y, alt)
                    .context("localizing the region's outline with the left RPC")?;
                let (e, n) = crs.forward(lon, lat);
                b = [b[0].min(e), b[1].min(n), b[2].max(e), b[3].max(n)];
            }
        }
    }
    Ok(b)
}

/// The pixels of a `width` × `height` image (camera `rpc`) that see the lon/lat bounds at any
/// altitude of the range.
fn lonlat_roi(
    rpc: &RpcModel,
    b: [f64; 4],
    alt_range: (f64, f64),
    size: (usize, usize),
) -> Result<Roi> {
    let [lon0, lat0, lon1, lat1] = b;
    if !(lon1 > lon0 && lat1 > lat0) {
        bail!(
            "the lon/lat bounds must be LON_MIN,LAT_MIN,LON_MAX,LAT_MAX with MIN < MAX, got {b:?}"
        );
    }
    let (mut x0, mut y0, mut x1, mut y1) = (
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    );
    for (lon, lat) in [(lon0, lat0), (lon1, lat0), (lon0, lat1), (lon1, lat1)] {
        for alt in [alt_range.0, alt_range.1] {
            let (x, y) = rpc.projection(lon, lat, alt);
            (x0, y0, x1, y1) = (x0.min(x), y0.min(y), x1.max(x), y1.max(y));
        }
    }
    let (w, h) = (size.0 as f64, size.1 as f64);
    let (x0, y0) = (x0.floor().max(0.0), y0.floor().max(0.0));
    let (x1, y1) = (x1.ceil().min(w), y1.ceil().min(h));
    if !(x1 > x0 && y1 > y0) {
        bail!(
            "the bounds {b:?} are not seen by the image ({}x{} px)",
            size.0,
            size.1
        );
    }
    Ok(Roi::new(
        x0 as usize,
        y0 as usize,
        (x1 - x0) as usize,
        (y1 - y0) as usize,
    ))
}

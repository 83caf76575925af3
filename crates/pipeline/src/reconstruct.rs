//! From a raw satellite pair to a DSM in one call, at any scene size: the left image's region
//! is cut into tiles with overlap collars ([`plan`]); each tile is rectified on its own from the
//! RPCs, matched over the disparity range its cameras and the scene's altitudes imply,
//! triangulated and gridded ([`tile`]); the tiles' cells are merged into one DSM on a common UTM
//! grid ([`mosaic`]), hole-filled, filtered and written as a Cloud-Optimized GeoTIFF.
//!
//! Memory stays bounded: the raw images are read by windows ([`raw`]), each tile's peak memory
//! is estimated before it runs, and only as many tiles run at once as fit in the budget.
//! The run is resumable and shardable: every tile leaves `tiles/<id>.json` (status, time,
//! disparity range, coverage) and `tiles/<id>.tif` (its cells) in the work folder; a rerun skips
//! finished tiles, retries failed ones, and `--shard I/N` runs the tiles ≡ I mod N, the DSM being
//! assembled once every tile has a record (by the last shard, or a final merge-only run).

pub mod mosaic;
pub mod plan;
pub mod raw;
pub mod tile;

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use camera::rectify::{Rectification, Roi};
use camera::{write_dsm, DsmGrid, Gridding, RpcModel, UtmZone};
use dataset::shard::Shard;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::dsm::{finish_dsm, DsmSummary, GridChoice};
use crate::eval::metrics::DsmScores;
use crate::matcher::Matcher;
use crate::progress::Progress;
use crate::rectify::{altitude_range, camera_of, file_stem};
use crate::stage::write_json;
use mosaic::{read_part, write_part, Mosaic};
use plan::{plan_tiles, Tile};
use raw::RawImage;
use tile::{run_tile, tile_memory, tile_rectification, Scene, TileRecord, TileStatus};

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
    /// Keep every tile's rectified pair and disparity in the work folder (`L/`, `R/`,
    /// `homography/`, `disparity/`, the layout `eval` reads).
    pub keep_intermediates: bool,
}

impl ReconstructOptions {
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
            gridding: Gridding::Median,
            fill_holes: Some(40),
            median_filter: Some(7),
            border: 0,
            truth: None,
            tile: 1024,
            collar: 64,
            max_memory: 2 << 30,
            shard: Shard::ALL,
            merge_only: false,
            keep_intermediates: false,
        }
    }
}

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
    /// Memory the assembly of the DSM needs, bytes: it holds the whole grid (merge, hole
    /// filling, median filter), outside the tiles' budget.
    pub merge_memory: u64,
    /// The DSM, once every tile has a record.
    pub dsm: Option<DsmSummary>,
    /// Benchmark scores against the truth, when one was given.
    pub scores: Option<DsmScores>,
    /// Wall time of each step, seconds.
    pub seconds: Vec<(&'static str, f64)>,
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
}

/// The default work folder of an output DSM: `out/dsm.tif` → `out/dsm_work`.
pub fn default_work_dir(output: &Path) -> PathBuf {
    let stem = output
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "dsm".into());
    output.with_file_name(format!("{stem}_work"))
}

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
}

/// Runs the tiles (rectify → match → triangulate → grid), then merges them into the DSM (→
/// score).
pub fn reconstruct(
    opts: &ReconstructOptions,
    progress: &dyn Progress,
) -> Result<ReconstructSummary> {
    if opts.tile < 64 {
        bail!(
            "--tile {} is too small: tiles need at least 64 pixels",
            opts.tile
        );
    }
    let work = opts
        .work_dir
        .clone()
        .unwrap_or_else(|| default_work_dir(&opts.output));
    let mut seconds = Vec::new();
    let left = RawImage::open(&opts.left, "left")?;
    let right = RawImage::open(&opts.right, "right")?;
    let rpc_left = camera_of(
        &opts.left,
        left.rpc.clone(),
        opts.rpc_left.as_deref(),
        "left",
    )?;
    let rpc_right = camera_of(
        &opts.right,
        right.rpc.clone(),
        opts.rpc_right.as_deref(),
        "right",
    )?;
    let (alt_range, alt_source) = altitude_range(opts.alt_range, &rpc_left, &rpc_right)?;
    let (w, h) = left.size();
    let roi = match (opts.roi, opts.roi_lonlat) {
        (Some(_), Some(_)) => bail!("give the region in pixels or in lon/lat, not both"),
        (Some(roi), None) => roi,
        (None, Some(b)) => lonlat_roi(&rpc_left, b, alt_range, (w, h))
            .with_context(|| format!("the lon/lat region in {}", opts.left.display()))?,
        (None, None) => Roi::full(w, h),
    };
    roi.check_inside(w, h)
        .with_context(|| format!("the region of interest of {}", opts.left.display()))?;
    let stem = format!("{}-{}", file_stem(&opts.left)?, file_stem(&opts.right)?);
    let tiles = plan_tiles(roi, opts.tile, opts.collar, w, h);
    let grid = scene_grid(&opts.grid, &rpc_left, roi, alt_range)?;
    let settings = SceneSettings {
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
        gridding: format!("{:?}", opts.gridding).to_lowercase(),
        matcher: opts.matcher.describe(),
        border: opts.border,
    };
    // The tiles stay inside the budget by construction; the assembly holds the whole grid.
    let merge_memory = (grid.width * grid.height) as u64 * MERGE_BYTES_PER_CELL;
    if merge_memory > opts.max_memory {
        bail!(
            "assembling the {}x{}-cell DSM needs about {:.2} GiB, more than --max-memory {:.2} \
             GiB: use a coarser --resolution, a smaller --roi, or raise --max-memory",
            grid.width,
            grid.height,
            gib(merge_memory),
            gib(opts.max_memory)
        );
    }
    claim_work_folder(&work, &settings)?;
    let tiles_dir = work.join("tiles");
    let record_path = |t: &Tile| tiles_dir.join(format!("{}.json", t.id));
    let part_path = |t: &Tile| tiles_dir.join(format!("{}.tif", t.id));
    // A tile's record, if it has one for this plan.
    let record_of = |t: &Tile| -> Option<TileRecord> {
        let text = std::fs::read_to_string(record_path(t)).ok()?;
        serde_json::from_str::<TileRecord>(&text)
            .ok()
            .filter(|r| r.tile == *t)
    };

    let mut ran = 0;
    let mut in_flight = 0;
    let mut largest = 0;
    if !opts.merge_only {
        let todo: Vec<&Tile> = tiles
            .iter()
            .filter(|t| {
                opts.shard.contains(t.index)
                    && record_of(t).is_none_or(|r| r.status == TileStatus::Failed)
            })
            .collect();
        // Held by the process besides the tiles (images' headers, records, thread stacks).
        let base = 256 << 20;
        let matcher = &opts.matcher;
        // The network cuts a tile into strips of rows to stay within the budget.
        #[cfg(feature = "network")]
        if let Matcher::Network(n) = matcher {
            n.limit_memory(opts.max_memory.saturating_sub(2 * base));
        }
        let scene = Scene {
            left: &left,
            right: &right,
            rpc_left: &rpc_left,
            rpc_right: &rpc_right,
            rpc_files: [opts.rpc_left.as_deref(), opts.rpc_right.as_deref()],
            alt_range,
            alt_source,
            matcher,
            grid: &grid,
            gridding: opts.gridding,
            border: opts.border,
            keep: opts.keep_intermediates.then_some(work.as_path()),
            stem: &stem,
            single_tile: tiles.len() == 1,
        };
        let t = Instant::now();
        let rects: Vec<Result<Rectification>> = todo
            .par_iter()
            .map(|t| tile_rectification(&scene, t))
            .collect();
        let bands = left.bands().max(1);
        let memory: Vec<u64> = todo
            .iter()
            .zip(&rects)
            .map(|(t, r)| r.as_ref().map_or(0, |r| tile_memory(r, t, bands, matcher)))
            .collect();
        largest = memory.iter().copied().max().unwrap_or(0);
        if !todo.is_empty() && largest + base > opts.max_memory {
            bail!(
                "one tile needs about {:.2} GiB (plus {:.2} GiB for the process), more than \
                 --max-memory {:.2} GiB: use a smaller --tile (now {} px) or a narrower \
                 --alt-range (disparity range {:?} px)",
                gib(largest),
                gib(base),
                gib(opts.max_memory),
                opts.tile,
                todo.iter()
                    .zip(&rects)
                    .zip(&memory)
                    .max_by_key(|(_, m)| **m)
                    .and_then(|((_, r), _)| r.as_ref().ok().map(|r| r.disparity_range))
            );
        }
        let threads = rayon::current_num_threads().max(1);
        in_flight = if matcher.one_at_a_time() {
            1
        } else {
            (((opts.max_memory - base) / largest.max(1)) as usize)
                .clamp(1, threads.min(todo.len().max(1)))
        };
        progress.begin(&format!("tiles ({in_flight} at once)"), todo.len());
        let next = AtomicUsize::new(0);
        let done = AtomicUsize::new(0);
        let failure: Mutex<Option<anyhow::Error>> = Mutex::new(None);
        let worker = || loop {
            if failure.lock().map_or(true, |f| f.is_some()) {
                return;
            }
            let i = next.fetch_add(1, Ordering::SeqCst);
            let Some(tile) = todo.get(i) else { return };
            let (record, cells) = match &rects[i] {
                Ok(rect) => run_tile(&scene, tile, rect, memory[i]),
                Err(e) => (TileRecord::failed(tile, e), None),
            };
            let saved = (|| -> Result<()> {
                if let Some(cells) = &cells {
                    write_part(&part_path(tile), cells)?;
                }
                write_json(&record_path(tile), &serde_json::to_value(&record)?)
            })();
            if let Err(e) = saved {
                if let Ok(mut f) = failure.lock() {
                    f.get_or_insert(e);
                }
                return;
            }
            progress.advance(done.fetch_add(1, Ordering::SeqCst) + 1);
        };
        std::thread::scope(|s| {
            for _ in 0..in_flight {
                s.spawn(worker);
            }
        });
        progress.end();
        if let Some(e) = failure.into_inner().ok().flatten() {
            return Err(e.context(format!(
                "saving a tile record under {}",
                tiles_dir.display()
            )));
        }
        ran = done.into_inner();
        seconds.push(("tiles", t.elapsed().as_secs_f64()));
    }

    let mut records = Vec::with_capacity(tiles.len());
    let mut missing = Vec::new();
    for t in &tiles {
        match record_of(t) {
            Some(r) => records.push(r),
            None => missing.push(t.id.clone()),
        }
    }
    let mut summary = ReconstructSummary {
        stem,
        work: work.clone(),
        records,
        ran,
        missing,
        in_flight,
        tile_memory: largest,
        merge_memory,
        dsm: None,
        scores: None,
        seconds,
    };
    if !summary.missing.is_empty() {
        if opts.merge_only {
            bail!(
                "{} of {} tiles have no record in {} (first: {}): run the missing shards first",
                summary.missing.len(),
                tiles.len(),
                tiles_dir.display(),
                summary.missing[0]
            );
        }
        return Ok(summary);
    }

    let t = Instant::now();
    let mut mosaic = Mosaic::new(&grid, opts.gridding);
    let mut points = 0;
    for r in &summary.records {
        if let (TileStatus::Done, Some(cells)) = (r.status, r.cells) {
            mosaic.add(&read_part(&part_path(&r.tile), cells)?);
            points += r.points;
        }
    }
    let dsm = mosaic.into_image(&grid);
    let measured_cells = dsm.data().iter().filter(|v| v.is_finite()).count();
    let dsm = finish_dsm(dsm, opts.fill_holes, opts.median_filter)?;
    write_dsm(&opts.output, &dsm, &grid)
        .with_context(|| format!("writing {}", opts.output.display()))?;
    summary.seconds.push(("merge", t.elapsed().as_secs_f64()));
    summary.dsm = Some(DsmSummary {
        points,
        measured_cells,
        filled_cells: dsm.data().iter().filter(|v| v.is_finite()).count(),
        grid: grid.clone(),
        comparison: None,
    });
    if let Some(truth) = &opts.truth {
        let zone = UtmZone::from_epsg(grid.epsg)?;
        let truth = crate::score::read_truth(truth, zone)?;
        summary.scores = Some(crate::score::score_dsm_file(&opts.output, &truth)?);
    }
    Ok(summary)
}

/// Peak bytes per DSM cell while assembling: the mosaic (height + count), the filled and the
/// filtered copies.
const MERGE_BYTES_PER_CELL: u64 = 18;

fn gib(bytes: u64) -> f64 {
    bytes as f64 / (1u64 << 30) as f64
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
/// footprint of the region (its outline localized at the lowest and highest altitudes).
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
        GridChoice::Resolution {
            resolution,
            bounds,
            epsg,
        } => {
            let zone = match epsg {
                Some(code) => UtmZone::from_epsg(*code)?,
                None => camera_zone,
            };
            let [x_min, y_min, x_max, y_max] = match bounds {
                Some(b) => *b,
                None => {
                    // Cells aligned on multiples of the resolution, as GDAL's -tap does.
                    let [x0, y0, x1, y1] = footprint(rpc_left, roi, alt_range, zone)?;
                    let snap = |v: f64, up: bool| {
                        let k = v / resolution;
                        resolution * if up { k.ceil() } else { k.floor() }
                    };
                    [
                        snap(x0, false),
                        snap(y0, false),
                        snap(x1, true),
                        snap(y1, true),
                    ]
                }
            };
            Ok(DsmGrid::from_bounds(
                x_min,
                y_min,
                x_max,
                y_max,
                *resolution,
                zone.epsg(),
            )?)
        }
    }
}

/// UTM bounds of the region's outline localized at both ends of the altitude range.
fn footprint(rpc: &RpcModel, roi: Roi, alt_range: (f64, f64), zone: UtmZone) -> Result<[f64; 4]> {
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
                let (e, n) = zone.forward(lon, lat);
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

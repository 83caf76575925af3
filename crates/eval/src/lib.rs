//! The benchmark's evaluation and scoring: `eval` over a split (below), `score` of any DSM
//! against a ground truth ([`score`]), and the procedural world written in the public release's
//! layout, on one date or many ([`world_io`], [`world_dates`]), which the evaluation reads.
//!
//! `seasonstereo eval`: altitude MAE of the DSMs reconstructed from predicted disparities, as the
//! benchmark's released evaluation code computes it, aggregated into the paper's Table 1.
//!
//! # The protocol, per pair
//!
//! 1. The disparity of the rectified pair: computed here (`Method::Matcher`: census + MGM/SGM over a range
//!    derived from the cameras and the scene's altitude range), read from a folder of predictions
//!    (`Method::Predictions`), or the split's own ground-truth disparity (`Method::GroundTruth`,
//!    a check of the chain itself).
//! 2. Inputs larger than [`EvalOptions::crop`] (1024) pixels are centre-cropped and both
//!    homographies shifted accordingly ([`raster::geometry::crop_homography`]). A prediction file
//!    may be given at the full rectified size (it is cropped) or at the crop's size.
//! 3. The evaluation mask ([`protocol::evaluation_mask`]: finite d > 0, 32-px border, match
//!    x − d in [32, W − 32)), then s2p's iterative triangulation with the full RPCs
//!    ([`camera::triangulate_disparity`]).
//! 4. Max-per-cell rasterisation on the ground-truth DSM's UTM grid ([`camera::rasterize_max`]).
//! 5. The scores ([`metrics`]): MAE over all cells, without water, and without water and foliage
//!    (`mae_filtered`, the headline number), each after its own registration on the truth masked
//!    for it ([`align`]: integer shift by multiscale NCC, then vertical offset); coverage beside.
//!
//! [`Protocol::Release`] (the default) follows the released evaluator in every rule, including
//! its roundings where they decide a shift; [`Protocol::Robust`] is seasonstereo's deliberate
//! variant (see [`protocol`]).
//!
//! Omaha pairs whose ground-truth disparity (`disparity/<stem>.iio`) exceeds 192 px are dropped
//! (recorded with status `dropped_disparity_limit`, never aggregated). Aggregation
//! ([`aggregate`]): median of the pair MAEs per AOI, per split the mean ± sample std over AOIs,
//! and the average of the split means.
//!
//! # Outputs and resumability
//!
//! `<out>/pairs.csv` has one row per (method, split, pair); it is rewritten atomically after every
//! pair, so a killed run keeps every finished pair and a rerun skips them (a second method written
//! to the same folder adds rows, and a row of the table). `<out>/table1.md` is the table in
//! markdown; with `save_dsm`, `<out>/dsm/<method>/<split>/<stem>.tif` are the predicted DSMs
//! (float32 GeoTIFF on the ground truth's grid, before registration).
//!
//! # Layout
//!
//! See [`layout`] for the folders read and the assumptions made about the public release.
//!
//! # The procedural world
//!
//! [`crate::world_io::save_world`] also writes the world's ground truth in this layout
//! (`truth/<AOI>_DSM.tif`, `truth/<AOI>_CLS.tif`, `rpc/<ID>.json`). Its DSM is, by design, the
//! protocol's own max-per-cell rasterisation of the EXACT surface points seen at the left image's
//! pixel centres, computed from the scene geometry (not through disparity, homographies or RPC
//! triangulation); so evaluating the world's true disparity measures the error of the chain
//! homographies → RPC triangulation → UTM → grid alone, which must be (and is) well below 5 cm.

pub mod aggregate;
pub mod align;
pub mod layout;
pub mod metrics;
pub mod protocol;
pub mod records;
pub mod score;
pub mod table;
pub mod versus;
pub mod world_dates;
pub mod world_io;

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use camera::{DsmGrid, DsmRaster, RpcModel, UtmZone};
use raster::formats::{read_homographies, read_tiff};
use raster::geometry::{crop, crop_homography};
use raster::{Homography, Image};

pub use aggregate::{aggregate, Table};
pub use align::{align, AlignParams, Alignment, Scheme};
pub use layout::{AoiRule, PairFiles, Split, TruthFiles};
pub use metrics::{score_dsm, DsmScores, Exclusions, Registration, Score, ScoreParams};
pub use protocol::Protocol;
pub use records::{PairRecord, RecordFile};
pub use versus::{score_versus, CellsMae, Versus};
use workflow::matcher::{Matcher, RangeSource};
use workflow::progress::{Progress, Silent};

/// Name of the per-pair CSV in the output folder.
pub const PAIRS_CSV: &str = "pairs.csv";
/// Name of the markdown table in the output folder.
pub const TABLE_MD: &str = "table1.md";

/// Where the disparities come from.
#[derive(Clone, Debug)]
pub enum Method {
    /// A matcher run on each (cropped) rectified pair; the classical one searches the range
    /// the cameras give.
    Matcher(Matcher),
    /// `<dir>/[<split>/]<stem>.{iio,npy,tif,pfm}` (see [`layout::prediction_path`]).
    Predictions(PathBuf),
    /// The split's ground-truth disparity `disparity/<stem>.iio`: measures the chain's own error.
    GroundTruth,
}

impl Method {
    /// The default row name of the method in Table 1.
    pub fn default_name(&self) -> String {
        match self {
            Method::Matcher(m) => m.name(),
            Method::Predictions(dir) => dir
                .file_name()
                .map(|n| n.to_string_lossy().to_string())
                .unwrap_or_else(|| "predictions".to_string()),
            Method::GroundTruth => "ground-truth disparity".to_string(),
        }
    }
}

/// Everything an evaluation run needs.
#[derive(Clone, Debug)]
pub struct EvalOptions {
    pub splits: Vec<Split>,
    /// Folder of the SatNeRF/rpcm JSON cameras `<IMAGEID>.json`.
    pub rpc_dir: PathBuf,
    /// Folder of `<AOI>_DSM.tif`, `<AOI>_CLS.tif`, `<AOI>_WATER.png`.
    pub truth_dir: PathBuf,
    pub method: Method,
    /// Row name in the CSV and Table 1.
    pub method_name: String,
    /// Output folder (CSV, table, DSMs).
    pub out_dir: PathBuf,
    pub save_dsm: bool,
    /// At most this many pairs per split: the first ones by stem (scored or not).
    pub max_pairs: Option<usize>,
    pub aoi_rule: AoiRule,
    /// Inputs larger than this (either side) are centre-cropped to it.
    pub crop: usize,
    /// Omaha pairs with a ground-truth disparity above this are dropped.
    pub omaha_max_disparity: f64,
    /// The scoring rules: the released evaluator's by default.
    pub protocol: Protocol,
}

impl EvalOptions {
    /// The benchmark's settings for these splits, cameras, truth and method.
    pub fn new(
        splits: Vec<Split>,
        rpc_dir: impl Into<PathBuf>,
        truth_dir: impl Into<PathBuf>,
        method: Method,
        out_dir: impl Into<PathBuf>,
    ) -> Self {
        EvalOptions {
            splits,
            rpc_dir: rpc_dir.into(),
            truth_dir: truth_dir.into(),
            method_name: method.default_name(),
            method,
            out_dir: out_dir.into(),
            save_dsm: false,
            max_pairs: None,
            aoi_rule: AoiRule::default(),
            crop: 1024,
            omaha_max_disparity: aggregate::OMAHA_MAX_DISPARITY,
            protocol: Protocol::Release,
        }
    }

    /// A world folder written by `seasonstereo world` as one split named `name`: pairs, `rpc/` and
    /// `truth/` all under `dir`.
    pub fn world(dir: &Path, name: &str, method: Method, out_dir: impl Into<PathBuf>) -> Self {
        EvalOptions::new(
            vec![Split {
                name: name.to_string(),
                dir: dir.to_path_buf(),
            }],
            dir.join("rpc"),
            dir.join("truth"),
            method,
            out_dir,
        )
    }
}

/// What a run did.
#[derive(Clone, Debug)]
pub struct EvalReport {
    /// Pairs scored by this run (including "no overlap" results).
    pub scored: usize,
    /// Pairs skipped because the CSV already had them.
    pub skipped: usize,
    /// Pairs dropped by the Omaha disparity rule in this run.
    pub dropped: usize,
    /// Every row of the CSV (all methods), after the run.
    pub records: Vec<PairRecord>,
    pub table: Table,
    pub csv: PathBuf,
    pub markdown: PathBuf,
    /// Pairs that could not be scored (`split/stem`, the error as one line): the table holds
    /// the others, and a rerun retries only these.
    pub failed: Vec<(String, String)>,
}

/// The ground truth of one AOI, read once for all its pairs.
pub struct Truth {
    pub aoi: String,
    /// Heights, NaN where the truth has none (the release protocol keeps a declared nodata value).
    pub dsm: Image,
    pub grid: DsmGrid,
    pub exclusions: Exclusions,
}

impl Truth {
    /// Reads the truth of `aoi` as the released evaluator does ([`Protocol::Release`]); `zone` is
    /// the UTM zone of the AOI (from its cameras), used when the DSM is a DFC2019 plain TIFF with
    /// its `.txt` georeference.
    pub fn read(files: &TruthFiles, aoi: &str, zone: UtmZone) -> Result<Truth> {
        Truth::read_with(files, aoi, zone, Protocol::Release)
    }

    /// [`Truth::read`] under `protocol`: the release keeps a declared nodata value as a height
    /// (it reads the raw values), resizes a class raster of another size and masks nothing
    /// without a `_CLS.tif` (see [`read_exclusions`]).
    pub fn read_with(
        files: &TruthFiles,
        aoi: &str,
        zone: UtmZone,
        protocol: Protocol,
    ) -> Result<Truth> {
        let path = &files.dsm;
        let DsmRaster {
            image: mut dsm,
            grid,
            nodata,
        } = camera::read_dsm(path, Some(zone))
            .with_context(|| format!("reading the ground-truth DSM {}", path.display()))?;
        if !protocol.nodata_to_nan() && nodata.is_some_and(|v| !v.is_nan()) {
            // `read_dsm` made the nodata cells NaN: the release reads them as they are.
            dsm = read_tiff(path)
                .with_context(|| format!("reading the ground-truth DSM {}", path.display()))?
                .image
                .channel(0);
        }
        let (w, h) = dsm.size();
        Ok(Truth {
            aoi: aoi.to_string(),
            exclusions: read_exclusions(files, path, (w, h), protocol)?,
            dsm,
            grid,
        })
    }
}

/// Runs the evaluation: every pair of every split not yet in `<out>/pairs.csv` for this method,
/// then the table (printed by the caller, written to `<out>/table1.md`). Progress: one step per
/// pair of each split.
pub fn evaluate(opts: &EvalOptions, progress: &dyn Progress) -> Result<EvalReport> {
    if opts.splits.is_empty() {
        bail!("no split to evaluate (give --split NAME=DIR or --world DIR)");
    }
    if opts.method_name.trim().is_empty() {
        bail!("the method name must not be empty");
    }
    let csv = opts.out_dir.join(PAIRS_CSV);
    let mut file = RecordFile::open(&csv)?;
    let (mut scored, mut skipped, mut dropped) = (0, 0, 0);
    let mut failed: Vec<(String, String)> = Vec::new();
    let mut truth: Option<Truth> = None;
    for split in &opts.splits {
        let mut stems = split.stems()?;
        if let Some(n) = opts.max_pairs {
            stems.truncate(n);
        }
        progress.begin(&format!("eval {}", split.name), stems.len());
        for (i, stem) in stems.iter().enumerate() {
            if file.contains(&opts.method_name, &split.name, stem) {
                skipped += 1;
                progress.advance(i + 1);
                continue;
            }
            let record = match evaluate_pair(opts, split, stem, &mut truth) {
                Ok(record) => record,
                Err(e) => {
                    let name = format!("{}/{stem}", split.name);
                    failed.push((name, workflow::outputs::one_line(&e)));
                    progress.advance(i + 1);
                    continue;
                }
            };
            if record.status == records::STATUS_DROPPED {
                dropped += 1;
            } else {
                scored += 1;
            }
            file.push(record)?;
            progress.advance(i + 1);
        }
        progress.end();
    }
    if let (Some((first, cause)), 0) = (failed.first(), scored + skipped + dropped) {
        return Err(workflow::outputs::Incomplete::Nothing {
            message: format!(
                "no pair scored: all {} failed; first, {first}: {cause}",
                failed.len()
            ),
        }
        .into());
    }
    let records = file.rows().to_vec();
    let table = aggregate(&records);
    let markdown = opts.out_dir.join(TABLE_MD);
    let text = table.to_markdown();
    raster::formats::write_atomically(&markdown, |f| std::io::Write::write_all(f, text.as_bytes()))
        .with_context(|| format!("writing {}", markdown.display()))?;
    Ok(EvalReport {
        scored,
        skipped,
        dropped,
        records,
        table,
        csv,
        markdown,
        failed,
    })
}

/// Reads a disparity file, first channel.
fn read_disparity(path: &Path, what: &str) -> Result<Image> {
    Ok(raster::read_image(path)
        .with_context(|| format!("reading the {what} {}", path.display()))?
        .channel(0))
}

/// A disparity at the full rectified size `full` is cropped to the window; one already at the
/// window's size is kept; any other size is an error naming `path`.
fn fit_disparity(
    d: Image,
    path: &Path,
    full: (usize, usize),
    win: (usize, usize, usize, usize),
) -> Result<Image> {
    let (x0, y0, cw, ch) = win;
    if d.size() == full {
        if (cw, ch) == full {
            return Ok(d);
        }
        return Ok(crop(&d, x0, y0, cw, ch)?);
    }
    if d.size() == (cw, ch) {
        return Ok(d);
    }
    bail!(
        "{}: the disparity is {}x{} but the rectified pair is {}x{} (centre crop {cw}x{ch})",
        path.display(),
        d.width(),
        d.height(),
        full.0,
        full.1
    )
}

/// The disparity range of a rectified (cropped) frame of size `(w, h)` from the cameras: a grid of
/// left pixels is localised at the scene's lowest and highest altitudes and projected into the
/// right image; widened by 2 px each side.
pub fn camera_disparity_range(
    rpc_left: &RpcModel,
    rpc_right: &RpcModel,
    h_left: &Homography,
    h_right: &Homography,
    (w, h): (usize, usize),
) -> Result<(i32, i32)> {
    let inv = h_left
        .inverse()
        .context("the left homography is singular")?;
    let (a_lo, a_hi) = rpc_left.scene_altitude_range();
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    let n = 9;
    for j in 0..n {
        for i in 0..n {
            let x = (w.saturating_sub(1)) as f64 * i as f64 / (n - 1) as f64;
            let y = (h.saturating_sub(1)) as f64 * j as f64 / (n - 1) as f64;
            let (c, r) = inv.apply(x, y);
            for alt in [a_lo, a_hi] {
                let Ok((lon, lat)) = rpc_left.localization(c, r, alt) else {
                    continue;
                };
                let (cr, rr) = rpc_right.projection(lon, lat, alt);
                let (xr, _) = h_right.apply(cr, rr);
                let d = x - xr;
                if d.is_finite() {
                    lo = lo.min(d);
                    hi = hi.max(d);
                }
            }
        }
    }
    if !(lo.is_finite() && hi.is_finite()) {
        bail!("cannot derive a disparity range from the cameras (localisation failed everywhere)");
    }
    Ok(((lo.floor() - 2.0) as i32, (hi.ceil() + 2.0) as i32))
}

fn read_rpc(path: &Path, side: &str) -> Result<RpcModel> {
    if !path.is_file() {
        bail!(
            "{}: the {side} camera (SatNeRF/rpcm JSON) does not exist",
            path.display()
        );
    }
    RpcModel::read_rpcm_json(path)
        .with_context(|| format!("reading the {side} camera {}", path.display()))
}

fn safe_name(s: &str) -> String {
    s.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' || c == '.' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// Where [`EvalOptions::save_dsm`] writes the DSM of pair `stem` of `split` for `method` under
/// the output folder `out_dir`: `dsm/<method>/<split>/<stem>.tif`, names made file-safe.
pub fn saved_dsm_path(out_dir: &Path, method: &str, split: &str, stem: &str) -> PathBuf {
    out_dir
        .join("dsm")
        .join(safe_name(method))
        .join(safe_name(split))
        .join(format!("{stem}.tif"))
}

/// Scores one pair (or drops it by the Omaha rule).
fn evaluate_pair(
    opts: &EvalOptions,
    split: &Split,
    stem: &str,
    truth: &mut Option<Truth>,
) -> Result<PairRecord> {
    let files = PairFiles::new(
        &split.dir,
        stem,
        &opts.rpc_dir,
        &opts.truth_dir,
        &opts.aoi_rule,
    )?;
    let mut record = PairRecord::unscored(
        &split.name,
        stem,
        &files.aoi,
        &opts.method_name,
        records::STATUS_SCORED,
    );
    let gt_disparity = ground_truth_disparity(opts, split, &files)?;
    if let Some(d) = &gt_disparity {
        if dropped_by_omaha_rule(opts, split, d, &mut record) {
            return Ok(record);
        }
    }
    let rpc_left = read_rpc(&files.rpc_left, "left")?;
    let rpc_right = read_rpc(&files.rpc_right, "right")?;
    let truth = aoi_truth(opts, &files, &rpc_left, truth)?;
    let (hl, hr) = read_homographies(&files.homography)
        .with_context(|| format!("reading the homographies {}", files.homography.display()))?;
    let left_img = raster::read_image(&files.left)
        .with_context(|| format!("reading the left image {}", files.left.display()))?;
    let full = left_img.size();
    let win = raster::geometry::centre_window(full.0, full.1, opts.crop, opts.crop);
    let (hl, hr) = (
        crop_homography(&hl, win.0 as f64, win.1 as f64),
        crop_homography(&hr, win.0 as f64, win.1 as f64),
    );
    let cameras = CroppedCameras {
        rpc_left: &rpc_left,
        rpc_right: &rpc_right,
        hl: &hl,
        hr: &hr,
    };
    let disparity = method_disparity(opts, split, &files, left_img, win, &cameras, gt_disparity)?;
    let (dsm, pixels) = predicted_dsm(&disparity, &hl, &hr, &rpc_left, &rpc_right, &truth.grid)?;
    record.pixels = pixels;
    if opts.save_dsm {
        let path = saved_dsm_path(&opts.out_dir, &opts.method_name, &split.name, stem);
        camera::write_dsm(&path, &dsm, &truth.grid)
            .with_context(|| format!("writing the predicted DSM {}", path.display()))?;
    }
    let s = score_dsm(
        &dsm,
        &truth.dsm,
        &truth.exclusions,
        &opts.protocol.score_params(),
    )?;
    record_scores(&mut record, &s);
    Ok(record)
}

/// The pair's ground-truth disparity when something needs it (the Omaha rule,
/// `Method::GroundTruth`) and it exists.
fn ground_truth_disparity(
    opts: &EvalOptions,
    split: &Split,
    files: &PairFiles,
) -> Result<Option<Image>> {
    let needs_gt =
        layout::is_omaha_split(&split.name) || matches!(opts.method, Method::GroundTruth);
    if needs_gt && files.gt_disparity.is_file() {
        Ok(Some(read_disparity(
            &files.gt_disparity,
            "ground-truth disparity",
        )?))
    } else {
        Ok(None)
    }
}

/// Records the pair's largest true disparity, and marks the pair dropped when it is an Omaha
/// pair beyond the limit (the release never scores those).
fn dropped_by_omaha_rule(
    opts: &EvalOptions,
    split: &Split,
    gt_disparity: &Image,
    record: &mut PairRecord,
) -> bool {
    let (exceeds, max) = aggregate::exceeds_disparity_limit(gt_disparity, opts.omaha_max_disparity);
    record.max_gt_disparity = max;
    let dropped = layout::is_omaha_split(&split.name) && exceeds;
    if dropped {
        record.status = records::STATUS_DROPPED.to_string();
    }
    dropped
}

/// The ground truth of the pair's AOI, read once for all the AOI's pairs (`cached` holds the
/// last AOI's).
fn aoi_truth<'a>(
    opts: &EvalOptions,
    files: &PairFiles,
    rpc_left: &RpcModel,
    cached: &'a mut Option<Truth>,
) -> Result<&'a Truth> {
    if cached.as_ref().is_none_or(|t| t.aoi != files.aoi) {
        let zone = UtmZone::from_lonlat(rpc_left.lon_offset, rpc_left.lat_offset);
        *cached = Some(Truth::read_with(
            &files.truth,
            &files.aoi,
            zone,
            opts.protocol,
        )?);
    }
    Ok(cached.as_ref().expect("just read"))
}

/// The cameras of a pair, the homographies shifted to the crop.
struct CroppedCameras<'a> {
    rpc_left: &'a RpcModel,
    rpc_right: &'a RpcModel,
    hl: &'a Homography,
    hr: &'a Homography,
}

/// The disparity of the cropped pair by the evaluated method: matched here, read from the
/// predictions, or the ground truth's.
fn method_disparity(
    opts: &EvalOptions,
    split: &Split,
    files: &PairFiles,
    left_img: Image,
    win: (usize, usize, usize, usize),
    cameras: &CroppedCameras,
    gt_disparity: Option<Image>,
) -> Result<Image> {
    let full = left_img.size();
    let (x0, y0, cw, ch) = win;
    match &opts.method {
        Method::Matcher(matcher) => {
            let right_img = raster::read_image(&files.right)
                .with_context(|| format!("reading the right image {}", files.right.display()))?;
            if right_img.size() != full {
                bail!(
                    "{}: the right image is {}x{} but the left one {} is {}x{}",
                    files.right.display(),
                    right_img.width(),
                    right_img.height(),
                    files.left.display(),
                    full.0,
                    full.1
                );
            }
            let l = crop(&left_img, x0, y0, cw, ch)?;
            let r = crop(&right_img, x0, y0, cw, ch)?;
            let range = camera_disparity_range(
                cameras.rpc_left,
                cameras.rpc_right,
                cameras.hl,
                cameras.hr,
                (cw, ch),
            )?;
            Ok(matcher
                .disparity(&l, &r, RangeSource::Given(range), &Silent)?
                .disparity)
        }
        Method::Predictions(dir) => {
            let path = layout::prediction_path(dir, &split.name, &files.stem)?;
            let d = read_disparity(&path, "predicted disparity")?;
            fit_disparity(d, &path, full, win)
        }
        Method::GroundTruth => {
            let Some(d) = gt_disparity else {
                bail!(
                    "{}: the ground-truth disparity does not exist",
                    files.gt_disparity.display()
                );
            };
            fit_disparity(d, &files.gt_disparity, full, win)
        }
    }
}

/// Copies the benchmark's scores into the pair's record.
fn record_scores(record: &mut PairRecord, s: &DsmScores) {
    if s.no_overlap() {
        record.status = records::STATUS_NO_OVERLAP.to_string();
    }
    record.mae_raw = s.raw.mae;
    record.mae_no_water = s.no_water.mae;
    record.mae_filtered = s.filtered.mae;
    record.coverage = s.coverage;
    (record.dx, record.dy, record.offset) = (s.filtered.dx, s.filtered.dy, s.filtered.offset);
    (record.dx_raw, record.dy_raw, record.offset_raw) = (s.raw.dx, s.raw.dy, s.raw.offset);
    (
        record.dx_no_water,
        record.dy_no_water,
        record.offset_no_water,
    ) = (s.no_water.dx, s.no_water.dy, s.no_water.offset);
    record.cells = s.filtered.cells;
}

/// The DSM of a (cropped) rectified disparity on `grid`: the release's evaluation mask
/// ([`protocol::evaluation_mask`]), triangulation with the RPCs, max per cell. Returns the DSM
/// and the number of pixels triangulated.
pub fn predicted_dsm(
    disparity: &Image,
    h_left: &Homography,
    h_right: &Homography,
    rpc_left: &RpcModel,
    rpc_right: &RpcModel,
    grid: &DsmGrid,
) -> Result<(Image, usize)> {
    let mask = protocol::evaluation_mask(disparity);
    let pixels = mask.count();
    let points =
        camera::triangulate_disparity(disparity, h_left, h_right, rpc_left, rpc_right, &mask)?;
    let dsm = camera::rasterize_max(&points, grid);
    Ok((dsm, pixels))
}

/// The exclusions of an AOI's truth of `(w, h)` cells, as the protocol reads them: without a
/// `_CLS.tif` nothing is masked (the release masks only when it exists, `_WATER.png` included);
/// a class raster of another size is resized (release) or refused (robust); `_WATER.png` marks
/// water with zero and must be on the DSM's grid.
fn read_exclusions(
    files: &TruthFiles,
    dsm: &Path,
    (w, h): (usize, usize),
    protocol: Protocol,
) -> Result<Exclusions> {
    if !files.cls.is_file() {
        return Ok(Exclusions::none(w, h));
    }
    let mut cls = read_tiff(&files.cls)
        .with_context(|| format!("reading the ground-truth classes {}", files.cls.display()))?
        .image
        .channel(0);
    if cls.size() != (w, h) {
        if !protocol.resize_classes() {
            bail!(
                "{}: the class raster is {}x{} but the DSM {} is {w}x{h}",
                files.cls.display(),
                cls.width(),
                cls.height(),
                dsm.display()
            );
        }
        cls = protocol::resize_nearest(&cls, w, h);
    }
    let water = if files.water.is_file() {
        let m = raster::read_image(&files.water)
            .with_context(|| format!("reading the water mask {}", files.water.display()))?;
        if m.size() != (w, h) {
            bail!(
                "{}: the water mask is {}x{} but the DSM {} is {w}x{h}",
                files.water.display(),
                m.width(),
                m.height(),
                dsm.display()
            );
        }
        Some(metrics::water_from_png(&m))
    } else {
        None
    };
    Ok(Exclusions::from_classes(&cls, water.as_ref()))
}

//! The altitude half of the demo: both disparities triangulated through the world's RPC cameras
//! into DSMs on the truth's grid, and scored with the benchmark's protocol, through the same
//! files the benchmark's evaluation reads.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use camera::{RpcModel, UtmZone};
use raster::formats::{read_homographies, write_png, PngDepth};
use raster::{colormap, Homography, Image};

use super::summary::DsmResult;
use eval::align;
use eval::layout::{AoiRule, TruthFiles};
use eval::metrics::{class_code, score_dsm, DsmScores};
use eval::protocol::Protocol;
use eval::{predicted_dsm, Truth};
use products::dsm_picture;
use workflow::pairs::PairPaths;

/// DFC2019 classes of the truth DSM's `_CLS.tif` (as [`eval::world_io::dfc_class`] writes them).
pub const DFC_CLASSES: [(u8, &str); 4] =
    [(2, "ground"), (6, "building"), (5, "foliage"), (9, "water")];

/// Altitude errors at and above this are the brightest colour of the error maps, metres.
pub const DSM_ERROR_MAX: f32 = 3.0;

/// The world's cameras, homographies and truth as the benchmark's evaluation reads them.
pub struct WorldTruth {
    rpc_left: RpcModel,
    rpc_right: RpcModel,
    h_left: Homography,
    h_right: Homography,
    /// The truth DSM's files (the report's commands name them).
    pub files: TruthFiles,
    truth: Truth,
    /// The DFC class of each truth cell.
    cls: Image,
}

/// Reads the RPCs and homographies written with the world, and its truth DSM and classes.
pub fn read_world_truth(
    world_dir: &Path,
    pair: &PairPaths,
    left_id: &str,
    right_id: &str,
) -> Result<WorldTruth> {
    let rpc_left = RpcModel::read_rpcm_json(world_dir.join("rpc").join(format!("{left_id}.json")))
        .context("reading the left camera of the world")?;
    let rpc_right =
        RpcModel::read_rpcm_json(world_dir.join("rpc").join(format!("{right_id}.json")))
            .context("reading the right camera of the world")?;
    let (h_left, h_right) = read_homographies(&pair.homography)?;
    let aoi = AoiRule::default().aoi_of(left_id);
    let files = TruthFiles::new(&world_dir.join("truth"), &aoi);
    let zone = UtmZone::from_lonlat(rpc_left.lon_offset, rpc_left.lat_offset);
    let truth = Truth::read_with(&files, &aoi, zone, Protocol::Release)?;
    let cls = raster::formats::read_tiff(&files.cls)
        .with_context(|| format!("reading {}", files.cls.display()))?
        .image
        .channel(0);
    Ok(WorldTruth {
        rpc_left,
        rpc_right,
        h_left,
        h_right,
        files,
        truth,
        cls,
    })
}

/// A DSM triangulated from one disparity.
pub struct PredictedDsm {
    /// File name without extension: `dsm/<name>.tif`, `dsm_<name>.png`.
    name: &'static str,
    dsm: Image,
    path: PathBuf,
}

/// Triangulates each named disparity with the full RPCs, grids it on the truth's grid and writes
/// it as `out/dsm/<name>.tif`.
pub fn triangulate_dsms(
    out: &Path,
    w: &WorldTruth,
    disparities: [(&'static str, &Image); 2],
) -> Result<Vec<PredictedDsm>> {
    disparities
        .into_iter()
        .map(|(name, disparity)| {
            let (dsm, _) = predicted_dsm(
                disparity,
                &w.h_left,
                &w.h_right,
                &w.rpc_left,
                &w.rpc_right,
                &w.truth.grid,
            )?;
            let path = out.join("dsm").join(format!("{name}.tif"));
            camera::write_dsm(&path, &dsm, &w.truth.grid)
                .with_context(|| format!("writing {}", path.display()))?;
            Ok(PredictedDsm { name, dsm, path })
        })
        .collect()
}

/// Scores each DSM with the benchmark's protocol and per truth class, and writes the pictures
/// of the truth, of each DSM and of its headline errors: the results and the error maps.
pub fn score_dsms(
    out: &Path,
    w: &WorldTruth,
    dsms: Vec<PredictedDsm>,
) -> Result<(Vec<DsmResult>, Vec<Image>)> {
    let truth = &w.truth;
    let score_params = Protocol::Release.score_params();
    let cell = truth.grid.resolution;
    let height_range = colormap::robust_range(&truth.dsm);
    write_png(
        out.join("dsm_truth.png"),
        &dsm_picture(&truth.dsm, cell, height_range),
        PngDepth::Eight,
    )?;
    let mut results = Vec::new();
    let mut errors_maps = Vec::new();
    for PredictedDsm { name, dsm, path } in dsms {
        let scores = score_dsm(&dsm, &truth.dsm, &truth.exclusions, &score_params)?;
        let by_class = class_maes(&dsm, &scores, w);
        let errors = headline_errors(&dsm, &scores, truth);
        write_png(
            out.join(format!("dsm_{name}.png")),
            &dsm_picture(&dsm, cell, height_range),
            PngDepth::Eight,
        )?;
        write_png(
            out.join(format!("dsm_error_{name}.png")),
            &colormap::colorize_error(&errors, DSM_ERROR_MAX),
            PngDepth::Eight,
        )?;
        errors_maps.push(errors);
        results.push(DsmResult {
            scores,
            by_class,
            path,
        });
    }
    Ok((results, errors_maps))
}

/// The MAE per class of [`DFC_CLASSES`], after the all-cells registration (the filtered score
/// masks foliage and water, so its registration cannot be used for them).
fn class_maes(
    dsm: &Image,
    scores: &DsmScores,
    w: &WorldTruth,
) -> Vec<(String, Option<f64>, usize)> {
    match (scores.raw.dx, scores.raw.dy, scores.raw.offset) {
        (Some(dx), Some(dy), Some(offset)) => {
            let aligned = align::apply(dsm, dx, dy, offset);
            DFC_CLASSES
                .iter()
                .map(|&(c, n)| {
                    let (mae, cells) = class_mae(&aligned, &w.truth.dsm, &w.cls, c);
                    (n.to_string(), mae, cells)
                })
                .collect()
        }
        _ => DFC_CLASSES
            .iter()
            .map(|&(_, n)| (n.to_string(), None, 0))
            .collect(),
    }
}

/// The error map and histogram's cells: the headline score's (water and foliage masked) after
/// its registration.
fn headline_errors(dsm: &Image, scores: &DsmScores, truth: &Truth) -> Image {
    match scores.filtered.dx.zip(scores.filtered.dy) {
        Some((dx, dy)) => {
            let aligned = align::apply(dsm, dx, dy, scores.filtered.offset.unwrap_or(0.0));
            filtered_errors(&aligned, truth)
        }
        None => Image::filled(truth.grid.width, truth.grid.height, 1, f32::NAN),
    }
}

/// Mean |aligned − truth| over the cells of DFC class `c` finite in both: (MAE, cells).
fn class_mae(aligned: &Image, truth: &Image, cls: &Image, c: u8) -> (Option<f64>, usize) {
    let (mut sum, mut n) = (0.0f64, 0usize);
    for ((&p, &t), &k) in aligned.data().iter().zip(truth.data()).zip(cls.data()) {
        if p.is_finite() && t.is_finite() && class_code(k) == c {
            sum += (p - t).abs() as f64;
            n += 1;
        }
    }
    ((n > 0).then(|| sum / n as f64), n)
}

/// |aligned − truth| on the cells of the headline score (water and foliage masked), NaN elsewhere.
fn filtered_errors(aligned: &Image, truth: &Truth) -> Image {
    let (w, h) = truth.dsm.size();
    let ex = &truth.exclusions;
    let data = (0..w * h)
        .map(|i| {
            let (p, t) = (aligned.data()[i], truth.dsm.data()[i]);
            if ex.water.data()[i] || ex.foliage.data()[i] || !p.is_finite() || !t.is_finite() {
                f32::NAN
            } else {
                (p - t).abs()
            }
        })
        .collect();
    Image::new(w, h, 1, data).expect("the truth's size")
}

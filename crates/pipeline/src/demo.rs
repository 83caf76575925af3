//! The whole chain on a procedural world with exact ground truth, told as SeasonStereo's story:
//! render a pair, vary its appearance through the four seasons with the built-in model (geometry
//! untouched), match the synchronic pair and a winter↔summer pair, triangulate both disparities
//! through the RPC cameras into DSMs, score them against the truth DSM with the benchmark's
//! protocol, and write an HTML report. Offline, CPU only, deterministic.

#[cfg(feature = "network")]
pub mod ablation;
mod figures;

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use camera::{RpcModel, UtmZone};
use matching::{Aggregation, Paths, SgmParams};
use raster::formats::{read_homographies, write_png, PngDepth};
use raster::{colormap, Image, Mask};
use synth::{BuiltinSeasons, Season, SeasonGenerator, SourceImage};
use world::{class, WorldParams};

use crate::eval::align;
use crate::eval::layout::{AoiRule, TruthFiles};
use crate::eval::metrics::{score_dsm, DsmScores};
use crate::eval::protocol::Protocol;
use crate::eval::{predicted_dsm, Truth};
use crate::matcher::{Matcher, RangeSource};
use crate::metrics::{error_map, score_disparity, DisparityScores};
use crate::pairs::PairPaths;
use crate::progress::{track, Progress};
use crate::report::Report;
use crate::world_io::{mask_picture, save_world};

pub use figures::{dsm_picture, hillshade, thumbnail};

/// What the demo runs on.
#[derive(Clone, Debug)]
pub struct DemoOptions {
    /// Image size of the world, pixels.
    pub size: usize,
    /// Seed of the world and of the built-in seasonal model.
    pub seed: u64,
    /// Folder of the report and its images.
    pub out_dir: PathBuf,
    pub sgm: SgmParams,
}

/// Altitude scores of one DSM: the benchmark's numbers and the MAE per ground-truth class.
#[derive(Clone, Debug)]
pub struct DsmResult {
    pub scores: DsmScores,
    /// (DFC class name, MAE in metres after the all-cells registration, cells) per class of the
    /// truth's `_CLS.tif`.
    pub by_class: Vec<(String, Option<f64>, usize)>,
    /// The DSM (float32 GeoTIFF on the truth's grid).
    pub path: PathBuf,
}

/// One pair the demo matched.
#[derive(Clone, Debug)]
pub struct PairResult {
    /// "synchronic" or "winter ↔ summer".
    pub name: String,
    /// Disparity scores over the pixels visible in both views.
    pub visible: DisparityScores,
    /// Disparity scores per class of the left view (visible pixels).
    pub by_class: Vec<(String, DisparityScores)>,
    pub dsm: DsmResult,
    /// The predicted disparity (NPY float32).
    pub disparity: PathBuf,
}

/// What the demo measured.
#[derive(Clone, Debug)]
pub struct DemoSummary {
    /// Synchronic pair: scores over the pixels visible in both views.
    pub visible: DisparityScores,
    /// Synchronic pair: scores per class of the left view (visible pixels).
    pub by_class: Vec<(String, DisparityScores)>,
    /// The synchronic pair, then the winter ↔ summer pair.
    pub pairs: Vec<PairResult>,
    /// Disparity range searched (from the cameras).
    pub range: (i32, i32),
    /// Wall-clock seconds per step.
    pub seconds: Vec<(String, f64)>,
    pub report: PathBuf,
}

/// The world's OpenEarthMap classes the disparity scores are split by.
const CLASSES: [u8; 6] = [
    class::BUILDING,
    class::ROAD,
    class::DEVELOPED,
    class::RANGELAND,
    class::TREE,
    class::WATER,
];

/// DFC2019 classes of the truth DSM's `_CLS.tif` (as [`crate::world_io::dfc_class`] writes them).
const DFC_CLASSES: [(u8, &str); 4] = [(2, "ground"), (6, "building"), (5, "foliage"), (9, "water")];

/// Altitude errors at and above this are the brightest colour of the error maps, metres.
const DSM_ERROR_MAX: f32 = 3.0;

/// The `season` variant of one view of a world (image id `id`) by the built-in appearance model,
/// the view's exact classes as hints: colours change, geometry does not, so the true disparity
/// of any season pair is the synchronic one.
pub fn season_variant(
    generator: &BuiltinSeasons,
    id: &str,
    view: &world::View,
    season: Season,
) -> Result<Image> {
    let source = SourceImage::new(id, &view.image).with_classes(&view.classes);
    generator
        .generate(&source, season)
        .with_context(|| format!("the {season} variant of {id}"))
}

/// Runs the demo and writes `out_dir/report.html`.
pub fn run_demo(opts: &DemoOptions, progress: &dyn Progress) -> Result<DemoSummary> {
    let out = &opts.out_dir;
    let mut seconds = Vec::new();
    let mut clock = Instant::now();
    let mut lap = |name: &str, seconds: &mut Vec<(String, f64)>| {
        seconds.push((name.to_string(), clock.elapsed().as_secs_f64()));
        clock = Instant::now();
    };

    let params = WorldParams::new(opts.size, opts.seed);
    let world = track(progress, "rendering the world", opts.size, |cb| {
        world::generate(&params, &world::Neutral, cb)
    })
    .map_err(anyhow::Error::msg)
    .context("generating the procedural world")?;
    lap("render the world", &mut seconds);
    let name = format!("WORLD_{}", opts.seed);
    let world_dir = out.join("world");
    let pair = save_world(&world, &world_dir, &name)?;
    lap(
        "write the world (release layout, RPCs, truth DSM)",
        &mut seconds,
    );

    // The four seasons of the left image and the summer of the right one, by the built-in
    // appearance model with the exact classes as hints: pointwise colour changes and smooth
    // fields only, so every edge stays where it was and the true disparity is unchanged.
    let (left_id, right_id) = crate::world_io::image_ids(&name)?;
    let generator = BuiltinSeasons::new(opts.seed);
    let seasons_dir = out.join("seasons");
    let mut left_seasons = Vec::new();
    for season in Season::ALL {
        let image = season_variant(&generator, &left_id, &world.left, season)?;
        write_png(
            seasons_dir.join(format!("left_{season}_thumb.png")),
            &thumbnail(&image, 256)?,
            PngDepth::Eight,
        )?;
        left_seasons.push((season, image));
    }
    let left_winter = left_seasons
        .iter()
        .find(|(s, _)| *s == Season::Winter)
        .map(|(_, i)| i.clone())
        .expect("every season was generated");
    let right_summer = season_variant(&generator, &right_id, &world.right, Season::Summer)?;
    let winter_path = seasons_dir.join(format!("{left_id}__winter.iio"));
    let summer_path = seasons_dir.join(format!("{right_id}__summer.iio"));
    raster::write_image(&winter_path, &left_winter)?;
    raster::write_image(&summer_path, &right_summer)?;
    lap("seasonal variants (built-in model)", &mut seconds);

    // The search range comes from the cameras and the scene's altitude range, as it should for
    // satellite pairs, not from image matches.
    let range = world.disparity_range();
    let matcher = Matcher::Classical(opts.sgm.clone());
    let synchronic = matcher
        .disparity(
            &world.left.image,
            &world.right.image,
            RangeSource::Given(range),
            progress,
        )?
        .disparity;
    lap("match the synchronic pair", &mut seconds);
    let cross = matcher
        .disparity(
            &left_winter,
            &right_summer,
            RangeSource::Given(range),
            progress,
        )?
        .disparity;
    lap("match the winter ↔ summer pair", &mut seconds);

    // Disparity scores and pictures.
    let size = opts.size;
    let visible = Mask::from_fn(size, size, |x, y| !world.occluded.get(x, y));
    let classes = &world.left.classes;
    let disparity_scores = |predicted: &Image| -> Result<_> {
        let all = score_disparity(predicted, &world.disparity, &visible)?;
        let by_class: Vec<(String, DisparityScores)> = CLASSES
            .iter()
            .map(|&c| {
                let region = Mask::from_fn(size, size, |x, y| {
                    visible.get(x, y) && classes.get(x, y, 0) as u8 == c
                });
                Ok((
                    class::NAMES[c as usize].to_string(),
                    score_disparity(predicted, &world.disparity, &region)?,
                ))
            })
            .collect::<Result<_>>()?;
        Ok((all, by_class))
    };
    let visible_errors = |predicted: &Image| -> Result<Image> {
        let errors = error_map(predicted, &world.disparity)?;
        Ok(Image::new(
            size,
            size,
            1,
            errors
                .data()
                .iter()
                .zip(visible.data())
                .map(|(&e, &v)| if v { e } else { f32::NAN })
                .collect(),
        )?)
    };
    let (sync_scores, sync_by_class) = disparity_scores(&synchronic)?;
    let (cross_scores, cross_by_class) = disparity_scores(&cross)?;
    let sync_errors = visible_errors(&synchronic)?;
    let cross_errors = visible_errors(&cross)?;
    let truth_range = world.disparity.finite_range();
    write_png(out.join("left.png"), &world.left.image, PngDepth::Eight)?;
    write_png(out.join("right.png"), &world.right.image, PngDepth::Eight)?;
    write_png(out.join("left_winter.png"), &left_winter, PngDepth::Eight)?;
    write_png(out.join("right_summer.png"), &right_summer, PngDepth::Eight)?;
    colormap::write_colorized_png(out.join("truth.png"), &world.disparity, truth_range)?;
    colormap::write_colorized_png(out.join("prediction.png"), &synchronic, truth_range)?;
    colormap::write_colorized_png(out.join("prediction_cross_season.png"), &cross, truth_range)?;
    for (file, errors) in [
        ("error.png", &sync_errors),
        ("error_cross_season.png", &cross_errors),
    ] {
        write_png(
            out.join(file),
            &colormap::colorize_error(errors, 3.0),
            PngDepth::Eight,
        )?;
    }
    write_png(
        out.join("occlusion.png"),
        &mask_picture(&world.occluded),
        PngDepth::Eight,
    )?;
    let sync_path = out.join("prediction.iio");
    let cross_path = out.join("prediction_cross_season.iio");
    raster::write_image(&sync_path, &synchronic)?;
    raster::write_image(&cross_path, &cross)?;
    lap("score the disparities, write images", &mut seconds);

    // DSMs through the files the benchmark's evaluation reads: the homographies and RPCs written
    // with the world, the truth DSM and its classes.
    let rpc_left = RpcModel::read_rpcm_json(world_dir.join("rpc").join(format!("{left_id}.json")))
        .context("reading the left camera of the world")?;
    let rpc_right =
        RpcModel::read_rpcm_json(world_dir.join("rpc").join(format!("{right_id}.json")))
            .context("reading the right camera of the world")?;
    let (h_left, h_right) = read_homographies(&pair.homography)?;
    let aoi = AoiRule::default().aoi_of(&left_id);
    let truth_files = TruthFiles::new(&world_dir.join("truth"), &aoi);
    let zone = UtmZone::from_lonlat(rpc_left.lon_offset, rpc_left.lat_offset);
    let truth = Truth::read_with(&truth_files, &aoi, zone, Protocol::Release)?;
    let cls = raster::formats::read_tiff(&truth_files.cls)
        .with_context(|| format!("reading {}", truth_files.cls.display()))?
        .image
        .channel(0);
    let mut dsms = Vec::new();
    for (file, disparity) in [("synchronic", &synchronic), ("cross_season", &cross)] {
        let (dsm, _) = predicted_dsm(
            disparity,
            &h_left,
            &h_right,
            &rpc_left,
            &rpc_right,
            &truth.grid,
        )?;
        let path = out.join("dsm").join(format!("{file}.tif"));
        camera::write_dsm(&path, &dsm, &truth.grid)
            .with_context(|| format!("writing {}", path.display()))?;
        dsms.push((file, dsm, path));
    }
    lap("triangulate (RPC) and grid the two DSMs", &mut seconds);
    let score_params = Protocol::Release.score_params();
    let cell = truth.grid.resolution;
    let height_range = colormap::robust_range(&truth.dsm);
    write_png(
        out.join("dsm_truth.png"),
        &dsm_picture(&truth.dsm, cell, height_range),
        PngDepth::Eight,
    )?;
    let mut dsm_results = Vec::new();
    let mut dsm_errors = Vec::new();
    for (file, dsm, path) in dsms {
        let scores = score_dsm(&dsm, &truth.dsm, &truth.exclusions, &score_params)?;
        // Per class: after the all-cells registration (the filtered score masks foliage and
        // water, so its registration cannot be used for them).
        let by_class = match (scores.raw.dx, scores.raw.dy, scores.raw.offset) {
            (Some(dx), Some(dy), Some(offset)) => {
                let aligned = align::apply(&dsm, dx, dy, offset);
                DFC_CLASSES
                    .iter()
                    .map(|&(c, n)| {
                        let (mae, cells) = class_mae(&aligned, &truth.dsm, &cls, c);
                        (n.to_string(), mae, cells)
                    })
                    .collect()
            }
            _ => DFC_CLASSES
                .iter()
                .map(|&(_, n)| (n.to_string(), None, 0))
                .collect(),
        };
        // Error map and histogram: the headline score's cells (water and foliage masked) after
        // its registration.
        let errors = match scores.filtered.dx.zip(scores.filtered.dy) {
            Some((dx, dy)) => {
                let aligned = align::apply(&dsm, dx, dy, scores.filtered.offset.unwrap_or(0.0));
                filtered_errors(&aligned, &truth)
            }
            None => Image::filled(truth.grid.width, truth.grid.height, 1, f32::NAN),
        };
        write_png(
            out.join(format!("dsm_{file}.png")),
            &dsm_picture(&dsm, cell, height_range),
            PngDepth::Eight,
        )?;
        write_png(
            out.join(format!("dsm_error_{file}.png")),
            &colormap::colorize_error(&errors, DSM_ERROR_MAX),
            PngDepth::Eight,
        )?;
        dsm_errors.push(errors);
        dsm_results.push(DsmResult {
            scores,
            by_class,
            path,
        });
    }
    lap(
        "score the DSMs (benchmark protocol), write images",
        &mut seconds,
    );

    let mut dsm_results = dsm_results.into_iter();
    let pairs = vec![
        PairResult {
            name: "synchronic".into(),
            visible: sync_scores.clone(),
            by_class: sync_by_class.clone(),
            dsm: dsm_results.next().expect("two DSMs"),
            disparity: sync_path,
        },
        PairResult {
            name: "winter ↔ summer".into(),
            visible: cross_scores,
            by_class: cross_by_class,
            dsm: dsm_results.next().expect("two DSMs"),
            disparity: cross_path,
        },
    ];

    let report = out.join("report.html");
    let context = ReportContext {
        opts,
        pair: &pair,
        truth_dsm: &truth_files.dsm,
        winter: &winter_path,
        summer: &summer_path,
        range,
        generator: format!("built-in appearance model, seed {}", opts.seed),
    };
    write_report(
        &report,
        &context,
        &pairs,
        [&sync_errors, &cross_errors],
        [&dsm_errors[0], &dsm_errors[1]],
        &seconds,
    )?;
    Ok(DemoSummary {
        visible: sync_scores,
        by_class: sync_by_class,
        pairs,
        range,
        seconds,
        report,
    })
}

/// Mean |aligned − truth| over the cells of DFC class `c` finite in both: (MAE, cells).
fn class_mae(aligned: &Image, truth: &Image, cls: &Image, c: u8) -> (Option<f64>, usize) {
    let (mut sum, mut n) = (0.0f64, 0usize);
    for ((&p, &t), &k) in aligned.data().iter().zip(truth.data()).zip(cls.data()) {
        if p.is_finite() && t.is_finite() && crate::eval::metrics::class_code(k) == c {
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

/// Formats an optional fraction as a percentage.
pub fn percent(v: Option<f64>) -> String {
    v.map_or("–".into(), |v| format!("{:.2} %", 100.0 * v))
}

/// Formats an optional error in pixels.
pub fn pixels(v: Option<f64>) -> String {
    v.map_or("–".into(), |v| format!("{v:.3} px"))
}

/// Formats an optional altitude error in metres.
pub fn metres(v: Option<f64>) -> String {
    v.map_or("–".into(), |v| format!("{v:.3} m"))
}

/// Command-line flags of `predict`/`eval` giving the matcher `p` (empty for the defaults).
pub fn matcher_flags(p: &SgmParams) -> String {
    let d = SgmParams::default();
    let mut f = Vec::new();
    if p.aggregation != d.aggregation {
        f.push(match p.aggregation {
            Aggregation::Mgm => "--method mgm".to_string(),
            Aggregation::Sgm => "--method sgm".to_string(),
        });
    }
    if p.census != d.census {
        f.push(format!("--census {}x{}", p.census.width, p.census.height));
    }
    if p.p1 != d.p1 {
        f.push(format!("--p1 {}", p.p1));
    }
    if p.p2 != d.p2 {
        f.push(format!("--p2 {}", p.p2));
    }
    if p.p2_adaptive != d.p2_adaptive {
        f.push(format!("--p2-adaptive {}", p.p2_adaptive.unwrap_or(0.0)));
    }
    if p.paths != d.paths && p.paths == Paths::Four {
        f.push("--four-paths".into());
    }
    if p.lr_tolerance != d.lr_tolerance {
        f.push(format!("--lr-tolerance {}", p.lr_tolerance.unwrap_or(0.0)));
    }
    if p.uniqueness != d.uniqueness {
        f.push(format!("--uniqueness {}", p.uniqueness.unwrap_or(0.0)));
    }
    if p.speckle != d.speckle {
        match &p.speckle {
            Some(s) => f.push(format!(
                "--speckle {} --speckle-diff {}",
                s.min_area, s.max_diff
            )),
            None => f.push("--speckle 0".into()),
        }
    }
    f.iter().map(|s| format!(" {s}")).collect()
}

fn score_row(name: &str, s: &DisparityScores) -> Vec<String> {
    vec![
        name.to_string(),
        s.evaluated.to_string(),
        percent(s.coverage),
        pixels(s.mae),
        pixels(s.rmse),
        percent(s.bad1),
        percent(s.bad2),
    ]
}

/// What the report says about the run besides the scores.
struct ReportContext<'a> {
    opts: &'a DemoOptions,
    pair: &'a PairPaths,
    truth_dsm: &'a Path,
    winter: &'a Path,
    summer: &'a Path,
    range: (i32, i32),
    generator: String,
}

fn write_report(
    path: &Path,
    c: &ReportContext<'_>,
    pairs: &[PairResult],
    disparity_errors: [&Image; 2],
    dsm_errors: [&Image; 2],
    seconds: &[(String, f64)],
) -> Result<()> {
    let opts = c.opts;
    let (sync, cross) = (&pairs[0], &pairs[1]);
    let mut r = Report::new("seasonstereo demo: a satellite pair across the seasons, to a DSM");
    r.paragraph(&format!(
        "SeasonStereo matches satellite pairs whose two images were taken in different seasons and turns \
         them into Digital Surface Models. This report runs that story on a procedural {s}×{s} px world \
         (seed {seed}, 0.5 m per pixel) with exact ground truth: a rectified pair from two pushbroom cameras \
         with different incidence angles, its RPC cameras and its true DSM. The classical matcher (census + \
         MGM) matches the synchronic pair and a winter ↔ summer pair with the same geometry; both \
         disparities are triangulated through the RPCs into DSMs and scored against the truth with the \
         benchmark's protocol. Everything ran offline on the CPU. The built-in seasons only recolour the \
         scene; real multi-date pairs also move shadows, hide texture under snow and change the ground, so \
         real cross-season pairs are usually harder than this one.",
        s = opts.size,
        seed = opts.seed
    ));

    r.heading("1. One scene, four seasons");
    r.paragraph(&format!(
        "The left image through the four seasons of the {}, with the world's \
         classes as hints. It only changes colours, pointwise or through smooth low-frequency fields \
         (snow, foliage, haze, illumination), so every edge stays where it is and the true disparity \
         of any season pair is the synchronic one. SeasonStereo trains on such synthetic pairs; \
         `seasonstereo synthesize` applies the same model (or a generative API) to real pairs.",
        c.generator
    ));
    let thumbs: Vec<(String, String)> = Season::ALL
        .iter()
        .map(|s| {
            (
                format!("seasons/left_{s}_thumb.png"),
                format!("left image, {s}"),
            )
        })
        .collect();
    let thumb_refs: Vec<(&str, &str)> = thumbs
        .iter()
        .map(|(a, b)| (a.as_str(), b.as_str()))
        .collect();
    r.figures(&thumb_refs);

    r.heading("2. Two pairs: synchronic and winter ↔ summer");
    r.figures(&[
        ("left.png", "synchronic pair: left"),
        ("right.png", "synchronic pair: right"),
        ("occlusion.png", "left pixels hidden in the right view"),
    ]);
    r.figures(&[
        ("left_winter.png", "cross-season pair: left in winter"),
        ("right_summer.png", "cross-season pair: right in summer"),
    ]);

    r.heading("3. Disparities");
    r.paragraph(&format!(
        "Search range {lo}:{hi} px, derived from the cameras and the scene's altitude range (not from image \
         matches, which miss tall buildings on multi-date pairs). Disparity is on the left view: the left \
         pixel (x, y) matches the right pixel (x − d, y). Black: rejected by the consistency checks.",
        lo = c.range.0,
        hi = c.range.1
    ));
    r.figures(&[
        ("truth.png", "true disparity"),
        ("prediction.png", "synchronic disparity"),
        ("prediction_cross_season.png", "winter ↔ summer disparity"),
    ]);
    r.figures(&[
        ("error.png", "synchronic |error|, 0–3 px"),
        ("error_cross_season.png", "winter ↔ summer |error|, 0–3 px"),
    ]);

    r.heading("4. DSMs through the RPC cameras");
    r.paragraph(
        "Each disparity is triangulated with the full RPCs (s2p's iteration) and gridded on the truth \
         DSM's UTM grid, highest point per cell, after the benchmark's evaluation mask (32 px border). \
         Colour: altitude (the truth's 2–98th percentile); shading: hillshade lit from the north-west. \
         Black: no point fell in the cell.",
    );
    r.figures(&[
        ("dsm_truth.png", "truth DSM"),
        ("dsm_synchronic.png", "DSM from the synchronic pair"),
        ("dsm_cross_season.png", "DSM from the winter ↔ summer pair"),
    ]);
    r.figures(&[
        (
            "dsm_error_synchronic.png",
            "synchronic |altitude error|, 0–3 m",
        ),
        (
            "dsm_error_cross_season.png",
            "winter ↔ summer |altitude error|, 0–3 m",
        ),
    ]);
    r.paragraph(
        "Error maps: after the benchmark's registration (integer shift by NCC, then vertical offset), on \
         the cells of its headline score (water and foliage masked, black).",
    );

    r.heading("5. Synchronic vs cross-season");
    r.paragraph(
        "Altitude MAE as the benchmark computes it: each score after its own registration on the truth \
         masked for it; \"filtered\" (water and foliage masked) is the headline number of the paper's \
         tables. Coverage: share of the truth's cells with a predicted height (the 32 px border the \
         protocol trims is never covered). Disparity scores are on the left pixels visible in both views.",
    );
    let dsm_row = |p: &PairResult| {
        let s = &p.dsm.scores;
        vec![
            p.name.clone(),
            metres(s.mae_filtered),
            metres(s.mae_no_water),
            metres(s.mae_raw),
            percent(s.coverage),
            percent(p.visible.coverage),
            pixels(p.visible.mae),
            percent(p.visible.bad1),
            percent(p.visible.bad2),
        ]
    };
    r.table(
        &[
            "pair",
            "DSM MAE (filtered)",
            "DSM MAE (no water)",
            "DSM MAE (all)",
            "DSM coverage",
            "disparity coverage",
            "disparity MAE",
            "bad-1",
            "bad-2",
        ],
        &[dsm_row(sync), dsm_row(cross)],
    );
    r.paragraph(
        "Altitude MAE per class of the truth (after the all-cells registration; cells finite in both):",
    );
    let class_rows: Vec<Vec<String>> = DFC_CLASSES
        .iter()
        .enumerate()
        .map(|(i, (_, name))| {
            let (s, x) = (&sync.dsm.by_class[i], &cross.dsm.by_class[i]);
            vec![
                name.to_string(),
                s.2.to_string(),
                metres(s.1),
                x.2.to_string(),
                metres(x.1),
            ]
        })
        .collect();
    r.table(
        &[
            "truth class",
            "cells (synchronic)",
            "MAE (synchronic)",
            "cells (winter ↔ summer)",
            "MAE (winter ↔ summer)",
        ],
        &class_rows,
    );
    r.histograms(
        &[
            ("synchronic", dsm_errors[0].data()),
            ("winter ↔ summer", dsm_errors[1].data()),
        ],
        DSM_ERROR_MAX,
        30,
        "absolute altitude error (m), headline cells",
    );

    r.heading("6. Disparity scores per class (visible pixels)");
    let header = [
        "region", "pixels", "coverage", "MAE", "RMSE", "bad-1", "bad-2",
    ];
    for p in pairs {
        r.paragraph(&format!("{} pair:", p.name));
        let mut rows = vec![score_row("all visible", &p.visible)];
        rows.extend(p.by_class.iter().map(|(n, s)| score_row(n, s)));
        r.table(&header, &rows);
    }
    r.histograms(
        &[
            ("synchronic", disparity_errors[0].data()),
            ("winter ↔ summer", disparity_errors[1].data()),
        ],
        3.0,
        30,
        "absolute disparity error (px), visible matched pixels",
    );

    r.heading("Matcher");
    r.paragraph(&opts.sgm.describe());

    r.heading("Timings");
    let mut rows: Vec<Vec<String>> = seconds
        .iter()
        .map(|(n, s)| vec![n.clone(), format!("{s:.2} s")])
        .collect();
    let total: f64 = seconds.iter().map(|(_, s)| s).sum();
    rows.push(vec!["total".into(), format!("{total:.2} s")]);
    r.table(&["step", "wall clock"], &rows);

    r.heading("Reproduce");
    let out = opts.out_dir.display().to_string();
    let world = format!("{out}/world");
    let stem = &c.pair.stem;
    let ids = dataset::PairStem::parse(stem)?;
    let (left_id, right_id) = (ids.left.id.as_str(), ids.right.id.as_str());
    let flags = matcher_flags(&opts.sgm);
    let truth = c.truth_dsm.display().to_string();
    let (lo, hi) = c.range;
    let dsm_cmd = |disparity: &str, dsm: &str| {
        format!(
            "seasonstereo dsm {disparity} --homography {world}/homography/{stem}.npz \
             --rpc-left {world}/rpc/{left_id}.json --rpc-right {world}/rpc/{right_id}.json \
             --like {truth} --border 32 -o {dsm}"
        )
    };
    r.paragraph("This whole report:");
    r.code(&format!(
        "seasonstereo demo --size {} --seed {} -o {out}{flags}",
        opts.size, opts.seed
    ));
    r.paragraph(
        "Step by step on the demo's files (`dsm --border 32` keeps a few more pixels than the protocol's \
         evaluation mask, so the all-cells MAE may differ in the last digit; `eval` applies the protocol \
         exactly):",
    );
    r.code(&[
        "# the world, its RPCs and its truth DSM, in the benchmark's layout".to_string(),
        format!("seasonstereo world --size {} --seed {} -o {world}", opts.size, opts.seed),
        "# disparities of the synchronic and the winter ↔ summer pair".to_string(),
        format!(
            "seasonstereo predict --range {lo}:{hi}{flags} {world}/L/{stem}.iio {world}/R/{stem}.iio -o {out}/prediction.iio"
        ),
        format!(
            "seasonstereo predict --range {lo}:{hi}{flags} {} {} -o {out}/prediction_cross_season.iio",
            c.winter.display(),
            c.summer.display()
        ),
        "# DSMs on the truth's grid (highest point per cell, 32 px border as the benchmark)".to_string(),
        dsm_cmd(&format!("{out}/prediction.iio"), &format!("{out}/dsm/synchronic.tif")),
        dsm_cmd(
            &format!("{out}/prediction_cross_season.iio"),
            &format!("{out}/dsm/cross_season.tif"),
        ),
        "# the benchmark's scores of DSMs on the truth's grid".to_string(),
        format!("seasonstereo score {out}/dsm/synchronic.tif {out}/dsm/cross_season.tif --truth {truth}"),
        "# the benchmark's whole protocol on the world's synchronic pair (Table 1 layout)".to_string(),
        format!("seasonstereo eval --world {world}{flags} -o {out}/eval"),
    ]
    .join("\n"));
    r.paragraph("On your own data (raw images and RPCs; a truth DSM <AOI>_DSM.tif with <AOI>_CLS.tif beside it):");
    r.code(
        "# raw pair → rectified → disparity → DSM, scored with the benchmark's metric\n\
         seasonstereo reconstruct LEFT.tif RIGHT.tif --rpc-left LEFT.json --rpc-right RIGHT.json \\\n    \
         --like TRUTH_DSM.tif --truth TRUTH_DSM.tif -o dsm.tif\n\
         # score DSMs you already have on the truth's grid\n\
         seasonstereo score dsm.tif --truth TRUTH_DSM.tif\n\
         # rectified test splits in the release's layout, the paper's Table 1\n\
         seasonstereo eval --split Jacksonville=DATA/JAX --rpc-dir DATA/root_dir \\\n    \
         --truth-dir DATA/Track3-Truth --method mgm -o out/eval",
    );
    r.write(path)
}

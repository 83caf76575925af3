//! The whole chain on a procedural world with exact ground truth, told as SeasonStereo's story:
//! render a pair, vary its appearance through the four seasons with the built-in model (geometry
//! untouched), match the synchronic pair and a winter↔summer pair, triangulate both disparities
//! through the RPC cameras into DSMs, score them against the truth DSM with the benchmark's
//! protocol; then the same world on six dates, its pairs chosen and fused into one DSM against the
//! best pair alone; and write an HTML report. Offline, CPU only, deterministic.

#[cfg(feature = "network")]
pub mod ablation;
mod disparities;
mod dsms;
mod figures;
mod format;
mod laps;
mod many_dates;
mod options;
mod report;
mod summary;

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use raster::formats::{write_png, PngDepth};
use raster::{colormap, Image};
use synth::{BuiltinSeasons, Season, SeasonGenerator, SourceImage};
use world::{World, WorldParams};

use disparities::{score_disparities, DisparityResult};
use dsms::{read_world_truth, score_dsms, triangulate_dsms};
use eval::world_io::{image_ids, mask_picture, save_world};
use laps::Laps;
use report::{write_report, ReportContext};
use workflow::matcher::{Matcher, RangeSource};
use workflow::progress::{track, Progress};

pub use figures::thumbnail;
pub use format::{matcher_flags, metres, percent, pixels};
pub use many_dates::{ChosenPair, ManyDatesResult, MANY_DATES_SIZE};
pub use options::DemoOptions;
pub use products::{dsm_picture, hillshade};
pub use summary::{DemoSummary, DsmResult, PairResult};

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
    let mut laps = Laps::start();
    let world = render_world(opts, progress)?;
    laps.lap("render the world");
    let name = format!("WORLD_{}", opts.seed);
    let world_dir = out.join("world");
    let pair = save_world(&world, &world_dir, &name)?;
    laps.lap("write the world (release layout, RPCs, truth DSM)");
    let (left_id, right_id) = image_ids(&name)?;
    let seasons = seasonal_pair(opts, &world, &left_id, &right_id)?;
    laps.lap("seasonal variants (built-in model)");

    // The search range comes from the cameras and the scene's altitude range, as it should for
    // satellite pairs, not from image matches.
    let range = world.disparity_range();
    let matcher = Matcher::Classical(opts.sgm.clone());
    let synchronic = match_pair(
        &matcher,
        &world.left.image,
        &world.right.image,
        range,
        progress,
    )?;
    laps.lap("match the synchronic pair");
    let cross = match_pair(
        &matcher,
        &seasons.left_winter,
        &seasons.right_summer,
        range,
        progress,
    )?;
    laps.lap("match the winter ↔ summer pair");
    let sync_scores = score_disparities(&world, &synchronic)?;
    let cross_scores = score_disparities(&world, &cross)?;
    write_disparity_pictures(
        out,
        &world,
        &seasons,
        [&synchronic, &cross],
        [&sync_scores, &cross_scores],
    )?;
    let sync_path = out.join("prediction.iio");
    let cross_path = out.join("prediction_cross_season.iio");
    raster::write_image(&sync_path, &synchronic)?;
    raster::write_image(&cross_path, &cross)?;
    laps.lap("score the disparities, write images");

    // DSMs through the files the benchmark's evaluation reads: the homographies and RPCs written
    // with the world, the truth DSM and its classes.
    let truth = read_world_truth(&world_dir, &pair, &left_id, &right_id)?;
    let dsms = triangulate_dsms(
        out,
        &truth,
        [("synchronic", &synchronic), ("cross_season", &cross)],
    )?;
    laps.lap("triangulate (RPC) and grid the two DSMs");
    let (dsm_results, dsm_errors) = score_dsms(out, &truth, dsms)?;
    laps.lap("score the DSMs (benchmark protocol), write images");

    let mut dsm_results = dsm_results.into_iter();
    let pairs = vec![
        pair_result("synchronic", &sync_scores, dsm_results.next(), sync_path),
        pair_result(
            "winter ↔ summer",
            &cross_scores,
            dsm_results.next(),
            cross_path,
        ),
    ];
    let many_dates = many_dates::run_many_dates(opts, &matcher, progress)?;
    laps.lap("six dates: render, reconstruct and fuse 6 pairs, the best pair alone");

    let report = out.join("report.html");
    let context = ReportContext {
        opts,
        pair: &pair,
        truth_dsm: truth.files.dsm.clone(),
        cross_season: [seasons.winter_path.clone(), seasons.summer_path.clone()],
        range,
        generator: format!("built-in appearance model, seed {}", opts.seed),
    };
    write_report(
        &report,
        &context,
        &pairs,
        &many_dates,
        [&sync_scores.errors, &cross_scores.errors],
        [&dsm_errors[0], &dsm_errors[1]],
        &laps.seconds,
    )?;
    Ok(DemoSummary {
        visible: sync_scores.visible,
        by_class: sync_scores.by_class,
        pairs,
        range,
        many_dates,
        seconds: laps.seconds,
        report,
    })
}

/// Renders the procedural world of the options' size and seed.
fn render_world(opts: &DemoOptions, progress: &dyn Progress) -> Result<World> {
    let params = WorldParams::new(opts.size, opts.seed);
    track(progress, "rendering the world", opts.size, |cb| {
        world::generate(&params, &world::Neutral, cb)
    })
    .map_err(anyhow::Error::msg)
    .context("generating the procedural world")
}

/// The cross-season pair: the left image in winter, the right one in summer.
struct SeasonalPair {
    left_winter: Image,
    right_summer: Image,
    winter_path: PathBuf,
    summer_path: PathBuf,
}

/// The four seasons of the left image (thumbnails for the report) and the summer of the right
/// one, by the built-in appearance model with the exact classes as hints: pointwise colour
/// changes and smooth fields only, so every edge stays where it was and the true disparity is
/// unchanged. The cross-season pair is written under `seasons/` for the report's commands.
fn seasonal_pair(
    opts: &DemoOptions,
    world: &World,
    left_id: &str,
    right_id: &str,
) -> Result<SeasonalPair> {
    let generator = BuiltinSeasons::new(opts.seed);
    let seasons_dir = opts.out_dir.join("seasons");
    let mut left_seasons = Vec::new();
    for season in Season::ALL {
        let image = season_variant(&generator, left_id, &world.left, season)?;
        write_png(
            seasons_dir.join(format!("left_{season}_thumb.png")),
            &thumbnail(&image, 256)?,
            PngDepth::Eight,
        )?;
        left_seasons.push((season, image));
    }
    let left_winter = left_seasons
        .into_iter()
        .find(|(s, _)| *s == Season::Winter)
        .map(|(_, i)| i)
        .expect("every season was generated");
    let right_summer = season_variant(&generator, right_id, &world.right, Season::Summer)?;
    let winter_path = seasons_dir.join(format!("{left_id}__winter.iio"));
    let summer_path = seasons_dir.join(format!("{right_id}__summer.iio"));
    raster::write_image(&winter_path, &left_winter)?;
    raster::write_image(&summer_path, &right_summer)?;
    Ok(SeasonalPair {
        left_winter,
        right_summer,
        winter_path,
        summer_path,
    })
}

/// The disparity of a pair over the range the cameras give.
fn match_pair(
    matcher: &Matcher,
    left: &Image,
    right: &Image,
    range: (i32, i32),
    progress: &dyn Progress,
) -> Result<Image> {
    Ok(matcher
        .disparity(left, right, RangeSource::Given(range), progress)?
        .disparity)
}

/// The report's pictures of both pairs: the images, the true and predicted disparities (one
/// colour range, the truth's), the error maps and the occlusions.
fn write_disparity_pictures(
    out: &Path,
    world: &World,
    seasons: &SeasonalPair,
    [synchronic, cross]: [&Image; 2],
    [sync_scores, cross_scores]: [&DisparityResult; 2],
) -> Result<()> {
    let truth_range = world.disparity.finite_range();
    write_png(out.join("left.png"), &world.left.image, PngDepth::Eight)?;
    write_png(out.join("right.png"), &world.right.image, PngDepth::Eight)?;
    write_png(
        out.join("left_winter.png"),
        &seasons.left_winter,
        PngDepth::Eight,
    )?;
    write_png(
        out.join("right_summer.png"),
        &seasons.right_summer,
        PngDepth::Eight,
    )?;
    colormap::write_colorized_png(out.join("truth.png"), &world.disparity, truth_range)?;
    colormap::write_colorized_png(out.join("prediction.png"), synchronic, truth_range)?;
    colormap::write_colorized_png(out.join("prediction_cross_season.png"), cross, truth_range)?;
    for (file, errors) in [
        ("error.png", &sync_scores.errors),
        ("error_cross_season.png", &cross_scores.errors),
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
    Ok(())
}

/// One pair's disparity and DSM results.
fn pair_result(
    name: &str,
    scores: &DisparityResult,
    dsm: Option<DsmResult>,
    disparity: PathBuf,
) -> PairResult {
    PairResult {
        name: name.into(),
        visible: scores.visible.clone(),
        by_class: scores.by_class.clone(),
        dsm: dsm.expect("two DSMs"),
        disparity,
    }
}

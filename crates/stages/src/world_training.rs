//! A small training set from procedural worlds (`seasonstereo dataset world`), built by the same
//! stages as real data so that every stage is exercised end to end with exact ground truth:
//!
//! 1. per world (seed): the rectified pair and its homographies (the synchronic pair), "raw"
//!    images = the rectified views warped back through the homographies (the world renders no raw
//!    image), the exact class maps in the raw frame, and the segmentation files
//!    `<id>_mask.png` of the exact classes (water 6, tree 5, building 8; release polarity), or,
//!    with [`WorldMasks::Segmenter`], the `masks` stage's offline segmenter on the raw images;
//! 2. `teacher`: SGM on the real pairs (the offline default teacher); the exact disparity is the
//!    LiDAR-like ground truth (`disparity_maps/GT`);
//! 3. `synthesize`: the built-in seasonal model with the world's classes as hints, the fidelity
//!    check, rectification with the world's homographies;
//! 4. `dataset build`: the 25 combinations per pair, masks, subsets and manifest.
//!
//! A validation split (`val/`, other seeds) is built the same way, supervised and scored by the
//! exact disparity (`val/disparity/`, `experiments/sub_val.csv`).
//!
//! Sources live in `<out>/sources/{train,val}/`; everything is resumable.
//!
//! Note: the synthetic views pass through the raw frame and back (two bilinear resamplings), the
//! real views do not, so synthetic views are slightly smoother than real ones.

use std::path::{Path, PathBuf};

use anyhow::{bail, Result};
use dataset::shard::Shard;
use matching::SgmParams;
use raster::formats::{
    write_geotiff, write_homographies, write_npy, write_png, GeoTiffMeta, PngDepth,
};
use raster::geometry::warp_homography;
use raster::{Homography, Image};
use synth::BuiltinSeasons;
use world::{class, WorldParams};

use crate::dataset_build::{run_build, BuildOptions, BuildSummary, MaskDirs};
use crate::masks::{run_masks, ImageSegmenter, MasksOptions, OfflineSegmenter};
use crate::synthesize::{run_synthesize, SynthesizeOptions, SynthesizeSummary};
use crate::teacher::{run_teacher, TeacherOptions};
use workflow::matcher::Matcher;
use workflow::progress::Progress;

/// What `dataset world` builds.
#[derive(Clone, Debug)]
pub struct WorldTrainingOptions {
    /// The dataset folder.
    pub out_dir: PathBuf,
    /// World size, pixels.
    pub size: usize,
    /// Training worlds: seeds `seed`, `seed + 1`, …
    pub train_worlds: usize,
    /// Validation worlds: seeds `seed + 10000`, …
    pub val_worlds: usize,
    pub seed: u64,
    /// Seed of the built-in seasonal model.
    pub generator_seed: u64,
    /// Seed of the S3 draw.
    pub subset_seed: u64,
    /// Centre crop of `synthesize` (worlds smaller than it are kept whole).
    pub crop: usize,
    pub sgm: SgmParams,
    pub previews: bool,
    /// Where the water, tree and building masks come from.
    pub masks: WorldMasks,
}

/// The segmentation masks of a world training set.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum WorldMasks {
    /// The world's exact classes: isolates the other stages from segmentation errors.
    #[default]
    Exact,
    /// The `masks` stage with the offline segmenter on the raw images, as real data goes.
    Segmenter,
}

impl WorldTrainingOptions {
    pub fn new(out_dir: &Path, size: usize, train_worlds: usize, val_worlds: usize) -> Self {
        WorldTrainingOptions {
            out_dir: out_dir.to_path_buf(),
            size,
            train_worlds,
            val_worlds,
            seed: 1,
            generator_seed: 0,
            subset_seed: 0,
            crop: crate::synthesize::DEFAULT_CROP,
            sgm: SgmParams::default(),
            previews: false,
            masks: WorldMasks::Exact,
        }
    }
}

/// What one split went through.
#[derive(Clone, Debug, Default)]
pub struct SplitSummary {
    pub worlds: usize,
    pub synthesize: SynthesizeSummary,
    pub build: BuildSummary,
}

/// What `dataset world` did.
#[derive(Clone, Debug, Default)]
pub struct WorldTrainingSummary {
    pub train: SplitSummary,
    pub val: SplitSummary,
    /// Disparity range of the worlds (the teacher's search range).
    pub range: (i32, i32),
}

/// The image ids of world `seed`: `W<seed:06>_A`, `W<seed:06>_B` (AOI = `W<seed:06>`: the first
/// 7 characters, as the release's AOI rule).
pub fn world_ids(seed: u64) -> (String, String) {
    (format!("W{seed:06}_A"), format!("W{seed:06}_B"))
}

/// Builds the training and validation sets (see the module docs).
pub fn build_world_training(
    opts: &WorldTrainingOptions,
    progress: &dyn Progress,
) -> Result<WorldTrainingSummary> {
    check_world_options(opts)?;
    let range = world_range(opts.size);
    let mut summary = WorldTrainingSummary {
        range,
        ..Default::default()
    };
    for (split, count, first) in [
        ("train", opts.train_worlds, opts.seed),
        ("val", opts.val_worlds, opts.seed + 10_000),
    ] {
        if count == 0 {
            continue;
        }
        let s = build_split(opts, split, count, first, range, progress)?;
        if split == "train" {
            summary.train = s;
        } else {
            summary.val = s;
        }
    }
    Ok(summary)
}

/// Refuses a set that could not train anything.
fn check_world_options(opts: &WorldTrainingOptions) -> Result<()> {
    if opts.train_worlds == 0 {
        bail!("at least one training world is needed");
    }
    if opts.size < 64 {
        bail!(
            "worlds of {} px are too small to train on (64 or more)",
            opts.size
        );
    }
    Ok(())
}

/// One split through the real stages: `count` worlds from seed `first` written as sources,
/// their disparities, their seasonal variants, their masks and the dataset build.
fn build_split(
    opts: &WorldTrainingOptions,
    split: &str,
    count: usize,
    first: u64,
    range: (i32, i32),
    progress: &dyn Progress,
) -> Result<SplitSummary> {
    let src = opts.out_dir.join("sources").join(split);
    let seeds: Vec<u64> = (first..first + count as u64).collect();
    progress.begin(&format!("worlds ({split})"), seeds.len());
    for (k, &seed) in seeds.iter().enumerate() {
        write_world_sources(&src, opts.size, seed)?;
        progress.advance(k + 1);
    }
    progress.end();
    let pairs = src.join("pairs");
    let truth = src.join("truth");
    let teacher_dir = if split == "train" {
        run_world_teacher(opts, &src, range, progress)?
    } else {
        truth.clone()
    };
    let mut syn = SynthesizeOptions::new(&pairs, &src.join("raw"), &src.join("synthetic"));
    syn.classes_dir = Some(src.join("classes"));
    syn.crop = opts.crop;
    let generator = BuiltinSeasons::new(opts.generator_seed);
    let syn_summary = run_synthesize(&syn, &generator, progress)?;
    let mut b = BuildOptions::new(&pairs, &teacher_dir, &opts.out_dir);
    b.synthetic_dir = Some(src.join("synthetic"));
    (b.masks, b.segmenter) = world_masks(opts.masks, &src, progress)?;
    b.teacher_name = Some(if split == "train" {
        "sgm".into()
    } else {
        "GT".into()
    });
    b.lidar_dir = Some(truth);
    b.split = split.into();
    b.seed = opts.subset_seed;
    b.previews = opts.previews;
    let build = run_build(&b, progress)?;
    Ok(SplitSummary {
        worlds: count,
        synthesize: syn_summary,
        build,
    })
}

/// The training split's teacher disparities: the classical matcher over the worlds' range,
/// as on real pairs. Returns their folder.
fn run_world_teacher(
    opts: &WorldTrainingOptions,
    src: &Path,
    range: (i32, i32),
    progress: &dyn Progress,
) -> Result<PathBuf> {
    let t = src.join("teacher");
    run_teacher(
        &TeacherOptions {
            pairs_dir: src.join("pairs"),
            out_dir: t.clone(),
            matcher: Matcher::Classical(opts.sgm.clone()),
            range: Some(range),
            shard: Shard::ALL,
        },
        progress,
    )?;
    Ok(t)
}

/// The masks' folders and the segmenter's name: the worlds' exact classes, or the `masks`
/// stage's offline segmenter run on the raw images.
fn world_masks(
    masks: WorldMasks,
    src: &Path,
    progress: &dyn Progress,
) -> Result<(MaskDirs, String)> {
    match masks {
        WorldMasks::Exact => Ok((
            MaskDirs::release(&src.join("masks")),
            "world classes (exact)".into(),
        )),
        WorldMasks::Segmenter => {
            let segmenter = OfflineSegmenter::default();
            let name = segmenter.name();
            let out_dir = src.join("segmentation");
            run_masks(
                &MasksOptions {
                    images_dir: src.join("raw"),
                    out_dir: out_dir.clone(),
                    shard: Shard::ALL,
                    segmenter: Box::new(segmenter),
                },
                progress,
            )?;
            Ok((MaskDirs::release(&out_dir), name))
        }
    }
}

/// The disparity search range of the worlds of `size` (the same for every seed).
pub fn world_range(size: usize) -> (i32, i32) {
    // The range depends on the cameras and the scene's altitude span only, not on the seed.
    WorldParams::new(size, 1).disparity_range()
}

/// Writes the sources of world `seed` under `src` (skipped when its homography, written last,
/// exists).
pub fn write_world_sources(src: &Path, size: usize, seed: u64) -> Result<()> {
    let (left_id, right_id) = world_ids(seed);
    let pair = format!("{left_id}-{right_id}");
    let done = src
        .join("pairs")
        .join("homography")
        .join(format!("{pair}.npz"));
    if done.is_file() {
        return Ok(());
    }
    let world = world::generate(&WorldParams::new(size, seed), &world::Neutral, &|_, _| {})
        .map_err(anyhow::Error::msg)?;
    let pairs = src.join("pairs");
    write_npy(
        pairs.join("L").join(format!("{pair}.iio")),
        &world.left.image,
    )?;
    write_npy(
        pairs.join("R").join(format!("{pair}.iio")),
        &world.right.image,
    )?;
    write_npy(
        src.join("truth").join(format!("{pair}.iio")),
        &world.disparity,
    )?;
    for (id, view, h) in [
        (&left_id, &world.left, &world.rectify_left),
        (&right_id, &world.right, &world.rectify_right),
    ] {
        let inv = h
            .inverse()
            .ok_or_else(|| anyhow::anyhow!("world {seed}: singular homography"))?;
        let (raw, _) = warp_homography(&view.image, &inv, size, size)?;
        write_geotiff(
            src.join("raw").join(format!("{id}.tif")),
            &raw,
            &GeoTiffMeta::default(),
        )?;
        let classes = raw_classes(&view.classes, h, size);
        write_png(
            src.join("classes").join(format!("{id}.png")),
            &classes,
            PngDepth::Eight,
        )?;
        for (name, cls, other) in [
            ("water", class::WATER, 255.0),
            ("tree", class::TREE, 1.0),
            ("building", class::BUILDING, 1.0),
        ] {
            // The release's segmentation files: the class is 0.
            let mut m = classes.clone();
            m.data_mut()
                .iter_mut()
                .for_each(|v| *v = if *v == cls as f32 { 0.0 } else { other });
            let path = src
                .join("masks")
                .join(format!("{name}_segmentation"))
                .join("masks")
                .join(format!("{id}_mask.png"));
            write_png(path, &m, PngDepth::Eight)?;
        }
    }
    write_homographies(&done, &world.rectify_left, &world.rectify_right)?;
    Ok(())
}

/// Class ids of the raw frame: nearest rectified pixel of each raw pixel (background outside).
fn raw_classes(rectified: &Image, h: &Homography, size: usize) -> Image {
    let (w, ht) = rectified.size();
    Image::from_fn(size, size, |x, y| {
        let (u, v) = h.apply(x as f64, y as f64);
        let (u, v) = (u.round(), v.round());
        if u < 0.0 || v < 0.0 || u >= w as f64 || v >= ht as f64 {
            class::BACKGROUND as f32
        } else {
            rectified.get(u as usize, v as usize, 0)
        }
    })
}

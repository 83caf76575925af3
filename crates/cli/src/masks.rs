//! `seasonstereo masks` (water, tree and building masks) and `masks-score` (against DFC2019
//! classes).

use std::path::PathBuf;

use anyhow::Result;
use clap::{Args, ValueEnum};
use seasonstereo::defaults::SEGFORMER_PRESET;
use seasonstereo::stages::{
    masks, masks_score, masks_table, ImageSegmenter, MasksOptions, MasksRecord, OfflineSegmenter,
    PairIndex, RulesSegmenter, SegformerSegmenter,
};
use seasonstereo::Progress;

use crate::args::{report, DeviceArg, ShardArg};

#[derive(Args)]
#[command(
    after_help = "One segmentation per image gives the water, tree and building masks in the \
    release's layout: OUT/{water,tree,building}_segmentation/masks/<stem>_mask.png (the class is 0; \
    other pixels 255 for water, 1 for tree and building), probs/<stem>_<class>_prob.png, \
    <class>_percentages.txt, plus OUT/classes/<stem>.png (OpenEarthMap ids). Post-processing as the \
    release: water components < 0.1 % removed and holes < 0.1 % filled, tree components < 0.05 % \
    removed, buildings dilated by 3 px.\n\n\
    Segmenter (named in OUT/masks.json and every record): SegFormer (OpenEarthMap mit-b2) with \
    --segformer, the preferred path; else the offline rules (--segmenter rules, the default): \
    vegetation index, and with --pairs the height above the local ground from the pairs' \
    disparities (trees = vegetation and raised, buildings = raised and not vegetation, water = low \
    and dark and smooth, or blue). Measured on the 10 DFC2019 JAX_068 dev images against the LiDAR \
    classes (BENCHMARKS.md, `seasonstereo masks-score`): tree IoU 0.36 (recall 0.63), building \
    IoU 0.78 (tree IoU 0.6 / recall 0.7 not met: the LiDAR class 5 leaves much visible \
    canopy labelled ground); without --pairs only the tree mask is made (colour only: tree IoU 0.21, recall \
    0.70). --segmenter \
    pixel-classifier is the previous offline default, a Gaussian mixture trained on procedural \
    worlds (tree IoU 0.00 / building IoU 0.39 on the dev images). Images must be \
    8-bit (0–255).\n\n\
    Examples:\n  seasonstereo masks --images data/raw_crops -o data/segmentation \\\n      \
    --segformer checkpoints/openearthmap_segformer_mit-b2.pt\n  seasonstereo masks --images \
    data/raw_crops -o data/segmentation \\\n      --pairs data/pairs --disparities \
    data/teacher/sgm"
)]
pub struct MasksArgs {
    /// Folder of images (searched recursively: .png .tif .tiff .iio .npy); outputs are named by
    /// file stem.
    #[arg(long, value_name = "DIR")]
    images: PathBuf,
    /// Output folder.
    #[arg(short, long, value_name = "DIR")]
    output: PathBuf,
    /// SegFormer weights (the release's openearthmap_segformer_mit-b2.pt or HF safetensors).
    #[arg(long, value_name = "FILE")]
    segformer: Option<PathBuf>,
    /// SegFormer layout: mit-b2 (the release) or tiny (the parity fixture).
    #[arg(long, value_name = "PRESET", default_value = SEGFORMER_PRESET, requires = "segformer")]
    segformer_config: String,
    /// The offline segmenter (without --segformer): rules (colour + heights, for real imagery)
    /// or pixel-classifier (trained on procedural worlds).
    #[arg(
        long,
        value_enum,
        default_value = "rules",
        conflicts_with = "segformer"
    )]
    segmenter: OfflineKind,
    /// Rectified pairs (the folder `rectify` wrote: rectify/<pair>.json, homography/) whose
    /// disparities give the rules the height above ground of each image they contain.
    #[arg(long, value_name = "DIR")]
    pairs: Option<PathBuf>,
    /// Disparities of those pairs, <pair>.iio (a `teacher` output). Default: PAIRS/disparity
    /// (the layout of a `reconstruct` work folder).
    #[arg(long, value_name = "DIR", requires = "pairs")]
    disparities: Option<PathBuf>,
    #[command(flatten)]
    device: DeviceArg,
    #[command(flatten)]
    shard: ShardArg,
}

/// The offline segmenters.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum OfflineKind {
    Rules,
    PixelClassifier,
}

pub fn run(a: MasksArgs, progress: &dyn Progress) -> Result<()> {
    let segmenter: Box<dyn ImageSegmenter> = match &a.segformer {
        Some(w) => Box::new(SegformerSegmenter::load(
            w,
            &a.segformer_config,
            a.device.device,
        )?),
        None => match a.segmenter {
            OfflineKind::PixelClassifier => Box::new(OfflineSegmenter::default()),
            OfflineKind::Rules => {
                let index = match &a.pairs {
                    Some(p) => {
                        let d = a.disparities.clone().unwrap_or_else(|| p.join("disparity"));
                        let index = PairIndex::read(p, &d)?;
                        println!(
                            "heights from {} pairs with disparities in {} ({} without)",
                            index.len(),
                            d.display(),
                            index.without_disparity.len()
                        );
                        Some(index)
                    }
                    None => None,
                };
                Box::new(RulesSegmenter::new(index))
            }
        },
    };
    let opts = MasksOptions {
        images_dir: a.images,
        out_dir: a.output,
        shard: a.shard.shard,
        segmenter,
    };
    println!("segmenter: {}", opts.segmenter.name());
    let s = masks(&opts, progress)?;
    report("masks", &s);
    println!("masks in {}", opts.out_dir.display());
    Ok(())
}

#[derive(Args)]
#[command(
    after_help = "Projects the truth classes (2 ground, 5 high vegetation, 6 building) into each \
    image through the truth DSM and the image's RPC (the highest LiDAR cell per pixel) and compares \
    them with the masks where the truth is 2, 5 or 6: tree = class 5, building = 6, ground = 2 \
    against neither mask. Prints a markdown table (per image, mean over images, pooled pixels).\n\n\
    Registration (--register): the cameras' frame and the truth grid can be a few cells apart; \
    the benchmark registers every DSM by the integer shift (±5 cells) maximising the NCC. Given \
    DSMs reconstructed through the same cameras on the truth grid (`reconstruct --like TRUTH`), \
    each one's shift is found by the benchmark's rule and the truth is moved by the median shift \
    before it is projected. On the JAX_068 dev data the 12 pairs' DSMs are 0 or 1 cell off, \
    not in one direction, and the scores move by at most 0.01 (BENCHMARKS.md).\n\n\
    Example:\n  D=../shared/data/dfc2019-jax068-dev\n  seasonstereo masks-score --masks out/masks \
    --rpc-dir $D/rpcs/ba \\\n      --truth $D/truth/JAX_068_DSM.tif --register out/jax/006-020.tif"
)]
pub struct MasksScoreArgs {
    /// A `masks` output folder.
    #[arg(long, value_name = "DIR")]
    masks: PathBuf,
    /// Cameras of the images, <stem>.json (SatNeRF/rpcm); images without one are skipped.
    #[arg(long, value_name = "DIR")]
    rpc_dir: PathBuf,
    /// Truth DSM <AOI>_DSM.tif (GeoTIFF, or DFC2019 plain TIFF + .txt).
    #[arg(long, value_name = "DSM")]
    truth: PathBuf,
    /// Truth classes on the DSM's grid. Default: <AOI>_CLS.tif beside the DSM.
    #[arg(long, value_name = "TIFF")]
    classes: Option<PathBuf>,
    /// DSMs through the same cameras on the truth grid: register the truth by their median
    /// benchmark shift. Default: no shift.
    #[arg(long, value_name = "DSM", num_args = 1..)]
    register: Vec<PathBuf>,
}

pub fn run_score(a: MasksScoreArgs) -> Result<()> {
    let folder = masks_score(
        &a.masks,
        &a.rpc_dir,
        &a.truth,
        a.classes.as_deref(),
        &a.register,
    )?;
    for r in &folder.registered {
        println!(
            "registration {}: dx {} dy {} (NCC {})",
            r.dsm.display(),
            r.alignment.dx,
            r.alignment.dy,
            r.alignment
                .ncc
                .map_or("undefined".into(), |c| format!("{c:.4}"))
        );
    }
    println!(
        "truth shifted by dx {} dy {} cells",
        folder.shift.dx, folder.shift.dy
    );
    let scores = folder.scores;
    if let Some(record) = MasksRecord::read(&a.masks)? {
        println!("segmenter: {}", record.segmenter);
    }
    print!("{}", masks_table(&scores));
    Ok(())
}

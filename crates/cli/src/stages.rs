//! The data stages of the training set: `teacher`, `curate`, `masks` (arguments and runs).
//! Every stage is resumable (finished items are skipped) and shardable (`--shard i/n`).

use std::path::PathBuf;

use anyhow::Result;
use clap::{Args, ValueEnum};
use pipeline::curate::{self, features, ColourStatistic, CurateOptions, SsimScale};
use pipeline::masks::heights::PairIndex;
use pipeline::masks::{self, MasksOptions, OfflineSegmenter, RulesSegmenter, SegformerSegmenter};
use pipeline::teacher::batch::{BatchSummary, Shard};
use pipeline::teacher::{self, Teacher, TeacherOptions};

use crate::{parse_range, Model, NetworkArgs, SgmArgs};

fn parse_shard(s: &str) -> Result<Shard, String> {
    Shard::parse(s).map_err(|e| e.to_string())
}

/// `--shard i/n`, shared by the stages.
#[derive(Args)]
pub struct ShardArg {
    /// Process only shard I of N (0 ≤ I < N): the items at positions ≡ I mod N of the sorted
    /// list, for array jobs (Slurm: --shard $SLURM_ARRAY_TASK_ID/$N; Kubernetes indexed jobs:
    /// --shard $JOB_COMPLETION_INDEX/$N). Default: everything.
    #[arg(long, value_name = "I/N", value_parser = parse_shard, default_value = "0/1")]
    shard: Shard,
}

/// `--device`, shared by the commands that run a network.
#[derive(Args)]
pub struct DeviceArg {
    /// Where the network runs: auto (the best backend compiled in: cuda, then wgpu, then cpu),
    /// cpu, wgpu or cuda (GPU backends need the build features `wgpu` / `cuda`).
    #[arg(
        id = "device",
        long = "device",
        value_name = "DEVICE",
        default_value = "auto",
        value_parser = ["auto", "cpu", "wgpu", "cuda"]
    )]
    pub name: String,
}

fn report(what: &str, s: &BatchSummary) {
    println!(
        "{what}: {} processed, {} already done (skipped), {} in this shard of {} items",
        s.done, s.skipped, s.in_shard, s.total
    );
}

#[derive(Args)]
#[command(
    after_help = "Reads PAIRS/L/<stem>.iio|npy and PAIRS/R/<stem>.iio|npy (the release's \
    synchronic_only/ layout or `seasonstereo rectify` outputs); writes OUT/<stem>.iio (float32, NaN = \
    no disparity) and OUT/teacher.json (which teacher). Existing disparities are kept (resumable); a \
    folder holds one teacher only.\n\n\
    SGM range: --range, else PAIRS/rectify/<stem>.json (from `rectify`), else estimated from the \
    images.\n\n\
    Examples:\n  seasonstereo teacher --pairs data/synchronic_only -o data/teacher/sgm\n  \
    seasonstereo teacher --pairs data/synchronic_only -o data/teacher/monster++ --model monsterpp \
    --weights monster++-mix_all.pth --config vitl --shard $SLURM_ARRAY_TASK_ID/16"
)]
pub struct TeacherArgs {
    /// Folder of rectified pairs (L/, R/).
    #[arg(long, value_name = "DIR")]
    pairs: PathBuf,
    /// Output folder of the teacher disparities.
    #[arg(short, long, value_name = "DIR")]
    output: PathBuf,
    #[command(flatten)]
    net: NetworkArgs,
    /// SGM disparity range MIN:MAX for every pair (pixels, inclusive).
    #[arg(long, value_parser = parse_range, allow_hyphen_values = true, conflicts_with = "model")]
    range: Option<(i32, i32)>,
    #[command(flatten)]
    sgm: SgmArgs,
    #[command(flatten)]
    shard: ShardArg,
}

pub fn run_teacher(a: TeacherArgs, progress: &dyn pipeline::Progress) -> Result<()> {
    let teacher = match a.net.model {
        Some(Model::Monsterpp) => Teacher::Monster(a.net.monster_options()?),
        None => Teacher::Sgm {
            params: a.sgm.params()?,
            range: a.range,
        },
    };
    let name = teacher.record()["teacher"]
        .as_str()
        .unwrap_or("?")
        .to_string();
    let opts = TeacherOptions {
        pairs_dir: a.pairs,
        out_dir: a.output,
        teacher,
        shard: a.shard.shard,
    };
    let s = teacher::run_teacher(&opts, progress)?;
    report(&format!("teacher {name}"), &s);
    println!("disparities in {}", opts.out_dir.display());
    Ok(())
}

#[derive(Clone, Copy, ValueEnum)]
enum ColourArg {
    /// Mean per-pixel RGB distance (paper).
    Mean,
    /// 0.5·mean + 0.5·95th percentile (the release's color_distance_rgb).
    Release,
}

#[derive(Clone, Copy, ValueEnum)]
enum SsimArg {
    /// clamp(SSIM, 0, 1): the release's raw mean SSIM, negatives clipped.
    Clamp,
    /// (1 + SSIM)/2.
    Affine,
}

#[derive(Args)]
#[command(
    after_help = "Per pair (cached in OUT/scores/<stem>.json, resumable, shardable): the right \
    image warped by the teacher disparity (x_R = x_L − d), then over valid pixels d_color, SSIM \
    (scikit-image defaults: 7×7 uniform window) and S_feat (cosine similarity of DINOv3 CLS features \
    with --dinov3, else of an offline colour/gradient histogram descriptor). When every pair is \
    scored: d_max = 95th percentile of d_color (numpy linear), S_color = 1 − min(d_color, d_max)/d_max, \
    S_comb = 0.5 (S_color + S_SSIM), ranks by S_comb and S_feat, selection = both top-K.\n\n\
    Outputs: OUT/scores.csv, OUT/selected.txt, OUT/selected.csv, OUT/curate.json, OUT/report.html. \
    With --shard, each shard scores its pairs; the ranking runs once all pairs are scored (rerun \
    without --shard to force it).\n\n\
    Example: seasonstereo curate --pairs data/synchronic_only --teacher data/teacher/sgm -o data/curate \
    --keep 1000"
)]
pub struct CurateArgs {
    /// Folder of rectified pairs (L/, R/).
    #[arg(long, value_name = "DIR")]
    pairs: PathBuf,
    /// Folder of the teacher disparities (<stem>.iio), from `seasonstereo teacher`.
    #[arg(long, value_name = "DIR")]
    teacher: PathBuf,
    /// Output folder.
    #[arg(short, long, value_name = "DIR")]
    output: PathBuf,
    /// Pairs kept by each ranking: a count (1000, the paper's K of 1,565 pairs), a percentage
    /// (64%) or a fraction (0.64).
    #[arg(long, value_name = "K", default_value = "64%", value_parser = curate::select::Keep::parse)]
    keep: curate::select::Keep,
    /// Which statistic of the per-pixel colour distances is d_color.
    #[arg(long, value_enum, default_value_t = ColourArg::Mean)]
    colour_distance: ColourArg,
    /// How the mean SSIM becomes S_SSIM in [0, 1].
    #[arg(long, value_enum, default_value_t = SsimArg::Clamp)]
    ssim_scale: SsimArg,
    /// DINOv3 weights (HF safetensors or .pth, e.g. dinov3-vitl16-pretrain-sat493m) for S_feat;
    /// without them the offline descriptor is used (named in the outputs).
    #[arg(long, value_name = "FILE")]
    dinov3: Option<PathBuf>,
    /// DINOv3 layout: vits16, vitb16, vitl16, tiny. Default: inferred from the checkpoint.
    #[arg(long, value_name = "PRESET", requires = "dinov3")]
    dinov3_config: Option<String>,
    /// DINOv3 input normalisation: imagenet (the HF processor's default) or sat493m.
    #[arg(
        long,
        value_name = "NAME",
        default_value = "imagenet",
        requires = "dinov3"
    )]
    dinov3_normalisation: String,
    #[command(flatten)]
    device: DeviceArg,
    #[command(flatten)]
    shard: ShardArg,
}

pub fn run_curate(a: CurateArgs, progress: &dyn pipeline::Progress) -> Result<()> {
    let features: Box<dyn features::FeatureSimilarity> = match &a.dinov3 {
        Some(w) => Box::new(features::Dinov3Similarity::load(
            w,
            a.dinov3_config.as_deref(),
            &a.dinov3_normalisation,
            &a.device.name,
        )?),
        None => Box::new(features::HistogramDescriptor),
    };
    let opts = CurateOptions {
        pairs_dir: a.pairs,
        teacher_dir: a.teacher,
        out_dir: a.output,
        keep: a.keep,
        colour: match a.colour_distance {
            ColourArg::Mean => ColourStatistic::Mean,
            ColourArg::Release => ColourStatistic::ReleaseMeanP95,
        },
        ssim_scale: match a.ssim_scale {
            SsimArg::Clamp => SsimScale::Clamp,
            SsimArg::Affine => SsimScale::Affine,
        },
        shard: a.shard.shard,
        features,
    };
    println!("S_feat: {}", opts.features.name());
    let s = curate::run_curate(&opts, progress)?;
    report("curate scoring", &s.scoring);
    match &s.ranking {
        Some(r) => println!(
            "{} of {} pairs selected (K = {}, d_max = {:.3}): {}; scores: {}; report: {}",
            r.selected.len(),
            r.rows.len(),
            r.k,
            r.d_max,
            r.selected_txt.display(),
            r.scores_csv.display(),
            r.report.display()
        ),
        None => println!(
            "{} pairs have no score yet (other shards); the ranking runs once every pair is scored",
            s.missing
        ),
    }
    Ok(())
}

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
    Examples:\n  seasonstereo masks --images data/raw_crops -o data/segmentation --segformer \
    checkpoints/openearthmap_segformer_mit-b2.pt\n  seasonstereo masks --images data/raw_crops \
    -o data/segmentation --pairs data/pairs --disparities data/teacher/sgm"
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
    #[arg(
        long,
        value_name = "PRESET",
        default_value = "mit-b2",
        requires = "segformer"
    )]
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

pub fn run_masks(a: MasksArgs, progress: &dyn pipeline::Progress) -> Result<()> {
    let segmenter: Box<dyn masks::ImageSegmenter> = match &a.segformer {
        Some(w) => Box::new(SegformerSegmenter::load(
            w,
            &a.segformer_config,
            &a.device.name,
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
    let s = masks::run_masks(&opts, progress)?;
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
    Example: seasonstereo masks-score --masks out/masks --rpc-dir ../shared/data/dfc2019-jax068-dev/rpcs/ba \
    --truth ../shared/data/dfc2019-jax068-dev/truth/JAX_068_DSM.tif --register out/jax/006-020.tif"
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

pub fn run_masks_score(a: MasksScoreArgs) -> Result<()> {
    let folder = masks::score::score_folder(
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
    if let Some(name) = std::fs::read_to_string(a.masks.join(masks::RECORD_FILE))
        .ok()
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
        .and_then(|v| v["segmenter"].as_str().map(str::to_string))
    {
        println!("segmenter: {name}");
    }
    print!("{}", masks::score::table(&scores));
    Ok(())
}

//! `seasonstereo curate`: consistency scores of the synchronic pairs and the selection.

use std::path::PathBuf;

use anyhow::Result;
use clap::{Args, ValueEnum};
use seasonstereo::defaults::DINOV3_NORMALISATION;
use seasonstereo::stages::{
    curate, ColourStatistic, CurateOptions, Dinov3Similarity, FeatureSimilarity,
    HistogramDescriptor, Keep, SsimScale,
};
use seasonstereo::Progress;

use crate::args::{report, DeviceArg, ShardArg};

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
    Example:\n  seasonstereo curate --pairs data/synchronic_only --teacher data/teacher/sgm \\\n      \
    -o data/curate --keep 1000"
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
    #[arg(long, value_name = "K", default_value = "64%", value_parser = Keep::parse)]
    keep: Keep,
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
    #[arg(long, value_name = "NAME", default_value = DINOV3_NORMALISATION, requires = "dinov3")]
    dinov3_normalisation: String,
    #[command(flatten)]
    device: DeviceArg,
    #[command(flatten)]
    shard: ShardArg,
}

pub fn run(a: CurateArgs, progress: &dyn Progress) -> Result<()> {
    let opts = a.options()?;
    println!("S_feat: {}", opts.features.name());
    let s = curate(&opts, progress)?;
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

impl CurateArgs {
    /// The stage's options for these flags (the DINOv3 weights loaded when given).
    fn options(self) -> Result<CurateOptions> {
        let features: Box<dyn FeatureSimilarity> = match &self.dinov3 {
            Some(w) => Box::new(Dinov3Similarity::load(
                w,
                self.dinov3_config.as_deref(),
                &self.dinov3_normalisation,
                self.device.device,
            )?),
            None => Box::new(HistogramDescriptor),
        };
        Ok(CurateOptions {
            pairs_dir: self.pairs,
            teacher_dir: self.teacher,
            out_dir: self.output,
            keep: self.keep,
            colour: match self.colour_distance {
                ColourArg::Mean => ColourStatistic::Mean,
                ColourArg::Release => ColourStatistic::ReleaseMeanP95,
            },
            ssim_scale: match self.ssim_scale {
                SsimArg::Clamp => SsimScale::Clamp,
                SsimArg::Affine => SsimScale::Affine,
            },
            shard: self.shard.shard,
            features,
        })
    }
}

//! `seasonstereo teacher`: the frozen teacher's disparities for every real synchronic pair.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use seasonstereo::stages::{teacher, TeacherOptions};
use seasonstereo::Progress;

use crate::args::{parse_range, report, MatcherArgs, ShardArg};

#[derive(Args)]
#[command(
    after_help = "Reads PAIRS/L/<stem>.iio|npy and PAIRS/R/<stem>.iio|npy (the release's \
    synchronic_only/ layout or `seasonstereo rectify` outputs); writes OUT/<stem>.iio (float32, NaN = \
    no disparity) and OUT/teacher.json (which teacher). Existing disparities are kept (resumable); a \
    folder holds one teacher only.\n\n\
    Disparity range of the classical teacher: --range, else PAIRS/rectify/<stem>.json (from `rectify`), else estimated from the \
    images.\n\n\
    Examples:\n  seasonstereo teacher --pairs data/synchronic_only -o data/teacher/sgm\n  \
    seasonstereo teacher --pairs data/synchronic_only -o data/teacher/monster++ \\\n      \
    --model monsterpp --weights monster++-mix_all.pth --config vitl \\\n      \
    --shard $SLURM_ARRAY_TASK_ID/16"
)]
pub struct TeacherArgs {
    /// Folder of rectified pairs (L/, R/).
    #[arg(long, value_name = "DIR")]
    pairs: PathBuf,
    /// Output folder of the teacher disparities.
    #[arg(short, long, value_name = "DIR")]
    output: PathBuf,
    #[command(flatten)]
    matcher: MatcherArgs,
    /// SGM disparity range MIN:MAX for every pair (pixels, inclusive).
    #[arg(long, value_parser = parse_range, allow_hyphen_values = true, conflicts_with = "model")]
    range: Option<(i32, i32)>,
    #[command(flatten)]
    shard: ShardArg,
}

pub fn run(a: TeacherArgs, progress: &dyn Progress) -> Result<()> {
    let opts = TeacherOptions {
        pairs_dir: a.pairs,
        out_dir: a.output,
        matcher: a.matcher.matcher()?,
        range: a.range,
        shard: a.shard.shard,
    };
    let s = teacher(&opts, progress)?;
    report(&format!("teacher {}", opts.matcher.name()), &s);
    println!("disparities in {}", opts.out_dir.display());
    Ok(())
}

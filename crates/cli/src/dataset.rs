//! `seasonstereo dataset build` and `dataset world`: training sets (resumable, shardable).

use std::path::PathBuf;

use anyhow::{bail, Result};
use clap::{Args, Subcommand};
use seasonstereo::stages::{
    dataset_build, world_training, BuildOptions, BuildSummary, MaskDirs, Subset,
    WorldTrainingOptions, WorldTrainingSummary,
};
use seasonstereo::{Aggregation, Progress};

use crate::args::{SgmArgs, ShardArg};

#[derive(Args)]
pub struct DatasetArgs {
    #[command(subcommand)]
    command: DatasetCommand,
}

#[derive(Subcommand)]
enum DatasetCommand {
    /// Assemble the training set: the 25 season combinations of every selected pair, masks,
    /// disparities, subsets S1/S2/S3 and manifest, in the layout the trainer reads.
    Build(BuildArgs),
    /// A small training set (and validation set) from procedural worlds with exact ground
    /// truth, made by the real stages: teacher (census + MGM), synthesize (built-in seasons), dataset build.
    World(WorldArgs),
}

#[derive(Args)]
#[command(
    after_help = "Writes the release's layout under OUT (what `seasonstereo train` and the \
    released Python trainer read):\n  OUT/<split>/L/<stem>.npy, R/<stem>.npy (stem = \
    <LEFTID>[__<season>]-<RIGHTID>[__<season>], no tag = real), homography/<pair>.npz, \
    masks/{L,R}/<pair>.npy (rectified footprint), water_masks/ and tree_masks/ (KEEP masks: \
    1 = not water / not tree), building_masks/ (1 = building)\n  \
    OUT/disparity_maps/<teacher>/<pair>.iio, OUT/disparity_maps/GT/<pair>.iio (with --lidar)\n  \
    OUT/experiments/sub1_synchronic.csv (S1: real only), sub2_synchronic.csv (S2: + synchronic \
    synthetic), sub5_syndiach.csv (S3: + half synchronic, half diachronic synthetic, S2's budget), \
    sub3_diachronic.csv (all combinations); sub_val.csv for --split val\n  \
    OUT/manifest.json, OUT/<split>/summary.txt, missing_files.txt\n\n\
    Masks: MASKS/{water,tree,building}_segmentation/masks/<id>_mask.png from `seasonstereo masks` \
    (the class is 0), run on the crops of `synthesize` (OUT/cropped/). A missing file falls back \
    as in the release (keep everything, no building) and is listed in missing_files.txt.\n\n\
    Resumable: every file is written atomically and skipped when present; a killed build redoes \
    at most the file it was writing. Shardable over the sorted pairs; the lists and the manifest \
    are written when every pair is finished (by the last shard, or by any rerun).\n\n\
    Example:\n  seasonstereo dataset build --pairs data/synchronic_only \\\n      --selected \
    out/curate/selected.txt --synthetic out/synthetic \\\n      --masks out/masks --teacher \
    out/teacher \\\n      -o data/diachronic-stereo-synthetic"
)]
struct BuildArgs {
    /// Synchronic pairs folder (L/, R/, homography/).
    #[arg(long)]
    pairs: PathBuf,
    /// Teacher disparities <pair>.iio of the real pairs (`seasonstereo teacher`).
    #[arg(long)]
    teacher: PathBuf,
    /// Output dataset folder.
    #[arg(short, long, default_value = "out/dataset")]
    output: PathBuf,
    /// Selected pairs: curate's selected.txt or selected.csv. Default: every pair.
    #[arg(long, value_name = "FILE")]
    selected: Option<PathBuf>,
    /// The `synthesize` output folder. Without it only the real pairs are written.
    #[arg(long, value_name = "DIR")]
    synthetic: Option<PathBuf>,
    /// The `masks` output folder (MASKS/{water,tree,building}_segmentation/masks/).
    #[arg(long, value_name = "DIR")]
    masks: Option<PathBuf>,
    /// Name of the segmenter for the manifest. Default: from MASKS, else "none".
    #[arg(long)]
    segmenter: Option<String>,
    /// Folder name of the teacher under disparity_maps/ (default: from teacher.json; MonSter++
    /// is `monster++` as in the release).
    #[arg(long)]
    teacher_name: Option<String>,
    /// LiDAR-derived disparities <pair>.iio, copied to disparity_maps/GT (configuration (a)).
    #[arg(long, value_name = "DIR")]
    lidar: Option<PathBuf>,
    /// Split to write: train, or val (supervised by its own val/disparity, list sub_val).
    #[arg(long, default_value = "train")]
    split: String,
    /// Seed of the S3 draw (the same seed always gives the same lists).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Also write PNG previews (OUT/<split>/png/).
    #[arg(long)]
    preview: bool,
    #[command(flatten)]
    shard: ShardArg,
}

#[derive(Args)]
#[command(
    after_help = "Writes a complete training set (the layout of `dataset build`) to OUT, \
    its sources to OUT/sources/{train,val}/ (pairs, raw images, class maps, segmentation files, \
    teacher, exact disparities, variants). Training pairs are supervised by the classical \
    teacher, census + MGM (disparity_maps/sgm) with the exact disparity as LiDAR (disparity_maps/GT); the validation \
    split by the exact disparity (val/disparity, experiments/sub_val.csv).\n\n\
    Example (seconds on a laptop):\n  seasonstereo dataset world --size 128 --worlds 4 \
    --val-worlds 1 -o out/world-set\n  seasonstereo train --config tiny --data out/world-set"
)]
struct WorldArgs {
    /// Output dataset folder.
    #[arg(short, long, default_value = "out/world-set")]
    output: PathBuf,
    /// World size, pixels.
    #[arg(long, default_value_t = 256)]
    size: usize,
    /// Training worlds (one pair each).
    #[arg(long, default_value_t = 4)]
    worlds: usize,
    /// Validation worlds.
    #[arg(long, default_value_t = 1)]
    val_worlds: usize,
    /// Seed of the first training world (validation worlds start at SEED + 10000).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Seed of the built-in seasonal generator.
    #[arg(long, default_value_t = 0)]
    generator_seed: u64,
    /// Seed of the S3 draw.
    #[arg(long, default_value_t = 0)]
    subset_seed: u64,
    /// Also write PNG previews.
    #[arg(long)]
    preview: bool,
    #[command(flatten)]
    sgm: SgmArgs,
}

fn print_build(split: &str, s: &BuildSummary, out: &std::path::Path) {
    println!(
        "{split}: {} pairs ({} in this shard): {} built now, {} already built; {} combinations written, {} already there",
        s.pairs, s.pairs_in_shard, s.pairs_done, s.pairs_skipped, s.combinations_written, s.combinations_skipped
    );
    if s.missing_masks > 0 {
        println!(
            "warning: {} segmentation masks were missing; the release's defaults were used (keep all, no building): see {}",
            s.missing_masks,
            out.join(split).join("missing_files.txt").display()
        );
    }
    if s.finalized {
        for (label, c) in &s.subsets {
            println!(
                "  {label:4} {:6} rows: {} real, {} synchronic synthetic, {} diachronic",
                c.total, c.real, c.synchronic_synthetic, c.diachronic
            );
        }
        println!("manifest: {}", out.join("manifest.json").display());
    } else {
        println!(
            "{} pairs are not finished yet (other shards): the last shard to finish, or a rerun, writes the subsets and the manifest",
            s.pending
        );
    }
}

/// Runs `seasonstereo dataset …`.
pub fn run(a: DatasetArgs, progress: &dyn Progress) -> Result<()> {
    match a.command {
        DatasetCommand::Build(b) => {
            let s = dataset_build(&b.options()?, progress)?;
            print_build(&b.split, &s, &b.output);
            failed_pairs(&s)?;
        }
        DatasetCommand::World(w) => {
            let s = world_training(&w.options()?, progress)?;
            print_world(&w, &s);
        }
    }
    Ok(())
}

/// Exit code 2 when some pairs failed (each named with its error).
fn failed_pairs(s: &BuildSummary) -> Result<()> {
    for (pair, cause) in &s.failed {
        eprintln!("warning: pair {pair} failed: {cause}");
    }
    let names = s.failed.iter().map(|(p, _)| p.clone()).collect();
    let total = s.pairs_in_shard;
    crate::exit::partial_if_any("pairs", total, names, "fix them and rerun the same command")
}

impl BuildArgs {
    /// The build's options for these flags.
    fn options(&self) -> Result<BuildOptions> {
        let mut opts = BuildOptions::new(&self.pairs, &self.teacher, &self.output);
        opts.selected = self.selected.clone();
        opts.synthetic_dir = self.synthetic.clone();
        if let Some(m) = &self.masks {
            if !m.is_dir() {
                bail!("--masks {}: no such folder", m.display());
            }
            opts.masks = MaskDirs::release(m);
        }
        opts.segmenter = match (&self.segmenter, &self.masks) {
            (Some(s), _) => s.clone(),
            (None, Some(m)) => MaskDirs::recorded_segmenter(m)
                .unwrap_or_else(|| format!("masks from {}", m.display())),
            (None, None) => "none (release defaults)".into(),
        };
        opts.teacher_name = self.teacher_name.clone();
        opts.lidar_dir = self.lidar.clone();
        opts.split = self.split.clone();
        opts.seed = self.seed;
        opts.previews = self.preview;
        opts.shard = self.shard.shard;
        Ok(opts)
    }
}

impl WorldArgs {
    /// The world training set's options for these flags.
    fn options(&self) -> Result<WorldTrainingOptions> {
        let mut opts =
            WorldTrainingOptions::new(&self.output, self.size, self.worlds, self.val_worlds);
        opts.seed = self.seed;
        opts.generator_seed = self.generator_seed;
        opts.subset_seed = self.subset_seed;
        opts.previews = self.preview;
        opts.sgm = self.sgm.params(Aggregation::Mgm)?;
        Ok(opts)
    }
}

/// What `dataset world` made and how to train on it.
fn print_world(w: &WorldArgs, s: &WorldTrainingSummary) {
    println!(
        "{} training and {} validation worlds of {}² px (disparity range {}..{} px); variants rejected: {} (train), {} (val)",
        s.train.worlds, s.val.worlds, w.size, s.range.0, s.range.1,
        s.train.synthesize.rejected, s.val.synthesize.rejected
    );
    print_build("train", &s.train.build, &w.output);
    if s.val.worlds > 0 {
        print_build("val", &s.val.build, &w.output);
    }
    println!(
        "train with: experiments/{}.csv (S1), {}.csv (S2), {}.csv (S3), {}.csv (all)",
        Subset::S1.csv_name(),
        Subset::S2.csv_name(),
        Subset::S3.csv_name(),
        Subset::All.csv_name()
    );
}

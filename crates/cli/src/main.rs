//! `seasonstereo`: dense stereo matching of multi-date satellite imagery.
//!
//! This binary only parses arguments and draws progress; the work lives in the library crates.

/// Tensors of the networks come and go by the megabyte: mimalloc reuses their pages where the
/// system allocator returns them to the kernel and faults them in again (BENCHMARKS.md).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

mod allocator;
mod args;
mod bars;
mod bench;
mod bench_merge;
mod curate;
mod dataset;
mod demo;
mod dsm;
mod eval;
mod exit;
mod jobs;
mod masks;
mod predict;
mod reconstruct;
mod reconstruct_many;
mod rectify;
mod score;
mod synthesize;
mod teacher;
mod train;
mod world;

use std::process::ExitCode;

use anyhow::Result;
use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "seasonstereo",
    version,
    about = "Dense stereo matching of multi-date satellite imagery: disparity maps and DSMs",
    long_about = "Dense stereo matching of multi-date satellite imagery.\n\n\
        Conventions: pairs are rectified (epipolar lines are rows); disparity lives on the left view, \
        x_R = x_L − d, positive and growing with altitude; invalid pixels are NaN.\n\n\
        Start with `seasonstereo demo`: it renders a procedural satellite world with exact ground truth, \
        matches it and writes an HTML report.",
    after_help = exit::EXIT_CODES_HELP
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Replace existing final outputs (DSMs, disparities, reports), atomically; work folders
    /// resume whatever this says.
    #[arg(long, global = true)]
    overwrite: bool,
    /// Exit 0 with a warning, instead of 2, when some tiles or items failed.
    #[arg(long, global = true)]
    allow_partial: bool,
}

#[derive(Subcommand)]
enum Command {
    /// Render a procedural satellite world (rectified pair, exact disparity, heights, classes,
    /// homographies and RPC cameras) in the public release's folder layout.
    World(world::WorldArgs),
    /// Rectify a raw satellite pair from its RPC cameras (epipolar lines become rows) and give the
    /// disparity search range implied by the scene's altitudes.
    Rectify(rectify::RectifyArgs),
    /// Predict the disparity of a rectified pair.
    Predict(predict::PredictArgs),
    /// From a raw pair to a DSM in one command: rectify from the RPCs, match over the range the
    /// cameras imply, triangulate and grid (optionally scored against a ground truth).
    Reconstruct(reconstruct::ReconstructArgs),
    /// Many acquisitions of one area → one DSM: the best pairs by date gap, convergence,
    /// incidence and sun angles, each reconstructed on one grid, fused per cell (strongest
    /// height cluster), holes filled where no pair measured or too few agreed; count and spread
    /// rasters, a report. Exit 2 when some pairs failed, 3 when none produced a DSM.
    ReconstructMany(reconstruct_many::ReconstructManyArgs),
    /// Score DSMs against a ground truth with the benchmark's metric (MAE and coverage); a DSM on
    /// its own grid is cut onto the truth's.
    Score(score::ScoreArgs),
    /// Time the networks (MonSter++, SegFormer, DINOv3, a training step) with random weights:
    /// median and min over N runs after a warm-up, peak RSS, --json; or a whole-scene DSM merge.
    Bench(bench::BenchArgs),
    /// Turn a rectified disparity into a georeferenced DSM (RPC triangulation, highest point per
    /// cell), on a ground truth's grid or on a UTM grid of your choosing.
    Dsm(dsm::DsmArgs),
    /// SeasonStereo's story on a procedural world: four seasons, a synchronic and a winter ↔ summer
    /// pair matched, triangulated to DSMs and scored against the truth; an HTML report (offline, CPU).
    Demo(demo::DemoArgs),
    /// Altitude MAE of the DSMs from predicted disparities, as the benchmark's code computes it
    /// (RPC triangulation, max-per-cell DSM on the ground truth's grid, NCC registration, foliage
    /// and water masked); prints the paper's Table 1. Resumable: pairs already in OUT/pairs.csv
    /// are skipped.
    Eval(eval::EvalArgs),
    /// Teacher disparities (SGM, or MonSter++ with weights) for every real synchronic pair;
    /// resumable and shardable.
    Teacher(teacher::TeacherArgs),
    /// Score the consistency of synchronic pairs (colour, SSIM, image features) and select the
    /// intersection of the two top-K rankings; resumable and shardable.
    Curate(curate::CurateArgs),
    /// Water, tree and building masks from one segmentation per image (SegFormer with weights,
    /// or the offline rules on colour and height above ground); resumable and shardable.
    Masks(masks::MasksArgs),
    /// Score a `masks` folder against DFC2019 classes (tree, building, ground IoU / precision /
    /// recall), the truth projected into each image through its DSM and RPCs.
    MasksScore(masks::MasksScoreArgs),
    /// Four seasonal variants of every image of the selected pairs (centre crop, built-in model
    /// or a generative API), checked for geometric fidelity and rectified; resumable, shardable.
    Synthesize(synthesize::SynthesizeArgs),
    /// Training sets: `dataset build` assembles the 25 season combinations per pair, masks,
    /// subsets S1/S2/S3 and manifest; `dataset world` makes one from procedural worlds.
    Dataset(dataset::DatasetArgs),
    /// Fine-tune MonSter++ with the SeasonStereo loss from a TOML configuration or a preset
    /// (tiny, a-lidar, b-disp, c-photo, d-full, s1, s2, s3); checkpoints, exact --resume, Ctrl-C
    /// saves and exits.
    Train(train::TrainArgs),
    /// Cluster jobs: `jobs slurm reconstruct <reconstruct arguments>` submits a scene as a
    /// Slurm array of tile tasks plus a merge; `jobs slurm dataset` the training-set stages as
    /// one array per stage with a check between stages; `jobs status` and `jobs resubmit`
    /// follow either up.
    Jobs(jobs::JobsArgs),
}

fn main() -> ExitCode {
    allocator::keep_freed_pages();
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => return exit::parse_error(e),
    };
    exit::set(exit::Safety {
        overwrite: cli.overwrite,
        allow_partial: cli.allow_partial,
    });
    exit::exit_code(run(cli))
}

fn run(cli: Cli) -> Result<()> {
    let progress = bars::Bars::default();
    match cli.command {
        Command::World(a) => world::run(a, &progress),
        Command::Rectify(a) => rectify::run(a, &progress),
        Command::Predict(a) => predict::run(a, &progress),
        Command::Dsm(a) => dsm::run(a),
        Command::Reconstruct(a) => reconstruct::run(a, &progress),
        Command::ReconstructMany(a) => reconstruct_many::run(a, &progress),
        Command::Score(a) => score::run(a),
        Command::Bench(a) => bench::run(a),
        Command::Teacher(a) => teacher::run(a, &progress),
        Command::Curate(a) => curate::run(a, &progress),
        Command::Masks(a) => masks::run(a, &progress),
        Command::MasksScore(a) => masks::run_score(a),
        Command::Synthesize(a) => synthesize::run(a, &progress),
        Command::Dataset(a) => dataset::run(a, &progress),
        Command::Train(a) => train::run(a),
        Command::Demo(a) => demo::run(a, &progress),
        Command::Eval(a) => eval::run(a, &progress),
        Command::Jobs(a) => jobs::run(a, |argv| Cli::try_parse_from(argv).map(|_| ())),
    }
}

#[cfg(test)]
mod tests {
    use clap::CommandFactory;

    /// clap's consistency checks (unique argument ids, valid defaults, …) of every subcommand,
    /// which otherwise only fire when that subcommand is parsed.
    #[test]
    fn command_line_definition_is_consistent() {
        super::Cli::command().debug_assert();
    }
}

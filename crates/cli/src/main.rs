//! `seasonstereo`: dense stereo matching of multi-date satellite imagery.
//!
//! This binary only parses arguments and draws progress; the work lives in the library, which
//! it reaches through its API alone (the `seasonstereo` crate).

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
use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "seasonstereo",
    version,
    about = "Dense stereo matching of multi-date satellite imagery: disparity maps and DSMs",
    long_about = "Dense stereo matching of multi-date satellite imagery.\n\n\
        Conventions: pairs are rectified (epipolar lines are rows); disparity lives on the left view, \
        x_R = x_L − d, positive and growing with altitude; invalid pixels are NaN.\n\n\
        Start with `seasonstereo demo`: it renders a procedural satellite world with exact ground truth, \
        matches it and writes an HTML report. `seasonstereo <command> -h` lists a command's \
        common options, `--help` all of them.",
    after_help = "Exit codes: 0 all done, 1 error before any work, 2 partial, 3 nothing produced \
        (more: --help).\nA command's common options: seasonstereo <command> -h; all of them: --help.",
    after_long_help = exit::EXIT_CODES_HELP,
    max_term_width = 100
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Replace existing final outputs (DSMs, disparities, reports), atomically.
    ///
    /// Work folders resume whatever this says.
    #[arg(long, global = true)]
    overwrite: bool,
    /// Exit 0 with a warning, instead of 2, when some tiles or items failed.
    #[arg(long, global = true)]
    allow_partial: bool,
}

/// The commands, as `seasonstereo -h` lists them: under headings, each on one line. Every
/// command is in one group (checked by a test).
const COMMAND_GROUPS: [(&str, &[&str]); 5] = [
    (
        "Satellite images to DSMs",
        &["reconstruct", "reconstruct-many", "score", "jobs"],
    ),
    ("Step by step", &["rectify", "predict", "dsm"]),
    ("Try it without data", &["demo", "world"]),
    ("Benchmarks", &["eval", "masks-score", "bench"]),
    (
        "Training (SeasonStereo)",
        &[
            "teacher",
            "curate",
            "masks",
            "synthesize",
            "dataset",
            "train",
        ],
    ),
];

#[derive(Subcommand)]
enum Command {
    /// Render a procedural satellite world with exact ground truth.
    ///
    /// A rectified pair, its exact disparity, heights, classes, homographies and RPC cameras, in
    /// the public release's folder layout.
    World(world::WorldArgs),
    /// Rectify a raw satellite pair from its RPC cameras.
    ///
    /// Epipolar lines become rows; prints the disparity search range implied by the scene's
    /// altitudes.
    Rectify(rectify::RectifyArgs),
    /// Predict the disparity of a rectified pair.
    Predict(predict::PredictArgs),
    /// From a raw pair to a DSM in one command.
    ///
    /// Rectify from the RPCs, match over the range the cameras imply, triangulate and grid
    /// (optionally scored against a ground truth).
    Reconstruct(reconstruct::ReconstructArgs),
    /// Many acquisitions of one area → one fused DSM.
    ///
    /// The best pairs by date gap, convergence, incidence and sun angles, each reconstructed on
    /// one grid, fused per cell (strongest height cluster), holes filled where no pair measured
    /// or too few agreed; count and spread rasters, a report. Exit 2 when some pairs failed, 3
    /// when none produced a DSM.
    ReconstructMany(reconstruct_many::ReconstructManyArgs),
    /// Score DSMs against a ground truth with the benchmark's metric.
    ///
    /// MAE and coverage; a DSM on its own grid is cut onto the truth's.
    Score(score::ScoreArgs),
    /// Time the networks, or a whole-scene DSM merge.
    ///
    /// MonSter++, SegFormer, DINOv3 and a training step with random weights: median and min
    /// over N runs after a warm-up, peak RSS, --json.
    Bench(bench::BenchArgs),
    /// Turn a rectified disparity into a georeferenced DSM.
    ///
    /// RPC triangulation, highest point per cell, on a ground truth's grid or on a UTM grid of
    /// your choosing.
    Dsm(dsm::DsmArgs),
    /// SeasonStereo's story on a procedural world, as an HTML report.
    ///
    /// Four seasons, a synchronic and a winter ↔ summer pair matched, triangulated to DSMs and
    /// scored against the truth (offline, CPU).
    Demo(demo::DemoArgs),
    /// The benchmark's altitude MAE over test splits: the paper's Table 1.
    ///
    /// DSMs from predicted disparities (RPC triangulation, max-per-cell DSM on the ground
    /// truth's grid, NCC registration, foliage and water masked). Resumable: pairs already in
    /// OUT/pairs.csv are skipped.
    Eval(eval::EvalArgs),
    /// Teacher disparities for every real synchronic pair.
    ///
    /// The classical matcher (census + MGM), or MonSter++ with weights; resumable and
    /// shardable.
    Teacher(teacher::TeacherArgs),
    /// Select the most consistent synchronic pairs.
    ///
    /// Scores their consistency (colour, SSIM, image features) and keeps the intersection of the
    /// two top-K rankings; resumable and shardable.
    Curate(curate::CurateArgs),
    /// Water, tree and building masks of every image.
    ///
    /// One segmentation per image (SegFormer with weights, or the offline rules on colour and
    /// height above ground); resumable and shardable.
    Masks(masks::MasksArgs),
    /// Score a `masks` folder against DFC2019 classes.
    ///
    /// Tree, building and ground IoU / precision / recall, the truth projected into each image
    /// through its DSM and RPCs.
    MasksScore(masks::MasksScoreArgs),
    /// Four seasonal variants of every image of the selected pairs.
    ///
    /// Centre crop, built-in model or a generative API; checked for geometric fidelity and
    /// rectified; resumable, shardable.
    Synthesize(synthesize::SynthesizeArgs),
    /// Training sets, from the stages' outputs or from procedural worlds.
    ///
    /// `dataset build` assembles the 25 season combinations per pair, masks, subsets S1/S2/S3
    /// and manifest; `dataset world` makes one from procedural worlds.
    Dataset(dataset::DatasetArgs),
    /// Fine-tune MonSter++ with the SeasonStereo loss.
    ///
    /// From a TOML configuration or a preset (tiny, a-lidar, b-disp, c-photo, d-full, s1, s2,
    /// s3); checkpoints, exact --resume, Ctrl-C saves and exits.
    Train(train::TrainArgs),
    /// Cluster jobs on Slurm: submit, follow up, resubmit.
    ///
    /// `jobs slurm reconstruct <reconstruct arguments>` submits a scene as a Slurm array of
    /// tile tasks plus a merge; `jobs slurm dataset` the training-set stages as one array per
    /// stage with a check between stages; `jobs status` and `jobs resubmit` follow either up.
    Jobs(jobs::JobsArgs),
}

/// The command line's definition, with `seasonstereo -h` listing the commands by group.
fn cli_command() -> clap::Command {
    let cmd = Cli::command();
    let template = help_template(&cmd);
    cmd.help_template(template)
}

/// clap's default help layout, with the commands under [`COMMAND_GROUPS`]' headings.
fn help_template(cmd: &clap::Command) -> String {
    let styles = cmd.get_styles();
    let (header, literal) = (styles.get_header(), styles.get_literal());
    let width = cmd
        .get_subcommands()
        .map(|c| c.get_name().len())
        .max()
        .unwrap_or(0);
    let mut groups = String::new();
    for (heading, names) in COMMAND_GROUPS {
        groups.push_str(&format!("{header}{heading}:{header:#}\n"));
        for name in names {
            let about = cmd
                .find_subcommand(name)
                .and_then(|c| c.get_about())
                .map(|a| a.to_string())
                .unwrap_or_default();
            groups.push_str(&format!("  {literal}{name:<width$}{literal:#}  {about}\n"));
        }
        groups.push('\n');
    }
    format!(
        "{{before-help}}{{about-with-newline}}\n{{usage-heading}} {{usage}}\n\n{groups}\
         {header}Options:{header:#}\n{{options}}{{after-help}}"
    )
}

/// Parses a command line (the program's name first).
fn parse<I, T>(argv: I) -> Result<Cli, clap::Error>
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    let mut cmd = cli_command();
    let mut matches = cmd.try_get_matches_from_mut(argv)?;
    Cli::from_arg_matches_mut(&mut matches).map_err(|e| e.format(&mut cmd))
}

fn main() -> ExitCode {
    allocator::keep_freed_pages();
    let cli = match parse(std::env::args_os()) {
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
        Command::Jobs(a) => jobs::run(a, |argv| parse(argv).map(|_| ())),
    }
}

#[cfg(test)]
mod tests {
    /// clap's consistency checks (unique argument ids, valid defaults, …) of every subcommand,
    /// which otherwise only fire when that subcommand is parsed.
    #[test]
    fn command_line_definition_is_consistent() {
        super::cli_command().debug_assert();
    }

    /// `seasonstereo -h` lists the commands by group: each command in exactly one group, and
    /// no group names a command that does not exist.
    #[test]
    fn every_command_is_in_one_group() {
        let cmd = super::cli_command();
        let grouped: Vec<&str> = super::COMMAND_GROUPS
            .iter()
            .flat_map(|(_, names)| names.iter().copied())
            .collect();
        for c in cmd.get_subcommands() {
            let n = grouped.iter().filter(|g| **g == c.get_name()).count();
            assert_eq!(
                n,
                1,
                "`{}` is in {n} groups of COMMAND_GROUPS",
                c.get_name()
            );
        }
        for g in &grouped {
            assert!(cmd.find_subcommand(g).is_some(), "no command `{g}`");
        }
    }
}

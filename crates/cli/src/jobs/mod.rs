//! `seasonstereo jobs`: a reconstruction or the training-set stages submitted to a Slurm
//! cluster, their tiles' or shards' state, and what failed submitted again. The arguments map
//! onto the library's `SlurmRequest` / `ChainRequest`; the plan, the scripts and the submission
//! live in the library.

mod dataset;
mod units;

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::{Args, Subcommand};
use seasonstereo::jobs::{array_spec, is_chain, quote, split};
use seasonstereo::{
    job_status, resubmit_slurm, submit_slurm_reconstruct, Incomplete, JobStatus, SlurmRequest,
    Submitted,
};

use crate::reconstruct::ReconstructArgs;

#[derive(Args)]
pub struct JobsArgs {
    #[command(subcommand)]
    command: JobsCommand,
}

#[derive(Subcommand)]
enum JobsCommand {
    /// Submit to Slurm (sbatch): a reconstruction or the training-set stages.
    ///
    /// `jobs slurm reconstruct <reconstruct arguments>` or `jobs slurm dataset <the training-set
    /// stages' folders and options>`.
    #[command(subcommand)]
    Slurm(SlurmCommand),
    /// The state of a submission: done, failed and missing tiles or shards.
    ///
    /// The tiles (reconstruct) or each stage's shards (dataset) of a submission: done, failed
    /// (with their errors) and missing, and the command that resubmits only the failed ones.
    /// Exit code 2 while some are failed or missing.
    Status(StatusArgs),
    /// Submit again only what failed or is missing.
    ///
    /// The array tasks whose tiles failed or are missing, then the merge; for a dataset job,
    /// the failed and missing shards of the first unfinished stage, then every later stage
    /// (finished items are skipped).
    Resubmit(ResubmitArgs),
}

#[derive(Subcommand)]
enum SlurmCommand {
    /// Submit a `reconstruct` as a Slurm array of tile tasks plus a merge.
    ///
    /// Plans the tiles, writes the job scripts into the work folder (every argument quoted) and
    /// submits an array of tile tasks sized to the plan plus a merge task after them
    /// (`afterany`), which refuses to write a DSM while tiles are failed (unless
    /// --allow-partial), naming them. Every `reconstruct` option is passed through as typed.
    #[command(after_help = SLURM_RECONSTRUCT_HELP, after_long_help = SLURM_RECONSTRUCT_HELP)]
    Reconstruct(Box<SlurmReconstructArgs>),
    /// Submit the training-set build, one Slurm array per stage.
    ///
    /// One array job of --shards tasks per stage: teacher → curate → synthesize → masks →
    /// dataset build, then one unsharded `dataset build` (lists and manifest). Each stage's
    /// arguments are passed through exactly (shell-quoted job scripts in WORK/jobs/); a check
    /// step after each stage (`afterany`) fails, naming the failed shards and the resubmit
    /// command, unless all its shards exited 0, and the next stage runs `afterok` on it with
    /// --kill-on-invalid-dep=yes: a failed shard cancels the rest of the chain instead of
    /// leaving it pending.
    #[command(after_help = dataset::AFTER_HELP, after_long_help = dataset::AFTER_LONG_HELP)]
    Dataset(Box<dataset::SlurmDatasetArgs>),
}

/// `jobs slurm reconstruct`'s epilogue, for `-h` and `--help` alike (it replaces
/// `reconstruct`'s).
const SLURM_RECONSTRUCT_HELP: &str = "\
Example:
  seasonstereo jobs slurm reconstruct left.tif right.tif -o dsm.tif \\
      --rpc-left l.json --rpc-right r.json --max-memory 6 \\
      --sbatch-args \"-p long --time=04:00:00\" --wait
Then: seasonstereo jobs status --work dsm_work

The reconstruct options: seasonstereo reconstruct --help";

#[derive(Args)]
#[command(
    // Each task sets these itself (refused on this command line): not listed.
    mut_arg("shard", |a| a.hide(true)),
    mut_arg("merge", |a| a.hide(true)),
    mut_arg("tiles_only", |a| a.hide(true)),
)]
pub struct SlurmReconstructArgs {
    #[command(flatten)]
    job: JobOptions,
    #[command(flatten)]
    reconstruct: ReconstructArgs,
}

/// The job's own options, read anywhere on the line and not passed to `reconstruct`.
#[derive(Args)]
struct JobOptions {
    /// More sbatch options as one string; they come after ours, so they win.
    ///
    /// Partition, account, time limit, GPUs, e.g. "-p long --time=04:00:00 --gres=gpu:1".
    #[arg(long, value_name = "ARGS", allow_hyphen_values = true, help_heading = SLURM)]
    sbatch_args: Option<String>,
    /// Tiles per array task (default: the CPUs of a task).
    ///
    /// The array has ceil(tiles / N) tasks.
    #[arg(long, value_name = "N", help_heading = SLURM)]
    tiles_per_task: Option<usize>,
    /// CPUs of a tile task (default: the tiles that fit in --max-memory).
    ///
    /// Default: as many as tiles fit in --max-memory at once, at most the largest node's CPUs
    /// (sinfo).
    #[arg(long, value_name = "N", help_heading = SLURM)]
    cpus_per_task: Option<usize>,
    /// Block until the merge ends and exit with its exit code.
    #[arg(long, help_heading = SLURM)]
    wait: bool,
}

/// The heading of the job's own options.
const SLURM: &str = "Slurm";

#[derive(Args)]
pub struct WorkArg {
    /// The --work folder of the submission.
    #[arg(long, value_name = "DIR")]
    work: PathBuf,
}

#[derive(Args)]
pub struct StatusArgs {
    #[command(flatten)]
    work: WorkArg,
    /// Dataset jobs: this stage's shards and the earlier stages' (exit code 2, naming the first
    /// unfinished stage's failed shards, unless all exited 0); the check steps run this.
    #[arg(long, value_name = "NAME")]
    stage: Option<String>,
}

#[derive(Args)]
pub struct ResubmitArgs {
    #[command(flatten)]
    work: WorkArg,
    /// Block until the merge ends and exit with its exit code.
    #[arg(long)]
    wait: bool,
}

/// Options of the job, left out of the arguments passed to `reconstruct`: `(name, takes a value)`.
const JOB_OPTIONS: [(&str, bool); 6] = [
    ("--sbatch-args", true),
    ("--tiles-per-task", true),
    ("--cpus-per-task", true),
    ("--wait", false),
    ("--overwrite", false),
    ("--allow-partial", false),
];

/// Options each task sets itself.
const TASK_OPTIONS: [&str; 3] = ["--shard", "--merge", "--tiles-only"];

pub fn run(a: JobsArgs, parse: dataset::ParseLine) -> Result<()> {
    match a.command {
        JobsCommand::Slurm(SlurmCommand::Reconstruct(r)) => slurm_reconstruct(*r),
        JobsCommand::Slurm(SlurmCommand::Dataset(d)) => dataset::submit(*d, parse),
        JobsCommand::Status(s) if is_chain(&s.work.work) => {
            dataset::status(&s.work.work, s.stage.as_deref())
        }
        JobsCommand::Status(s) => match s.stage {
            Some(_) => bail!(
                "--stage is for dataset jobs: {} holds a reconstruction (leave --stage out)",
                s.work.work.display()
            ),
            None => print_status(&job_status(&s.work.work)?),
        },
        JobsCommand::Resubmit(r) if is_chain(&r.work.work) => {
            dataset::resubmit(&r.work.work, r.wait)
        }
        JobsCommand::Resubmit(r) => {
            let s = resubmit_slurm(&r.work.work, r.wait)?;
            report(&s, &r.work.work)
        }
    }
}

fn slurm_reconstruct(a: SlurmReconstructArgs) -> Result<()> {
    let options = a.reconstruct.options()?;
    let safety = crate::exit::safety();
    options.check_output(safety.overwrite)?;
    let flag = |on: bool, name: &str| if on { vec![name.to_string()] } else { vec![] };
    let request = SlurmRequest {
        binary: std::env::current_exe().context("locating the seasonstereo binary")?,
        args: passthrough(std::env::args().collect())?,
        merge_flags: flag(safety.allow_partial, "--allow-partial"),
        task_flags: flag(safety.overwrite, "--overwrite"),
        cwd: std::env::current_dir().context("reading the current folder")?,
        sbatch_args: split(a.job.sbatch_args.as_deref().unwrap_or(""))?,
        tiles_per_task: a.job.tiles_per_task,
        cpus: a.job.cpus_per_task,
        wait: a.job.wait,
    };
    let s = submit_slurm_reconstruct(&options, &request)?;
    report(&s, &options.work())
}

/// The `reconstruct` arguments as typed: the line after `jobs slurm reconstruct`, without the
/// job's options and the global flags (the scripts add what each task needs).
fn passthrough(argv: Vec<String>) -> Result<Vec<String>> {
    let start = argv
        .iter()
        .position(|a| a == "reconstruct")
        .map_or(argv.len(), |i| i + 1);
    let (mut out, mut words) = (Vec::new(), argv[start..].iter());
    while let Some(word) = words.next() {
        let name = word.split('=').next().unwrap_or(word);
        if TASK_OPTIONS.contains(&name) {
            bail!("{name} is set by the job itself (tile tasks take shards, the merge task merges): leave it out");
        }
        match JOB_OPTIONS.iter().find(|(n, _)| *n == name) {
            Some((_, true)) if !word.contains('=') => drop(words.next()),
            Some(_) => {}
            None => out.push(word.clone()),
        }
    }
    Ok(out)
}

/// What was submitted; with --wait, the merge's exit code as ours.
fn report(s: &Submitted, work: &Path) -> Result<()> {
    let r = &s.record;
    println!(
        "submitted {} tiles as array job {} (tasks {}, {} tiles per task) and merge job {} \
         (afterany); scripts and logs in {}",
        r.tiles.len(),
        s.tiles_job,
        array_spec(&s.tasks),
        r.tiles_per_task,
        s.merge_job,
        r.tiles_script.parent().unwrap_or(work).display()
    );
    if let Some((t, m)) = s.resources {
        println!(
            "resources: tile tasks {} CPUs, {} MiB; merge {} CPUs, {} MiB",
            t.cpus, t.mem_mib, m.cpus, m.mem_mib
        );
    }
    println!(
        "follow: seasonstereo jobs status --work {}",
        quote(&work.display().to_string())
    );
    merge_outcome(s.merge_exit, &s.merge_job, work)
}

/// The merge's exit code (with --wait) as this command's result.
fn merge_outcome(exit: Option<i32>, job: &str, work: &Path) -> Result<()> {
    let see = format!(
        "see `seasonstereo jobs status --work {}` and the log {}",
        quote(&work.display().to_string()),
        work.join("jobs/logs")
            .join(format!("merge-{job}.log"))
            .display()
    );
    match exit {
        None | Some(0) => Ok(()),
        Some(2) => Err(Incomplete::Partial {
            message: format!("merge job {job} wrote a partial DSM (exit code 2): {see}"),
            failed: Vec::new(),
        }
        .into()),
        Some(3) => Err(Incomplete::Nothing {
            message: format!("merge job {job} wrote no DSM (exit code 3): {see}"),
        }
        .into()),
        Some(c) => bail!("merge job {job} failed (exit code {c}): {see}"),
    }
}

/// Done / failed / missing tiles and the command that resubmits the failed ones; exit code 2
/// while the DSM cannot be merged.
fn print_status(s: &JobStatus) -> Result<()> {
    let r = &s.record;
    let jobs = r
        .submissions
        .last()
        .map_or("none".into(), |(t, m)| format!("tiles {t}, merge {m}"));
    println!(
        "{}: {} tiles: {} done, {} failed, {} missing; array of {} tasks; last jobs: {jobs}",
        s.work.display(),
        r.tiles.len(),
        s.tiles.done.len(),
        s.tiles.failed.len(),
        s.tiles.missing.len(),
        r.array_size
    );
    units::print_units(&s.tiles);
    if s.tiles.complete() {
        println!(
            "every tile is finished; the DSM is the merge's ({})",
            r.merge_script.display()
        );
        return Ok(());
    }
    units::incomplete(&s.tiles, "tiles", &s.work)
}

//! `seasonstereo jobs slurm dataset`: the training-set stages as a Slurm chain, and the status
//! and resubmission of such a chain. The folders and per-stage options map onto the library's
//! `ChainRequest`; the scripts, markers and submission live in the library.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::Args;
use seasonstereo::jobs::{array_spec, jobs_dir, quote, split};
use seasonstereo::{chain_status, resubmit_slurm_chain, submit_slurm_chain, ChainRequest};
use seasonstereo::{ChainStatus, ChainSubmitted, StageLine};

use crate::args::heading::{CLUSTER, INPUTS, OUTPUTS};

/// The example, ending both `-h` and `--help`.
macro_rules! example {
    () => {
        "Example:
  seasonstereo jobs slurm dataset --pairs data/synchronic_only --raw data/raw \\
      --work work -o data/diachronic-stereo-synthetic --shards 16 \\
      --curate-args \"--keep 1000\" \\
      --sbatch-args \"--cpus-per-task=8 --mem=32G --time=04:00:00\"
Then: seasonstereo jobs status --work work (per-stage shards);
      seasonstereo jobs resubmit --work work"
    };
}

/// `jobs slurm dataset -h`'s epilogue.
pub const AFTER_HELP: &str = example!();

/// `jobs slurm dataset --help`'s epilogue: the stages, the job's files, the example.
pub const AFTER_LONG_HELP: &str = concat!(
    "The stages, each sharded --shards ways (`--shard I/N`, finished items skipped, files \
    written atomically), with WORK's folders between them:
  teacher       --pairs PAIRS -o WORK/teacher [--teacher-args]
  curate        --pairs PAIRS --teacher WORK/teacher -o WORK/curate [--curate-args]
  synthesize    --pairs PAIRS --raw RAW --selected WORK/curate/selected.txt
                -o WORK/synthetic [--synthesize-args]
  masks         --images WORK/synthetic/cropped -o WORK/masks [--masks-args]
  dataset build --pairs PAIRS --selected WORK/curate/selected.txt --synthetic WORK/synthetic
                --masks WORK/masks --teacher WORK/teacher -o OUT [--build-args]
  finalize:     the same `dataset build` once, unsharded (every pair skipped; the lists and
                manifest.json).
Each line is checked by this command's parser before anything is submitted.

WORK/jobs/ holds the scripts (<stage>.sh, check-<stage>.sh), logs/, shards/<stage>/<I>.exit \
    (each task's exit code; none = not run or killed) and chain.json. WORK, the binary and the \
    inputs must be on a file system every node sees.

",
    example!()
);

/// The headings of the job's options.
const STAGE_OPTIONS: &str = "Stages' options";

#[derive(Args)]
pub struct SlurmDatasetArgs {
    /// Synchronic pairs folder (L/, R/, homography/).
    ///
    /// Read by teacher, curate, synthesize and dataset build.
    #[arg(long, value_name = "DIR", help_heading = INPUTS)]
    pairs: PathBuf,
    /// Folder of the raw images, read by synthesize.
    ///
    /// Searched recursively by image id.
    #[arg(long, value_name = "DIR", help_heading = INPUTS)]
    raw: PathBuf,
    /// Work folder: the stages' outputs and jobs/.
    ///
    /// teacher/, curate/, synthetic/, masks/ and jobs/ (the scripts, logs and markers).
    #[arg(long, value_name = "DIR", help_heading = OUTPUTS)]
    work: PathBuf,
    /// The training set (dataset build's output folder).
    #[arg(short, long, value_name = "DIR", help_heading = OUTPUTS)]
    output: PathBuf,
    /// Array tasks per stage (each runs `--shard I/N`).
    #[arg(long, value_name = "N", default_value_t = 16, help_heading = CLUSTER)]
    shards: usize,
    /// More `teacher` options as one string, e.g. "--model monsterpp".
    ///
    /// For instance "--model monsterpp --weights m.pth".
    #[arg(long, value_name = "ARGS", allow_hyphen_values = true, help_heading = STAGE_OPTIONS)]
    teacher_args: Option<String>,
    /// More `curate` options as one string, e.g. "--keep 1000".
    #[arg(long, value_name = "ARGS", allow_hyphen_values = true, help_heading = STAGE_OPTIONS)]
    curate_args: Option<String>,
    /// More `synthesize` options as one string, e.g. "--generator gemini".
    ///
    /// For instance "--generator gemini --prompts s.toml".
    #[arg(long, value_name = "ARGS", allow_hyphen_values = true, help_heading = STAGE_OPTIONS)]
    synthesize_args: Option<String>,
    /// More `masks` options as one string, e.g. "--segformer mit-b2.pt".
    #[arg(long, value_name = "ARGS", allow_hyphen_values = true, help_heading = STAGE_OPTIONS)]
    masks_args: Option<String>,
    /// More `dataset build` options as one string (also of the finalize pass).
    ///
    /// For instance "--seed 3".
    #[arg(long, value_name = "ARGS", allow_hyphen_values = true, help_heading = STAGE_OPTIONS)]
    build_args: Option<String>,
    /// More sbatch options for every job, as one string (they win over ours).
    ///
    /// Partition, account, time limit, CPUs, memory, GPUs, e.g. "-p long --cpus-per-task=8
    /// --mem=32G".
    #[arg(long, value_name = "ARGS", allow_hyphen_values = true, help_heading = CLUSTER)]
    sbatch_args: Option<String>,
    /// sbatch options of one stage's tasks only (repeat for several stages).
    ///
    /// STAGE is teacher, curate, synthesize, masks, build or finalize; they come after
    /// --sbatch-args, so they win; e.g. --stage-sbatch-args "teacher=--gres=gpu:1 -p gpu".
    #[arg(long, value_name = "STAGE=ARGS", allow_hyphen_values = true, help_heading = CLUSTER)]
    stage_sbatch_args: Vec<String>,
    /// Block until the finalize pass ends; exit 0 if it succeeded, else 2.
    ///
    /// Exit code 2 names the failed shards.
    #[arg(long, help_heading = CLUSTER)]
    wait: bool,
}

/// Submits the chain and reports its jobs.
/// Parses a whole `seasonstereo` command line (the program's name first), as `main` does: how
/// the stage lines are checked before any task starts (given by `main`, which owns the parser).
pub type ParseLine = fn(&[String]) -> std::result::Result<(), clap::Error>;

pub fn submit(a: SlurmDatasetArgs, parse: ParseLine) -> Result<()> {
    let request = ChainRequest {
        what: "dataset".into(),
        binary: std::env::current_exe().context("locating the seasonstereo binary")?,
        cwd: std::env::current_dir().context("reading the current folder")?,
        work: a.work.clone(),
        stages: stage_lines(&a, parse)?,
        shards: a.shards,
        sbatch_args: split(a.sbatch_args.as_deref().unwrap_or(""))?,
        wait: a.wait,
    };
    if a.shards == 0 {
        bail!("--shards 0: give at least 1 array task per stage");
    }
    let s = submit_slurm_chain(&request)?;
    report(&s, &a.work)
}

/// The stages in order: name, the option with the user's extra arguments, the line before them
/// (`{P}` --pairs, `{R}` --raw, `{O}` --output, `{W}/x` the folder x of --work).
const STAGES: [(&str, &str, &str); 6] = [
    (
        "teacher",
        "--teacher-args",
        "teacher --pairs {P} -o {W}/teacher",
    ),
    (
        "curate",
        "--curate-args",
        "curate --pairs {P} --teacher {W}/teacher -o {W}/curate",
    ),
    (
        "synthesize",
        "--synthesize-args",
        "synthesize --pairs {P} --raw {R} --selected {W}/curate/selected.txt -o {W}/synthetic",
    ),
    (
        "masks",
        "--masks-args",
        "masks --images {W}/synthetic/cropped -o {W}/masks",
    ),
    ("build", "--build-args", BUILD),
    ("finalize", "--build-args", BUILD),
];

const BUILD: &str = "dataset build --pairs {P} --selected {W}/curate/selected.txt --synthetic \
    {W}/synthetic --masks {W}/masks --teacher {W}/teacher -o {O}";

/// The six stage lines, each checked by the parser; the global flags go to every stage.
fn stage_lines(a: &SlurmDatasetArgs, parse: ParseLine) -> Result<Vec<StageLine>> {
    let word = |w: &str| match w {
        "{P}" => a.pairs.display().to_string(),
        "{R}" => a.raw.display().to_string(),
        "{O}" => a.output.display().to_string(),
        w => match w.strip_prefix("{W}/") {
            Some(sub) => a.work.join(sub).display().to_string(),
            None => w.to_string(),
        },
    };
    let stage_sbatch = stage_sbatch_args(&a.stage_sbatch_args)?;
    let mut lines = Vec::new();
    for (name, flag, template) in STAGES {
        let mut args: Vec<String> = template.split_whitespace().map(word).collect();
        args.extend(extra(flag, extra_text(a, flag))?);
        args.extend(global_flags());
        check_line(name, flag, &args, parse)?;
        let sbatch_args = stage_sbatch
            .iter()
            .filter(|(stage, _)| stage == name)
            .flat_map(|(_, words)| words.iter().cloned())
            .collect();
        lines.push(StageLine {
            name: name.into(),
            args,
            sharded: name != "finalize",
            sbatch_args,
        });
    }
    Ok(lines)
}

/// `--stage-sbatch-args STAGE=ARGS` as (stage, words), each stage one of the chain's.
fn stage_sbatch_args(given: &[String]) -> Result<Vec<(String, Vec<String>)>> {
    given
        .iter()
        .map(|g| {
            let (stage, text) = g.split_once('=').with_context(|| {
                format!("--stage-sbatch-args {g}: give STAGE=ARGS, e.g. \"teacher=--gres=gpu:1\"")
            })?;
            if !STAGES.iter().any(|(name, _, _)| *name == stage) {
                let names: Vec<&str> = STAGES.iter().map(|s| s.0).collect();
                bail!(
                    "--stage-sbatch-args {g}: no stage {stage} (the stages: {})",
                    names.join(", ")
                );
            }
            Ok((stage.to_string(), split(text)?))
        })
        .collect()
}

/// The user's text of a stage's `--<stage>-args`.
fn extra_text<'a>(a: &'a SlurmDatasetArgs, flag: &str) -> Option<&'a str> {
    let text = match flag {
        "--teacher-args" => &a.teacher_args,
        "--curate-args" => &a.curate_args,
        "--synthesize-args" => &a.synthesize_args,
        "--masks-args" => &a.masks_args,
        _ => &a.build_args,
    };
    text.as_deref()
}

/// A stage's extra options as words; `--shard` is refused (the job sets it).
fn extra(flag: &str, text: Option<&str>) -> Result<Vec<String>> {
    let words = split(text.unwrap_or(""))?;
    if words
        .iter()
        .any(|w| w == "--shard" || w.starts_with("--shard="))
    {
        bail!("{flag}: --shard is set by the job (task I of --shards N): leave it out");
    }
    Ok(words)
}

/// `--overwrite` and `--allow-partial` as given to this command, for every stage.
fn global_flags() -> Vec<String> {
    let safety = crate::exit::safety();
    let flags = [
        (safety.overwrite, "--overwrite"),
        (safety.allow_partial, "--allow-partial"),
    ];
    flags
        .iter()
        .filter(|f| f.0)
        .map(|f| f.1.to_string())
        .collect()
}

/// Parses a stage line as `seasonstereo` would, so a typo fails here rather than on the cluster.
fn check_line(name: &str, flag: &str, args: &[String], parse: ParseLine) -> Result<()> {
    let argv: Vec<String> = std::iter::once("seasonstereo".to_string())
        .chain(args.iter().cloned())
        .collect();
    match parse(&argv) {
        Ok(()) => Ok(()),
        Err(e) => {
            let first = e.to_string();
            let first = first
                .lines()
                .next()
                .unwrap_or("")
                .trim_start_matches("error: ");
            bail!("the {name} stage's arguments do not parse ({first}): fix {flag}")
        }
    }
}

/// What was submitted; with --wait, the chain's outcome.
fn report(s: &ChainSubmitted, work: &Path) -> Result<()> {
    let jobs: Vec<String> = s.jobs.iter().map(|(n, id)| format!("{n}={id}")).collect();
    println!(
        "submitted from stage {} (array tasks {}): {}; scripts and logs in {}",
        s.first.0,
        array_spec(&s.first.1),
        jobs.join(" "),
        jobs_dir(work).display()
    );
    let shown = quote(&work.display().to_string());
    println!("follow: seasonstereo jobs status --work {shown}");
    match s.exit {
        None => Ok(()),
        Some(code) => outcome(code, work),
    }
}

/// After --wait: the shard markers, not `sbatch --wait`'s exit code alone, say whether the chain
/// finished (Slurm 22.05's `sbatch --wait` exits 0 for a job cancelled by its dependency).
fn outcome(code: i32, work: &Path) -> Result<()> {
    if chain_status(work)?.first_incomplete().is_some() {
        println!("the chain did not finish (finalize exit code {code}):");
        return status(work, None);
    }
    match code {
        0 => Ok(()),
        c => bail!(
            "every shard finished but the finalize job exited {c}: see its log in {}",
            jobs_dir(work).join("logs").display()
        ),
    }
}

/// Resubmits the first unfinished stage's failed shards and the later stages.
pub fn resubmit(work: &Path, wait: bool) -> Result<()> {
    let s = resubmit_slurm_chain(work, wait)?;
    report(&s, work)
}

/// Per-stage shard states (with `stage`, that stage's and the earlier ones'); exit code 2 naming
/// the failed shards of the first unfinished stage, with the resubmit command.
pub fn status(work: &Path, stage: Option<&str>) -> Result<()> {
    let s = chain_status(work)?;
    // A stage and the ones before it: a check names the first unfinished one, the root cause.
    let upto = match stage {
        Some(name) => s
            .stages
            .iter()
            .position(|st| st.name == name)
            .map(|k| k + 1),
        None => Some(s.stages.len()),
    };
    let Some(shown) = upto.map(|k| &s.stages[..k]) else {
        let names: Vec<&str> = s.stages.iter().map(|st| st.name.as_str()).collect();
        bail!(
            "no stage {:?} in {}: give one of {}",
            stage.unwrap_or(""),
            work.display(),
            names.join(", ")
        );
    };
    print_stages(&s, shown);
    match shown.iter().find(|st| !st.shards.complete()) {
        None => finished(&s, stage),
        Some(st) => super::units::incomplete(&st.shards, &format!("{} shards", st.name), work),
    }
}

/// One line per stage of `shown`, then one per failed or missing shard.
fn print_stages(s: &ChainStatus, shown: &[seasonstereo::StageStatus]) {
    println!(
        "{}: {} chain, {} stages",
        s.work.display(),
        s.record.what,
        s.stages.len()
    );
    for st in shown {
        let u = &st.shards;
        println!(
            "{:10} {} shards: {} done, {} failed, {} missing",
            st.name,
            u.len(),
            u.done.len(),
            u.failed.len(),
            u.missing.len()
        );
        super::units::print_units(u);
    }
}

/// The line for a finished chain (or stage).
fn finished(s: &ChainStatus, stage: Option<&str>) -> Result<()> {
    match stage {
        Some(name) => println!("every shard of {name} exited 0"),
        None => println!("every stage of the {} chain finished", s.record.what),
    }
    Ok(())
}

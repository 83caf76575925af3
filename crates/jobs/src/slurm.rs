//! Submitting a reconstruction to Slurm: an array of tile tasks sized by the plan, and a merge
//! task that runs after them whatever their outcome (`afterany`) and refuses to write a DSM
//! while tiles are failed.

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{bail, Context, Result};

use super::record::{jobs_dir, SlurmRecord};
use super::sbatch::sbatch;
use super::script::{join, quote, write_script};
use super::status::{array_spec, status};
use reconstruct::{plan, ReconstructOptions, ScenePlan};

/// What to submit besides the reconstruction's own options.
#[derive(Clone, Debug, Default)]
pub struct SlurmRequest {
    /// The `seasonstereo` binary the tasks run (on a file system the nodes see).
    pub binary: PathBuf,
    /// The `reconstruct` arguments as typed (without `--shard`, `--merge`, `--tiles-only`).
    pub args: Vec<String>,
    /// Flags given to the merge only (`--allow-partial`) and to every task (`--overwrite`).
    pub merge_flags: Vec<String>,
    pub task_flags: Vec<String>,
    /// The folder the tasks start in: relative paths in `args` are relative to it.
    pub cwd: PathBuf,
    /// More `sbatch` options (partition, account, time, GPUs), after ours: they win.
    pub sbatch_args: Vec<String>,
    /// Tiles per array task; default: the CPUs of a task.
    pub tiles_per_task: Option<usize>,
    /// CPUs per tile task; default: as many tiles as fit in `--max-memory`, at most a node's CPUs.
    pub cpus: Option<usize>,
    /// Block until the merge ends (`sbatch --wait`).
    pub wait: bool,
}

/// A task's CPUs and memory.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Resources {
    pub cpus: usize,
    /// MiB.
    pub mem_mib: u64,
}

/// What was submitted.
#[derive(Clone, Debug)]
pub struct Submitted {
    pub tiles_job: String,
    pub merge_job: String,
    /// The array tasks submitted.
    pub tasks: Vec<usize>,
    pub record: SlurmRecord,
    /// The tile tasks' and the merge's resources, for a first submission (a resubmission reuses
    /// the record's options).
    pub resources: Option<(Resources, Resources)>,
    /// The merge's exit code, with `wait`.
    pub merge_exit: Option<i32>,
}

/// Plans the tiles of `opts`, writes the job scripts into the work folder and submits the tile
/// array and the merge.
pub fn submit_reconstruct(opts: &ReconstructOptions, req: &SlurmRequest) -> Result<Submitted> {
    let plan = plan(opts)?;
    let node_cpus = node_cpus()?;
    let tiles = tile_resources(&plan, opts.max_memory, req.cpus, node_cpus)?;
    let merge = Resources {
        cpus: tiles.cpus,
        mem_mib: with_headroom(plan.merge_memory + plan.process_memory),
    };
    let tiles_per_task = req.tiles_per_task.unwrap_or(tiles.cpus).max(1);
    let array_size = plan.tiles.len().div_ceil(tiles_per_task);
    let record = write_scripts(&plan, req, array_size, tiles_per_task, (tiles, merge))?;
    let all: Vec<usize> = (0..array_size).collect();
    let submitted = submit(&plan.work, record, &all, req.wait)?;
    Ok(Submitted {
        resources: Some((tiles, merge)),
        ..submitted
    })
}

/// Submits again the array tasks of `work` holding failed or missing tiles, and a merge after
/// them.
pub fn resubmit(work: &Path, wait: bool) -> Result<Submitted> {
    let s = status(work)?;
    let tasks = s.tiles.tasks_to_rerun();
    if tasks.is_empty() {
        bail!(
            "every tile of {} is finished: nothing to resubmit (run the merge script {} if the \
             DSM is missing)",
            work.display(),
            s.record.merge_script.display()
        );
    }
    let ids = s.record.submissions.iter();
    super::sbatch::refuse_while_queued(ids.flat_map(|(t, m)| [t.as_str(), m.as_str()]))?;
    submit(work, s.record, &tasks, wait)
}

/// Memory requested for a budget: 10 % over it, MiB (the process plans to stay under it).
fn with_headroom(bytes: u64) -> u64 {
    (bytes + bytes / 10).div_ceil(1 << 20)
}

/// The tile tasks' CPUs (asked for, else as many tiles as fit in the budget, at most a node's
/// CPUs) and memory (the budget).
fn tile_resources(
    plan: &ScenePlan,
    max_memory: u64,
    cpus: Option<usize>,
    node_cpus: usize,
) -> Result<Resources> {
    let fit = (max_memory.saturating_sub(plan.process_memory) / plan.tile_memory.max(1)) as usize;
    let cpus = match cpus {
        Some(c) if c > node_cpus => bail!(
            "--cpus-per-task {c}: the largest node has {node_cpus} CPUs (sinfo): ask for at \
             most {node_cpus}"
        ),
        Some(c) => c.max(1),
        None => fit.clamp(1, node_cpus.min(plan.tiles.len()).max(1)),
    };
    Ok(Resources {
        cpus,
        mem_mib: with_headroom(max_memory),
    })
}

/// The CPUs of the largest node, from `sinfo`.
fn node_cpus() -> Result<usize> {
    let out = Command::new("sinfo")
        .args(["--noheader", "--format=%c"])
        .output()
        .context("running sinfo (is this a Slurm login node?)")?;
    let text = String::from_utf8_lossy(&out.stdout);
    let cpus = text
        .lines()
        .filter_map(|l| l.trim().trim_end_matches('+').parse::<usize>().ok())
        .max();
    match (out.status.success(), cpus) {
        (true, Some(c)) => Ok(c),
        _ => bail!(
            "sinfo gave no node CPU count ({}): check that Slurm is reachable (`sinfo`)",
            String::from_utf8_lossy(&out.stderr).trim()
        ),
    }
}

/// Writes the tile and merge scripts and the record into `<work>/jobs/`.
fn write_scripts(
    plan: &ScenePlan,
    req: &SlurmRequest,
    array_size: usize,
    tiles_per_task: usize,
    (tiles, merge): (Resources, Resources),
) -> Result<SlurmRecord> {
    let dir = workflow::outputs::resolve(&jobs_dir(&plan.work));
    std::fs::create_dir_all(dir.join("logs"))
        .with_context(|| format!("creating {} (is --work writable?)", dir.display()))?;
    let mut args = req.args.clone();
    args.extend(req.task_flags.iter().cloned());
    let run = format!(
        "exec {} reconstruct {}",
        quote(&req.binary.display().to_string()),
        join(&args)
    );
    let tiles_script = dir.join("reconstruct-tiles.sh");
    let merge_script = dir.join("reconstruct-merge.sh");
    let what = format!("the {} tiles of {}", plan.tiles.len(), plan.stem);
    write_script(
        &tiles_script,
        "jobs slurm reconstruct",
        &what,
        &req.cwd,
        &format!(
            "# Array task I runs the tiles at positions I, I+{array_size}, … of the plan; \
             exit code 2 when some failed.\n{run} --tiles-only --shard \
             \"${{SLURM_ARRAY_TASK_ID:?run as a Slurm array task}}/{array_size}\"\n"
        ),
    )?;
    let merge_flags = join(&req.merge_flags);
    write_script(
        &merge_script,
        "jobs slurm reconstruct",
        &what,
        &req.cwd,
        &format!("# The DSM from the tiles; exit code 3 while tiles are failed.\n{run} --merge {merge_flags}\n"),
    )?;
    let sbatch = |kind: &str, r: Resources, log: &str| -> Vec<String> {
        let mut v = vec![
            format!("--job-name=ss-{kind}-{}", plan.stem),
            format!("--cpus-per-task={}", r.cpus),
            format!("--mem={}M", r.mem_mib),
            format!("--output={}", dir.join("logs").join(log).display()),
        ];
        v.extend(req.sbatch_args.iter().cloned());
        v
    };
    let record = SlurmRecord {
        tiles: plan.tiles.clone(),
        array_size,
        tiles_per_task,
        tiles_sbatch: sbatch("tiles", tiles, "tiles-%A_%a.log"),
        merge_sbatch: sbatch("merge", merge, "merge-%j.log"),
        tiles_script,
        merge_script,
        submissions: Vec::new(),
    };
    record.write(&plan.work)?;
    Ok(record)
}

/// Submits `tasks` of the tile array, then the merge `afterany` on it; records both job ids.
fn submit(work: &Path, mut record: SlurmRecord, tasks: &[usize], wait: bool) -> Result<Submitted> {
    let mut args = vec![
        "--parsable".to_string(),
        format!("--array={}", array_spec(tasks)),
    ];
    args.extend(record.tiles_sbatch.iter().cloned());
    args.push(record.tiles_script.display().to_string());
    let (tiles_job, _) = sbatch(&args, false)?;
    let mut args = vec![
        "--parsable".to_string(),
        format!("--dependency=afterany:{tiles_job}"),
    ];
    if wait {
        args.push("--wait".into());
    }
    args.extend(record.merge_sbatch.iter().cloned());
    args.push(record.merge_script.display().to_string());
    // The record first: a `--wait` may last hours, and `status` must know the jobs meanwhile.
    record
        .submissions
        .push((tiles_job.clone(), "(being submitted)".into()));
    record.write(work)?;
    let (merge_job, exit) = sbatch(&args, wait)?;
    if let Some(last) = record.submissions.last_mut() {
        last.1 = merge_job.clone();
    }
    record.write(work)?;
    Ok(Submitted {
        tiles_job,
        merge_job,
        tasks: tasks.to_vec(),
        record,
        resources: None,
        merge_exit: exit,
    })
}

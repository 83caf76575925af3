//! Submitting a chain of sharded stages to Slurm (the training-set build: teacher → curate →
//! synthesize → masks → dataset build → finalize): one array job per stage, a check step after
//! each (`afterany`) that fails, naming the failed shards, unless every shard succeeded, and the
//! next stage `afterok` on that check with `--kill-on-invalid-dep=yes`, so a failed shard
//! cancels the rest of the chain instead of leaving it pending for ever.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};

use super::chain_record::{chain_status, marker_dir, ChainRecord, StageJob};
use super::record::jobs_dir;
use super::sbatch::sbatch;
use super::script::{join, quote, write_script};
use super::status::array_spec;

/// One stage's command line.
#[derive(Clone, Debug)]
pub struct StageLine {
    /// `teacher`, `curate`, …: names its scripts, logs and markers.
    pub name: String,
    /// The arguments after the binary (`teacher --pairs … -o …`), without `--shard`.
    pub args: Vec<String>,
    /// Run as an array of `--shard I/N` tasks; else one task without `--shard`.
    pub sharded: bool,
    /// sbatch options of this stage's tasks only, after the chain's (they win): a GPU for the
    /// teacher, more memory for synthesize.
    pub sbatch_args: Vec<String>,
}

/// A chain to submit.
#[derive(Clone, Debug, Default)]
pub struct ChainRequest {
    /// What the chain builds, for messages ("dataset").
    pub what: String,
    /// The `seasonstereo` binary the tasks run (on a file system the nodes see).
    pub binary: PathBuf,
    /// The folder the tasks start in: relative paths in the stages' arguments are relative to it.
    pub cwd: PathBuf,
    /// The work folder: `jobs/` (scripts, logs, markers, record) goes there.
    pub work: PathBuf,
    pub stages: Vec<StageLine>,
    /// Array tasks per sharded stage.
    pub shards: usize,
    /// More `sbatch` options (partition, account, time, CPUs, memory), after ours: they win.
    pub sbatch_args: Vec<String>,
    /// Block until the last stage ends (`sbatch --wait`).
    pub wait: bool,
}

/// What was submitted.
#[derive(Clone, Debug)]
pub struct ChainSubmitted {
    pub record: ChainRecord,
    /// `(job name, job id)` of this submission, in order.
    pub jobs: Vec<(String, String)>,
    /// The stage the submission starts at and its array tasks.
    pub first: (String, Vec<usize>),
    /// The last stage's exit code, with `wait`.
    pub exit: Option<i32>,
}

/// Writes the stages' scripts and the record into `<work>/jobs/` and submits the whole chain.
pub fn submit_chain(req: &ChainRequest) -> Result<ChainSubmitted> {
    if req.shards == 0 || req.stages.is_empty() {
        bail!("a chain needs at least one stage and one shard (--shards N, N ≥ 1)");
    }
    let work = workflow::outputs::resolve(&req.work);
    let record = write_scripts(req, &work)?;
    let all = (0..record.stages[0].shards).collect();
    submit(&work, record, 0, all, req.wait)
}

/// Submits again the failed and missing shards of the first unfinished stage of `work`, then
/// every later stage in full (their finished items are skipped).
pub fn resubmit_chain(work: &Path, wait: bool) -> Result<ChainSubmitted> {
    let s = chain_status(work)?;
    let Some(from) = s.first_incomplete() else {
        bail!(
            "every stage of {} finished: nothing to resubmit",
            work.display()
        );
    };
    let tasks = s.stages[from].shards.tasks_to_rerun();
    let ids = s
        .record
        .submissions
        .iter()
        .flatten()
        .map(|(_, id)| id.as_str());
    super::sbatch::refuse_while_queued(ids)?;
    submit(work, s.record, from, tasks, wait)
}

/// Writes every stage's task script and check script, and the record.
fn write_scripts(req: &ChainRequest, work: &Path) -> Result<ChainRecord> {
    let dir = jobs_dir(work);
    std::fs::create_dir_all(dir.join("logs"))
        .with_context(|| format!("creating {} (is --work writable?)", dir.display()))?;
    let last = req.stages.len() - 1;
    let stages = req
        .stages
        .iter()
        .enumerate()
        .map(|(k, line)| write_stage(req, work, line, k < last))
        .collect::<Result<Vec<_>>>()?;
    let record = ChainRecord {
        what: req.what.clone(),
        stages,
        submissions: Vec::new(),
    };
    record.write(work)?;
    Ok(record)
}

/// One stage's task script, its check script (`checked`: every stage but the last) and sbatch
/// options.
fn write_stage(
    req: &ChainRequest,
    work: &Path,
    line: &StageLine,
    checked: bool,
) -> Result<StageJob> {
    let dir = jobs_dir(work);
    let binary = quote(&req.binary.display().to_string());
    let shards = if line.sharded { req.shards } else { 1 };
    let markers = marker_dir(work, &line.name);
    std::fs::create_dir_all(&markers).with_context(|| format!("creating {}", markers.display()))?;
    let script = dir.join(format!("{}.sh", line.name));
    let what = format!("stage {} of the {} chain", line.name, req.what);
    let run = format!("{binary} {}", join(&line.args));
    let body = task_body(&run, &markers, shards, line.sharded);
    write_script(&script, "jobs slurm", &what, &req.cwd, &body)?;
    let check = checked.then(|| dir.join(format!("check-{}.sh", line.name)));
    if let Some(path) = &check {
        let body = format!(
            "# Fails (exit 2), naming the failed shards and the resubmit command, unless every \
             shard of\n# {} and of the stages before it exited 0.\nexec {binary} jobs status \
             --work {} --stage {}\n",
            line.name,
            quote(&work.display().to_string()),
            quote(&line.name)
        );
        write_script(
            path,
            "jobs slurm",
            &format!("the check of {what}"),
            &req.cwd,
            &body,
        )?;
    }
    let options = |name: &str, pattern: &str, ours: &[&str], stage: &[String]| {
        let log = dir.join("logs").join(format!("{name}-{pattern}.log"));
        let mut v = vec![format!("--job-name=ss-{name}")];
        v.extend(ours.iter().map(|o| o.to_string()));
        v.push(format!("--output={}", log.display()));
        v.extend(req.sbatch_args.iter().cloned());
        v.extend(stage.iter().cloned());
        v
    };
    let pattern = if line.sharded { "%A_%a" } else { "%j" };
    let check_name = format!("check-{}", line.name);
    Ok(StageJob {
        name: line.name.clone(),
        shards,
        sharded: line.sharded,
        script,
        check,
        sbatch: options(&line.name, pattern, &[], &line.sbatch_args),
        check_sbatch: options(&check_name, "%j", &["--cpus-per-task=1", "--mem=256M"], &[]),
    })
}

/// A stage task: clears its marker, runs the stage (its shard), leaves its exit code in the
/// marker, exits with it.
fn task_body(run: &str, markers: &Path, shards: usize, sharded: bool) -> String {
    let (index, shard) = match sharded {
        true => (
            "i=${SLURM_ARRAY_TASK_ID:?run as a Slurm array task}",
            format!(" --shard \"$i/{shards}\""),
        ),
        false => ("i=0", String::new()),
    };
    format!(
        "# Its exit code is left in {dir}/<task>.exit for the check step.\n{index}\n\
         m={q}/\"$i\".exit\nrm -f \"$m\"\n{run}{shard}\nrc=$?\n\
         echo \"$rc\" > \"$m.tmp\" && mv -f \"$m.tmp\" \"$m\"\nexit \"$rc\"\n",
        dir = markers.display(),
        q = quote(&markers.display().to_string()),
    )
}

/// Submits stage `from` (array tasks `tasks`) and every later stage, each with its check;
/// records the job ids as they come.
fn submit(
    work: &Path,
    mut record: ChainRecord,
    from: usize,
    tasks: Vec<usize>,
    wait: bool,
) -> Result<ChainSubmitted> {
    record.submissions.push(Vec::new());
    let (mut after, mut exit) = (None::<String>, None);
    let last = record.stages.len() - 1;
    for k in from..record.stages.len() {
        let stage = record.stages[k].clone();
        let run: Vec<usize> = if k == from {
            tasks.clone()
        } else {
            (0..stage.shards).collect()
        };
        clear_markers(work, &stage.name, &run)?;
        let mut args = vec!["--parsable".to_string()];
        if stage.sharded {
            args.push(format!("--array={}", array_spec(&run)));
        }
        if let Some(check) = &after {
            args.push(format!("--dependency=afterok:{check}"));
            args.push("--kill-on-invalid-dep=yes".into());
        }
        if k == last && wait {
            args.push("--wait".into());
        }
        args.extend(stage.sbatch.iter().cloned());
        args.push(stage.script.display().to_string());
        let (id, code) = sbatch(&args, k == last && wait)?;
        (after, exit) = (Some(id.clone()), code);
        push_job(work, &mut record, &stage.name, &id)?;
        if let Some(check) = &stage.check {
            let mut args = vec![
                "--parsable".to_string(),
                format!("--dependency=afterany:{id}"),
            ];
            args.extend(stage.check_sbatch.iter().cloned());
            args.push(check.display().to_string());
            let (check_id, _) = sbatch(&args, false)?;
            push_job(
                work,
                &mut record,
                &format!("check-{}", stage.name),
                &check_id,
            )?;
            after = Some(check_id);
        }
    }
    Ok(ChainSubmitted {
        jobs: record.submissions.last().cloned().unwrap_or_default(),
        first: (record.stages[from].name.clone(), tasks),
        record,
        exit,
    })
}

/// Records a job id of the current submission.
fn push_job(work: &Path, record: &mut ChainRecord, name: &str, id: &str) -> Result<()> {
    if let Some(jobs) = record.submissions.last_mut() {
        jobs.push((name.to_string(), id.to_string()));
    }
    record.write(work)
}

/// Removes the markers of the tasks about to run: until they end, they are missing.
fn clear_markers(work: &Path, stage: &str, tasks: &[usize]) -> Result<()> {
    for i in tasks {
        let path = marker_dir(work, stage).join(format!("{i}.exit"));
        match std::fs::remove_file(&path) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                return Err(e).with_context(|| format!("removing {}", path.display()))
            }
            _ => {}
        }
    }
    Ok(())
}

//! Running `sbatch`: a job id back, and with `--wait` the job's exit code; and asking `squeue`
//! which of a work folder's jobs Slurm still holds, before any of their work is sent again.

use std::process::Command;

use anyhow::{bail, Context, Result};

use super::script::join;

/// Runs `sbatch args`: the job id, and its exit code with `wait` (`sbatch --wait` exits with the
/// job's).
pub fn sbatch(args: &[String], wait: bool) -> Result<(String, Option<i32>)> {
    let out = Command::new("sbatch")
        .args(args)
        .output()
        .context("running sbatch (is this a Slurm login node, with sbatch on PATH?)")?;
    let stdout = String::from_utf8_lossy(&out.stdout);
    let id = stdout
        .lines()
        .find_map(|l| l.split(';').next().map(str::trim).filter(|s| !s.is_empty()))
        .map(str::to_string);
    match id {
        Some(id) if out.status.success() || wait => {
            Ok((id, wait.then(|| out.status.code().unwrap_or(1))))
        }
        _ => bail!(
            "sbatch {} failed: {}",
            join(args),
            String::from_utf8_lossy(&out.stderr).trim()
        ),
    }
}

/// Refuses to resubmit while any of `ids` (a work folder's submitted jobs) is still queued or
/// running for this user: its tasks have no exit marker yet, and sending them again would run
/// them twice, racing on the same outputs.
pub fn refuse_while_queued<'a>(ids: impl IntoIterator<Item = &'a str>) -> Result<()> {
    let ours: Vec<&str> = ids.into_iter().collect();
    // %F: the array's job id for an array task, the job id otherwise.
    let out = Command::new("squeue")
        .args(["--noheader", "--me", "--format=%F"])
        .output()
        .context("running squeue (is this a Slurm login node, with squeue on PATH?)")?;
    if !out.status.success() {
        bail!(
            "squeue --me failed: {}",
            String::from_utf8_lossy(&out.stderr).trim()
        );
    }
    let queued = String::from_utf8_lossy(&out.stdout);
    let mut active: Vec<&str> = ours
        .into_iter()
        .filter(|id| queued.lines().any(|l| l.trim() == *id))
        .collect();
    active.sort_unstable();
    active.dedup();
    if !active.is_empty() {
        bail!(
            "job(s) {} of this work folder are still queued or running (squeue): wait for \
             them to end (jobs status shows their tasks), or cancel them (scancel {}), then \
             resubmit",
            active.join(", "),
            active.join(" ")
        );
    }
    Ok(())
}

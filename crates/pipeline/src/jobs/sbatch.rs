//! Running `sbatch`: a job id back, and with `--wait` the job's exit code.

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

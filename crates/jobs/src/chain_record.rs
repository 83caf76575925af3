//! `jobs/chain.json` in the work folder: a chain of sharded stages submitted to Slurm (what each
//! stage runs, its scripts, the job ids), and the shard markers its tasks leave behind, read
//! back into per-stage shard states by `status` and `resubmit`.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};

use super::record::jobs_dir;
use super::status::Units;
use workflow::stage::{read_json, write_json};

/// One stage of a chain as submitted.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct StageJob {
    /// `teacher`, `curate`, … (also the name of its logs and marker folder).
    pub name: String,
    /// Array tasks (`--shard I/N`); 1 and no array for an unsharded stage.
    pub shards: usize,
    pub sharded: bool,
    pub script: PathBuf,
    /// The check step after it (none for the last stage).
    pub check: Option<PathBuf>,
    /// `sbatch` options of the stage's tasks and of its check (logs, the user's).
    pub sbatch: Vec<String>,
    pub check_sbatch: Vec<String>,
}

/// A chain of stages submitted to Slurm.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ChainRecord {
    /// What the chain builds, for messages ("dataset").
    pub what: String,
    pub stages: Vec<StageJob>,
    /// `(job name, job id)` of every submission, the first one first.
    pub submissions: Vec<Vec<(String, String)>>,
}

/// One stage's shards by state.
#[derive(Clone, Debug)]
pub struct StageStatus {
    pub name: String,
    pub shards: Units,
}

/// Every stage of a chain, in order.
#[derive(Clone, Debug)]
pub struct ChainStatus {
    pub work: PathBuf,
    pub record: ChainRecord,
    pub stages: Vec<StageStatus>,
}

impl ChainStatus {
    /// The first stage with failed or missing shards: where a resubmission starts.
    pub fn first_incomplete(&self) -> Option<usize> {
        self.stages.iter().position(|s| !s.shards.complete())
    }
}

fn record_path(work: &Path) -> PathBuf {
    jobs_dir(work).join("chain.json")
}

/// Whether `work` holds a chain submission (rather than a reconstruction).
pub fn is_chain(work: &Path) -> bool {
    record_path(work).is_file()
}

/// The folder of a stage's shard markers: `<I>.exit` holds array task I's exit code, written
/// when the task ends (none: not run yet, or killed).
pub fn marker_dir(work: &Path, stage: &str) -> PathBuf {
    jobs_dir(work).join("shards").join(stage)
}

impl ChainRecord {
    /// The record of the chain in `work`; an error naming the file when there is none.
    pub fn read(work: &Path) -> Result<ChainRecord> {
        let path = record_path(work);
        read_json(&path)?.with_context(|| {
            format!(
                "{} does not exist: {} was not submitted by `seasonstereo jobs slurm dataset` \
                 (give the --work folder of that command)",
                path.display(),
                work.display()
            )
        })
    }

    /// Saves the record, atomically.
    pub fn write(&self, work: &Path) -> Result<()> {
        write_json(&record_path(work), self)
    }

    /// The last job id submitted under `name`.
    pub fn last_job(&self, name: &str) -> Option<&str> {
        let mut jobs = self.submissions.iter().rev().flatten();
        jobs.find(|(n, _)| n == name).map(|(_, id)| id.as_str())
    }
}

/// The shard states of every stage of the chain in `work`, read from the markers.
pub fn chain_status(work: &Path) -> Result<ChainStatus> {
    let record = ChainRecord::read(work)?;
    let stages = record
        .stages
        .iter()
        .map(|s| StageStatus {
            name: s.name.clone(),
            shards: stage_units(work, &record, s),
        })
        .collect();
    Ok(ChainStatus {
        work: work.to_path_buf(),
        record,
        stages,
    })
}

/// A stage's shards: done (exit 0), failed (exit code and log), missing (no marker).
fn stage_units(work: &Path, record: &ChainRecord, stage: &StageJob) -> Units {
    let dir = marker_dir(work, &stage.name);
    let job = record.last_job(&stage.name).unwrap_or("?");
    let mut units = Units::default();
    for i in 0..stage.shards {
        let id = format!("{} shard {i}/{}", stage.name, stage.shards);
        let code = std::fs::read_to_string(dir.join(format!("{i}.exit")))
            .ok()
            .and_then(|t| t.trim().parse::<i32>().ok());
        match code {
            None => units.missing.push((id, i)),
            Some(0) => units.done.push(id),
            Some(c) => {
                let log = match stage.sharded {
                    true => format!("{}-{job}_{i}.log", stage.name),
                    false => format!("{}-{job}.log", stage.name),
                };
                let log = jobs_dir(work).join("logs").join(log);
                let error = format!("exit code {c}, see {}", log.display());
                units.failed.push((id, i, error));
            }
        }
    }
    units
}

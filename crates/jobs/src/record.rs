//! `jobs/slurm.json` in the work folder: what a submission planned and submitted, read back by
//! `status` and `resubmit`.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};

use reconstruct::plan::Tile;
use workflow::stage::{read_json, write_json};

/// A reconstruction submitted to Slurm.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SlurmRecord {
    /// The plan's tiles (array task `i` runs those at positions ≡ i mod `array_size`).
    pub tiles: Vec<Tile>,
    /// Tasks of the array.
    pub array_size: usize,
    /// Tiles per task asked for.
    pub tiles_per_task: usize,
    pub tiles_script: PathBuf,
    pub merge_script: PathBuf,
    /// `sbatch` options of the tile tasks and of the merge (resources, logs, the user's).
    pub tiles_sbatch: Vec<String>,
    pub merge_sbatch: Vec<String>,
    /// `(tiles job, merge job)` of every submission, the first one first.
    pub submissions: Vec<(String, String)>,
}

/// The folder of the job files in a work folder.
pub fn jobs_dir(work: &Path) -> PathBuf {
    work.join("jobs")
}

fn record_path(work: &Path) -> PathBuf {
    jobs_dir(work).join("slurm.json")
}

impl SlurmRecord {
    /// The record of the submission in `work`; an error naming the file when there is none.
    pub fn read(work: &Path) -> Result<SlurmRecord> {
        let path = record_path(work);
        read_json(&path)?.with_context(|| {
            format!(
                "{} does not exist: {} was not submitted by `seasonstereo jobs slurm \
                 reconstruct` or `jobs slurm dataset` (give the --work folder of that command)",
                path.display(),
                work.display()
            )
        })
    }

    /// Saves the record, atomically.
    pub fn write(&self, work: &Path) -> Result<()> {
        write_json(&record_path(work), self)
    }

    /// The array task that runs tile `index`.
    pub fn task_of(&self, index: usize) -> usize {
        index % self.array_size.max(1)
    }
}

//! What a submitted job's work folder holds: units (tiles, shards) done, failed (with their
//! errors) and missing, and the array tasks to run again.

use std::path::{Path, PathBuf};

use anyhow::Result;

use super::record::SlurmRecord;
use reconstruct::folder::TileFolder;
use reconstruct::tile::TileStatus;

/// The work units of an array job (a reconstruction's tiles, a stage's shards), by state.
#[derive(Clone, Debug, Default)]
pub struct Units {
    /// Finished units (tiles with points or empty, shards that exited 0).
    pub done: Vec<String>,
    /// Failed units: `(id, array task, error)`.
    pub failed: Vec<(String, usize, String)>,
    /// Units without a record (their task has not run, or was killed): `(id, array task)`.
    pub missing: Vec<(String, usize)>,
}

impl Units {
    /// The array tasks holding a failed or missing unit, in order.
    pub fn tasks_to_rerun(&self) -> Vec<usize> {
        let mut tasks: Vec<usize> = self
            .failed
            .iter()
            .map(|f| f.1)
            .chain(self.missing.iter().map(|m| m.1))
            .collect();
        tasks.sort_unstable();
        tasks.dedup();
        tasks
    }

    /// The `--array` value of [`Self::tasks_to_rerun`].
    pub fn rerun_array(&self) -> String {
        array_spec(&self.tasks_to_rerun())
    }

    /// Every unit finished.
    pub fn complete(&self) -> bool {
        self.failed.is_empty() && self.missing.is_empty()
    }

    /// The failed units' ids, then the missing ones'.
    pub fn unfinished(&self) -> Vec<String> {
        let failed = self.failed.iter().map(|f| f.0.clone());
        failed
            .chain(self.missing.iter().map(|m| m.0.clone()))
            .collect()
    }

    /// The number of units.
    pub fn len(&self) -> usize {
        self.done.len() + self.failed.len() + self.missing.len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// The tiles of a submission, by state.
#[derive(Clone, Debug)]
pub struct JobStatus {
    pub work: PathBuf,
    pub record: SlurmRecord,
    pub tiles: Units,
}

/// The state of the tiles of the submission in `work`, read from the tiles' records.
pub fn status(work: &Path) -> Result<JobStatus> {
    let record = SlurmRecord::read(work)?;
    let folder = TileFolder::new(work);
    let mut s = Units::default();
    for tile in &record.tiles {
        let task = record.task_of(tile.index);
        match folder.record(tile) {
            None => s.missing.push((tile.id.clone(), task)),
            Some(r) if r.status == TileStatus::Failed => s.failed.push((
                tile.id.clone(),
                task,
                r.error.unwrap_or_else(|| "no message".into()),
            )),
            Some(_) => s.done.push(tile.id.clone()),
        }
    }
    Ok(JobStatus {
        work: work.to_path_buf(),
        record,
        tiles: s,
    })
}

/// Slurm's `--array` value for `tasks`: `0-3` for a run, else `1,4,7`.
pub fn array_spec(tasks: &[usize]) -> String {
    match (tasks.first(), tasks.last()) {
        (Some(&a), Some(&b)) if b - a + 1 == tasks.len() && tasks.len() > 1 => format!("{a}-{b}"),
        _ => tasks
            .iter()
            .map(|t| t.to_string())
            .collect::<Vec<_>>()
            .join(","),
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn array_specs() {
        assert_eq!(super::array_spec(&[0, 1, 2, 3]), "0-3");
        assert_eq!(super::array_spec(&[2]), "2");
        assert_eq!(super::array_spec(&[1, 4]), "1,4");
    }
}

//! Training checkpoints: everything a run needs to continue exactly, written atomically.
//!
//! A checkpoint is a folder `<output>/checkpoints/step-0000123/` with
//! - `model.safetensors`: every parameter and BatchNorm statistic in PyTorch naming
//!   ([`nn::weights::save_checkpoint`]; loads into upstream PyTorch and back with
//!   [`nn::weights::load_weights`], so it is also the deliverable model);
//! - `optimizer.bpk`: the AdamW moments and step counts (burnpack);
//! - `state.json`: the step, the seed (the data order and the augmentation are functions of
//!   `(seed, step)`, see [`crate::data`]), the best validation EPE, the parameter ids the
//!   optimiser state is keyed by, and the run's configuration.
//!
//! The folder is written under a temporary name and renamed, then `checkpoints/latest` (written
//! atomically) names it: a crash leaves either the previous checkpoint or the new one, never a
//! half-written one.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::TrainError;

/// Version of the `state.json` layout.
pub const FORMAT: u32 = 1;
/// File names inside a checkpoint folder.
pub const MODEL_FILE: &str = "model.safetensors";
pub const OPTIMIZER_FILE: &str = "optimizer.bpk";
pub const STATE_FILE: &str = "state.json";
/// Pointer file naming the newest checkpoint folder.
pub const LATEST_FILE: &str = "latest";

/// `state.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CheckpointState {
    pub format: u32,
    /// Optimiser steps done (the next step to run, 0-based).
    pub step: usize,
    /// Seed of the data order and the augmentation.
    pub seed: u64,
    /// Learning rate of the last step done.
    pub last_lr: f64,
    /// Best validation EPE so far (`None` before the first validation).
    pub best_epe: Option<f64>,
    /// Float parameter ids by path (the optimiser state is keyed by them).
    pub param_ids: BTreeMap<String, u64>,
    /// The run's configuration (TOML).
    pub config: String,
}

/// The checkpoints folder of a run.
pub fn checkpoints_dir(output: &Path) -> PathBuf {
    output.join("checkpoints")
}

/// Folder name of the checkpoint after `step` steps.
pub fn step_dir_name(step: usize) -> String {
    format!("step-{step:07}")
}

/// Writes a checkpoint folder atomically and points `latest` to it. `write_model` and
/// `write_optimizer` receive the destination file paths inside the temporary folder.
pub fn write(
    output: &Path,
    state: &CheckpointState,
    write_model: impl FnOnce(&Path) -> Result<(), TrainError>,
    write_optimizer: impl FnOnce(&Path) -> Result<(), TrainError>,
) -> Result<PathBuf, TrainError> {
    let dir = checkpoints_dir(output);
    std::fs::create_dir_all(&dir).map_err(|e| TrainError::io(&dir, e))?;
    let name = step_dir_name(state.step);
    let final_dir = dir.join(&name);
    let tmp = dir.join(format!(".partial-{name}-{}", std::process::id()));
    if tmp.exists() {
        std::fs::remove_dir_all(&tmp).map_err(|e| TrainError::io(&tmp, e))?;
    }
    std::fs::create_dir_all(&tmp).map_err(|e| TrainError::io(&tmp, e))?;
    write_model(&tmp.join(MODEL_FILE))?;
    write_optimizer(&tmp.join(OPTIMIZER_FILE))?;
    let json = serde_json::to_string_pretty(state).expect("state serialises");
    let state_path = tmp.join(STATE_FILE);
    std::fs::write(&state_path, json).map_err(|e| TrainError::io(&state_path, e))?;
    if final_dir.exists() {
        std::fs::remove_dir_all(&final_dir).map_err(|e| TrainError::io(&final_dir, e))?;
    }
    std::fs::rename(&tmp, &final_dir).map_err(|e| TrainError::io(&final_dir, e))?;
    let latest = dir.join(LATEST_FILE);
    raster::formats::write_atomically(&latest, |f| {
        use std::io::Write;
        writeln!(f, "{name}")
    })
    .map_err(|e| TrainError::Checkpoint(e.to_string()))?;
    Ok(final_dir)
}

/// Deletes all but the newest `keep + 1` checkpoint folders (`keep = 0`: keeps all).
pub fn prune(output: &Path, keep: usize) -> Result<(), TrainError> {
    if keep == 0 {
        return Ok(());
    }
    let dir = checkpoints_dir(output);
    let mut steps: Vec<PathBuf> = std::fs::read_dir(&dir)
        .map_err(|e| TrainError::io(&dir, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.is_dir()
                && p.file_name()
                    .and_then(|n| n.to_str())
                    .is_some_and(|n| n.starts_with("step-"))
        })
        .collect();
    steps.sort();
    let n = steps.len();
    for p in steps.into_iter().take(n.saturating_sub(keep + 1)) {
        std::fs::remove_dir_all(&p).map_err(|e| TrainError::io(&p, e))?;
    }
    Ok(())
}

/// A checkpoint found on disk.
#[derive(Debug, Clone)]
pub struct Checkpoint {
    /// The checkpoint folder.
    pub dir: PathBuf,
    pub state: CheckpointState,
}

impl Checkpoint {
    /// Opens `path`: a checkpoint folder (with `state.json`) or a run folder (its newest
    /// checkpoint, named by `checkpoints/latest`).
    pub fn open(path: &Path) -> Result<Self, TrainError> {
        let dir = if path.join(STATE_FILE).is_file() {
            path.to_path_buf()
        } else {
            let latest = checkpoints_dir(path).join(LATEST_FILE);
            let name = std::fs::read_to_string(&latest).map_err(|_| {
                TrainError::Checkpoint(format!(
                    "{}: neither a checkpoint folder (no {STATE_FILE}) nor a run folder (no checkpoints/{LATEST_FILE}); give the run's output folder or one of its checkpoints/step-* folders",
                    path.display()
                ))
            })?;
            checkpoints_dir(path).join(name.trim())
        };
        let state_path = dir.join(STATE_FILE);
        let text =
            std::fs::read_to_string(&state_path).map_err(|e| TrainError::io(&state_path, e))?;
        let state: CheckpointState = serde_json::from_str(&text).map_err(|e| {
            TrainError::Checkpoint(format!(
                "{}: corrupt checkpoint state ({e}); resume from an older checkpoints/step-* folder",
                state_path.display()
            ))
        })?;
        if state.format != FORMAT {
            return Err(TrainError::Checkpoint(format!(
                "{}: checkpoint format {} is not supported (expected {FORMAT})",
                state_path.display(),
                state.format
            )));
        }
        for f in [MODEL_FILE, OPTIMIZER_FILE] {
            if !dir.join(f).is_file() {
                return Err(TrainError::Checkpoint(format!(
                    "{}: missing {f}; resume from another checkpoint",
                    dir.display()
                )));
            }
        }
        Ok(Self { dir, state })
    }

    /// `model.safetensors`.
    pub fn model_path(&self) -> PathBuf {
        self.dir.join(MODEL_FILE)
    }

    /// `optimizer.bpk`.
    pub fn optimizer_path(&self) -> PathBuf {
        self.dir.join(OPTIMIZER_FILE)
    }
}

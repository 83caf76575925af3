//! What the ablation runs on and what it measured: the report tells these, the CLI prints them.

use std::path::PathBuf;

use anyhow::{bail, Result};
use matching::SgmParams;

use super::heldout::HeldOut;
use super::runs::RunResult;
use eval::{PairRecord, Table};
use stages::world_training::WorldTrainingSummary;

/// What the ablation runs on.
#[derive(Clone, Debug)]
pub struct AblationOptions {
    /// Folder of the report and everything it is made from.
    pub out_dir: PathBuf,
    /// World size, pixels (training, validation and held-out worlds).
    pub size: usize,
    /// Training worlds (real pairs of S1).
    pub train_worlds: usize,
    /// Validation worlds (the training curves' validation EPE).
    pub val_worlds: usize,
    /// Held-out test worlds.
    pub heldout_worlds: usize,
    /// Seed of the worlds, the initial weights and the data order.
    pub seed: u64,
    /// Optimiser steps of each run: the training budget, the same for S1 and S3.
    pub steps: usize,
    /// Validate every this many steps (and before the first).
    pub validate_every: usize,
    /// Validation pairs scored at each validation.
    pub valid_pairs: usize,
    /// The classical matcher: the training set's teacher and the table's baseline.
    pub sgm: SgmParams,
}

impl AblationOptions {
    /// The defaults `seasonstereo demo --ablation` uses: minutes on 2 cores, not hours
    /// (BENCHMARKS.md, "Whole commands").
    pub fn new(out_dir: impl Into<PathBuf>) -> Self {
        AblationOptions {
            out_dir: out_dir.into(),
            size: 256,
            train_worlds: 4,
            val_worlds: 1,
            heldout_worlds: 3,
            seed: 1,
            steps: 60,
            validate_every: 10,
            valid_pairs: 4,
            sgm: SgmParams::default(),
        }
    }

    /// Refuses settings that would leave the table or the curves empty.
    pub(super) fn check(&self) -> Result<()> {
        if self.steps == 0 || self.heldout_worlds == 0 || self.val_worlds == 0 {
            bail!(
                "the ablation needs at least one step, one validation world and one held-out world"
            );
        }
        if self.validate_every == 0 || self.valid_pairs == 0 {
            bail!("the training curves need validation: every N ≥ 1 steps, on ≥ 1 pairs");
        }
        Ok(())
    }
}

/// What the ablation measured.
#[derive(Clone, Debug)]
pub struct AblationSummary {
    pub dataset: WorldTrainingSummary,
    pub heldout: HeldOut,
    /// S1, then S3.
    pub runs: Vec<RunResult>,
    /// Rows: the classical matcher, S1, S3; columns: the held-out splits.
    pub table: Table,
    /// Every scored pair (all methods).
    pub records: Vec<PairRecord>,
    /// Row name of the classical matcher.
    pub classical: String,
    /// Wall-clock seconds per step.
    pub seconds: Vec<(String, f64)>,
    pub report: PathBuf,
}

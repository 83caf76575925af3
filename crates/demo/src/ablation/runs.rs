//! The two fine-tuning runs of the ablation: the `tiny` preset of the `train` crate on the world
//! training set, one run per data subset, from one saved initialisation and one seed, so the
//! training data is the only difference between them.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use dataset::manifest::KindCounts;
use dataset::subset::Subset;
use train::{Observer, StepRecord, TrainConfig, TrainOptions, ValidationRecord};

use workflow::progress::Progress;

/// What the runs share: everything but the subset.
#[derive(Clone, Debug)]
pub struct RunPlan {
    /// The dataset folder (`dataset world`'s layout).
    pub data_root: PathBuf,
    /// Folder of the runs: `<dir>/init.safetensors`, `<dir>/<subset>/`.
    pub dir: PathBuf,
    /// Optimiser steps of each run (the same budget for every subset).
    pub steps: usize,
    /// Validate every this many steps (and before the first).
    pub validate_every: usize,
    /// Validation pairs (the first of the validation list).
    pub valid_pairs: usize,
    /// Seed of the initial weights, the data order and the augmentation.
    pub seed: u64,
}

/// One finished run.
#[derive(Clone, Debug)]
pub struct RunResult {
    pub subset: Subset,
    /// Row name in the tables, e.g. `S1 (real only)`.
    pub name: String,
    /// Training samples of the subset by kind.
    pub samples: KindCounts,
    /// Every step (loss terms, learning rate, time).
    pub steps: Vec<StepRecord>,
    /// The validation passes, the first before any step.
    pub validations: Vec<ValidationRecord>,
    /// The final weights (safetensors).
    pub weights: PathBuf,
    /// The resolved configuration (`config.toml` of the run folder).
    pub config: TrainConfig,
    /// Wall-clock seconds of the run, validation included.
    pub seconds: f64,
}

/// Row name of a subset.
pub fn subset_name(subset: Subset) -> String {
    match subset {
        Subset::S1 => "S1 (real only)".into(),
        Subset::S2 => "S2 (+ synchronic synthetic)".into(),
        Subset::S3 => "S3 (+ synchronic and diachronic synthetic)".into(),
        Subset::All => "all combinations".into(),
    }
}

impl RunPlan {
    /// The shared initial weights.
    pub fn init_path(&self) -> PathBuf {
        self.dir.join("init.safetensors")
    }

    /// The run of `subset`: the `tiny` preset on this plan's data, budget, seed and weights.
    pub fn config(&self, subset: Subset) -> Result<TrainConfig> {
        let mut c = TrainConfig::load("tiny", &[]).context("the tiny training preset")?;
        c.name = format!("ablation-{}", subset.label().to_ascii_lowercase());
        c.model.init = Some(self.init_path());
        c.data.root = self.data_root.clone();
        c.data.experiment = Some(subset.csv_name().to_string());
        c.data.valid_limit = self.valid_pairs;
        c.run.steps = self.steps;
        c.run.seed = self.seed;
        c.run.validate_every = self.validate_every;
        c.run.validate_at_start = true;
        c.run.checkpoint_every = self.steps;
        c.run.keep_checkpoints = 1;
        c.run.output = self.dir.join(subset.label());
        c.validate()?;
        Ok(c)
    }

    /// Writes the initial weights once: the runs' network drawn from the plan's seed. Both runs
    /// load this file, so they start from the same weights by construction.
    pub fn write_init(&self) -> Result<()> {
        let mut config = self.config(Subset::S1)?;
        config.model.init = None;
        // The CPU device training uses by default ([`TrainOptions::device`]).
        let device = nn::device::DeviceChoice::Cpu
            .device()
            .map_err(anyhow::Error::msg)?
            .autodiff();
        let (model, _) = train::setup::build_model(&config, &device, None)?;
        let path = self.init_path();
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent)
                .with_context(|| format!("creating {}", parent.display()))?;
        }
        nn::weights::save_checkpoint(&model, &path)
            .with_context(|| format!("writing the initial weights {}", path.display()))
    }

    /// Trains `subset` (a fresh run: any earlier run folder of the subset is replaced).
    pub fn run(
        &self,
        subset: Subset,
        samples: KindCounts,
        progress: &dyn Progress,
    ) -> Result<RunResult> {
        let config = self.config(subset)?;
        let out = &config.run.output;
        if out.exists() {
            std::fs::remove_dir_all(out).with_context(|| format!("removing {}", out.display()))?;
        }
        let name = subset_name(subset);
        let mut curves = Curves {
            progress,
            label: format!("training {}", subset.label()),
            steps: Vec::new(),
            validations: Vec::new(),
        };
        let t0 = Instant::now();
        let summary = train::train(&config, &TrainOptions::default(), &mut curves)
            .with_context(|| format!("training {name}"))?;
        progress.end();
        Ok(RunResult {
            subset,
            name,
            samples,
            steps: curves.steps,
            validations: curves.validations,
            weights: final_weights(out, summary.steps_done, config.run.steps)?,
            config,
            seconds: t0.elapsed().as_secs_f64(),
        })
    }
}

fn final_weights(out: &Path, done: usize, total: usize) -> Result<PathBuf> {
    let path = out.join("final.safetensors");
    anyhow::ensure!(
        done == total && path.is_file(),
        "the run in {} stopped after {done} of {total} steps",
        out.display()
    );
    Ok(path)
}

/// Keeps every record for the curves and moves the progress bar one step per optimiser step.
struct Curves<'a> {
    progress: &'a dyn Progress,
    label: String,
    steps: Vec<StepRecord>,
    validations: Vec<ValidationRecord>,
}

impl Observer for Curves<'_> {
    fn started(&mut self, _start: usize, total: usize, _lines: &[String]) {
        self.progress.begin(&self.label, total);
    }

    fn step(&mut self, record: &StepRecord) {
        self.steps.push(*record);
        self.progress.advance(record.step);
    }

    fn validated(&mut self, record: &ValidationRecord) {
        self.validations.push(*record);
    }
}

//! `seasonstereo demo --ablation`: the paper's data ablation (Table 2) in miniature on procedural
//! worlds, through the real stages.
//!
//! 1. A training set from world pairs ([`build_world_training`]): SGM teacher, built-in seasons,
//!    the `masks` stage's offline segmenter, `dataset build` (subsets S1 and S3 included).
//! 2. Held-out test worlds (other seeds) in the benchmark's layout, synchronic and winter ↔ summer
//!    ([`heldout`]).
//! 3. The tiny MonSter++ fine-tuned on S1 (real pairs only) and on S3 (+ synchronic and
//!    diachronic synthetic pairs) with the same budget, initial weights and seed ([`runs`]).
//! 4. Both networks and the classical teacher scored on the held-out splits by `eval` (DSM
//!    altitude MAE after the benchmark's registration, coverage).
//! 5. `report.html`: training curves, the table, what it shows and what it does not.
//!
//! Every run starts afresh in its own subfolders of the output folder (`dataset/`, `heldout/`,
//! `runs/`, `eval/`), so a table never mixes runs.

mod heldout;
mod report;
mod runs;

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use dataset::subset::Subset;
use matching::SgmParams;

use crate::eval::{evaluate, EvalOptions, Method, PairRecord, Table};
use crate::matcher::{Matcher, MonsterOptions, Network};
use crate::progress::Progress;
use crate::world_training::{
    build_world_training, WorldMasks, WorldTrainingOptions, WorldTrainingSummary,
};
use nn::device::DeviceChoice;

pub use heldout::{HeldOut, CROSS_SEASON, HELDOUT_SEED_OFFSET, SYNCHRONIC};
pub use runs::{subset_name, RunPlan, RunResult};

/// The subsets the ablation compares, in the table's order.
pub const SUBSETS: [Subset; 2] = [Subset::S1, Subset::S3];

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
    /// The defaults `seasonstereo demo --ablation` uses: about 10 minutes on 2 cores.
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

    fn check(&self) -> Result<()> {
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

/// Runs the ablation and writes `out_dir/report.html`.
pub fn run_ablation(opts: &AblationOptions, progress: &dyn Progress) -> Result<AblationSummary> {
    opts.check()?;
    let out = &opts.out_dir;
    for sub in ["dataset", "heldout", "runs", "eval"] {
        let dir = out.join(sub);
        if dir.exists() {
            std::fs::remove_dir_all(&dir).with_context(|| format!("removing {}", dir.display()))?;
        }
    }
    let mut seconds = Vec::new();
    let mut clock = Instant::now();
    let mut lap = |name: &str, seconds: &mut Vec<(String, f64)>| {
        seconds.push((name.to_string(), clock.elapsed().as_secs_f64()));
        clock = Instant::now();
    };

    let mut w = WorldTrainingOptions::new(
        &out.join("dataset"),
        opts.size,
        opts.train_worlds,
        opts.val_worlds,
    );
    w.seed = opts.seed;
    w.sgm = opts.sgm.clone();
    w.masks = WorldMasks::Segmenter;
    let dataset = build_world_training(&w, progress).context("building the training set")?;
    lap(
        "training set (teacher, seasons, segmentation, dataset build)",
        &mut seconds,
    );

    let seeds: Vec<u64> = (0..opts.heldout_worlds as u64)
        .map(|k| opts.seed + HELDOUT_SEED_OFFSET + k)
        .collect();
    let heldout = heldout::write_heldout(&out.join("heldout"), opts.size, &seeds, progress)?;
    lap(
        "held-out worlds (synchronic, winter ↔ summer)",
        &mut seconds,
    );

    let plan = RunPlan {
        data_root: out.join("dataset"),
        dir: out.join("runs"),
        steps: opts.steps,
        validate_every: opts.validate_every,
        valid_pairs: opts.valid_pairs,
        seed: opts.seed,
    };
    plan.write_init()?;
    let mut runs = Vec::new();
    for subset in SUBSETS {
        let samples = dataset
            .train
            .build
            .subsets
            .iter()
            .find(|(label, _)| label == subset.label())
            .map(|(_, c)| c.clone())
            .with_context(|| format!("dataset build wrote no {} list", subset.label()))?;
        runs.push(plan.run(subset, samples, progress)?);
        lap(&format!("train {}", subset_name(subset)), &mut seconds);
    }

    let teacher = Matcher::Classical(opts.sgm.clone());
    let classical = format!("{} teacher", teacher.name());
    let mut methods = vec![(classical.clone(), Method::Matcher(teacher))];
    for run in &runs {
        let mut config = run.config.monster_config()?;
        config.iters = run.config.run.valid_iters;
        let predictor = nn::infer::MonsterPredictor::load(
            config,
            &run.weights,
            DeviceChoice::Cpu.device().map_err(anyhow::Error::msg)?,
        )
        .with_context(|| format!("loading {}", run.weights.display()))?;
        let mut options = MonsterOptions::new(&run.weights, "tiny");
        options.iters = Some(run.config.run.valid_iters);
        options.device = DeviceChoice::Cpu;
        let network = Network::new(options, predictor);
        methods.push((run.name.clone(), Method::Matcher(Matcher::Network(network))));
    }
    let mut report = None;
    for (name, method) in methods {
        let mut e = EvalOptions::new(
            heldout.splits.clone(),
            &heldout.rpc_dir,
            &heldout.truth_dir,
            method,
            out.join("eval"),
        );
        e.method_name = name;
        e.save_dsm = true;
        report = Some(evaluate(&e, progress)?);
    }
    let report_eval = report.expect("three methods were evaluated");
    let table = columns_with_data(report_eval.table);
    lap(
        "evaluate on the held-out worlds (benchmark protocol)",
        &mut seconds,
    );

    let summary = AblationSummary {
        dataset,
        heldout,
        runs,
        table,
        records: report_eval.records,
        classical,
        seconds,
        report: out.join("report.html"),
    };
    report::write_report(opts, &summary)?;
    Ok(summary)
}

/// The table without the benchmark's empty columns (its four test splits, always present).
fn columns_with_data(mut table: Table) -> Table {
    let keep: Vec<bool> = (0..table.columns.len())
        .map(|i| table.rows.iter().any(|r| r.splits[i].is_some()))
        .collect();
    let mut k = keep.iter();
    table
        .columns
        .retain(|_| *k.next().expect("one flag per column"));
    for row in &mut table.rows {
        let mut k = keep.iter();
        row.splits
            .retain(|_| *k.next().expect("one flag per column"));
    }
    table
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::records::PairRecord;

    fn scored(split: &str, method: &str, mae: f64) -> PairRecord {
        let mut r = PairRecord::unscored(split, "W1_A-W1_B", "W1", method, "scored");
        r.mae_filtered = Some(mae);
        r
    }

    #[test]
    fn the_table_keeps_the_held_out_columns_only() {
        let records = [
            scored(SYNCHRONIC, "a", 0.5),
            scored(CROSS_SEASON, "a", 0.75),
            scored(CROSS_SEASON, "b", 1.0),
        ];
        let full = crate::eval::aggregate(&records);
        assert_eq!(
            full.columns.len(),
            6,
            "the benchmark's four splits come first"
        );
        let t = columns_with_data(full);
        let titles: Vec<&str> = t.columns.iter().map(|c| c.title.as_str()).collect();
        assert_eq!(titles, [SYNCHRONIC, CROSS_SEASON]);
        let mean = |row: usize, col: usize| t.rows[row].splits[col].as_ref().map(|s| s.mean);
        assert_eq!((mean(0, 0), mean(0, 1)), (Some(0.5), Some(0.75)));
        assert_eq!((mean(1, 0), mean(1, 1)), (None, Some(1.0)));
    }
}

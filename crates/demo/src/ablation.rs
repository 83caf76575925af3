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
mod summary;

use std::path::Path;

use anyhow::{bail, Context, Result};
use dataset::subset::Subset;

use super::laps::Laps;
use eval::{evaluate, EvalOptions, EvalReport, Method, Table};
use nn::device::DeviceChoice;
use stages::world_training::{
    build_world_training, WorldMasks, WorldTrainingOptions, WorldTrainingSummary,
};
use workflow::matcher::{Matcher, MonsterOptions, Network};
use workflow::progress::Progress;

pub use heldout::{HeldOut, CROSS_SEASON, HELDOUT_SEED_OFFSET, SYNCHRONIC};
pub use runs::{subset_name, RunPlan, RunResult};
pub use summary::{AblationOptions, AblationSummary};

/// The subsets the ablation compares, in the table's order.
pub const SUBSETS: [Subset; 2] = [Subset::S1, Subset::S3];

/// Runs the ablation and writes `out_dir/report.html`.
pub fn run_ablation(opts: &AblationOptions, progress: &dyn Progress) -> Result<AblationSummary> {
    opts.check()?;
    let out = &opts.out_dir;
    clear_previous_run(out)?;
    let mut laps = Laps::start();
    let dataset = build_training_set(opts, progress)?;
    laps.lap("training set (teacher, seasons, segmentation, dataset build)");
    let seeds: Vec<u64> = (0..opts.heldout_worlds as u64)
        .map(|k| opts.seed + HELDOUT_SEED_OFFSET + k)
        .collect();
    let heldout = heldout::write_heldout(&out.join("heldout"), opts.size, &seeds, progress)?;
    laps.lap("held-out worlds (synchronic, winter ↔ summer)");
    let runs = train_subsets(opts, &dataset, &mut laps, progress)?;
    let (classical, methods) = methods_compared(opts, &runs)?;
    let evaluated = evaluate_methods(out, &heldout, methods, progress)?;
    let table = columns_with_data(evaluated.table);
    laps.lap("evaluate on the held-out worlds (benchmark protocol)");
    let summary = AblationSummary {
        dataset,
        heldout,
        runs,
        table,
        records: evaluated.records,
        classical,
        seconds: laps.seconds,
        report: out.join("report.html"),
    };
    report::write_report(opts, &summary)?;
    Ok(summary)
}

/// Removes the subfolders of an earlier run, so that a table never mixes runs.
fn clear_previous_run(out: &Path) -> Result<()> {
    for sub in ["dataset", "heldout", "runs", "eval"] {
        let dir = out.join(sub);
        if dir.exists() {
            std::fs::remove_dir_all(&dir).with_context(|| format!("removing {}", dir.display()))?;
        }
    }
    Ok(())
}

/// The training set from world pairs, through the real stages with the offline segmenter's
/// masks.
fn build_training_set(
    opts: &AblationOptions,
    progress: &dyn Progress,
) -> Result<WorldTrainingSummary> {
    let mut w = WorldTrainingOptions::new(
        &opts.out_dir.join("dataset"),
        opts.size,
        opts.train_worlds,
        opts.val_worlds,
    );
    w.seed = opts.seed;
    w.sgm = opts.sgm.clone();
    w.masks = WorldMasks::Segmenter;
    build_world_training(&w, progress).context("building the training set")
}

/// Fine-tunes the tiny MonSter++ on each of [`SUBSETS`] from the same initial weights, with the
/// same budget and seed.
fn train_subsets(
    opts: &AblationOptions,
    dataset: &WorldTrainingSummary,
    laps: &mut Laps,
    progress: &dyn Progress,
) -> Result<Vec<RunResult>> {
    let out = &opts.out_dir;
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
        laps.lap(&format!("train {}", subset_name(subset)));
    }
    Ok(runs)
}

/// The table's rows: the classical teacher (its row name is returned too), then each trained
/// network.
fn methods_compared(
    opts: &AblationOptions,
    runs: &[RunResult],
) -> Result<(String, Vec<(String, Method)>)> {
    let teacher = Matcher::Classical(opts.sgm.clone());
    let classical = format!("{} teacher", teacher.name());
    let mut methods = vec![(classical.clone(), Method::Matcher(teacher))];
    for run in runs {
        methods.push((run.name.clone(), Method::Matcher(trained_network(run)?)));
    }
    Ok((classical, methods))
}

/// The network a run trained, on the CPU with the run's validation iterations.
fn trained_network(run: &RunResult) -> Result<Matcher> {
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
    Ok(Matcher::Network(Network::new(options, predictor)))
}

/// Scores every method on the held-out splits with `eval`, into one folder: the last report
/// holds every method's rows.
fn evaluate_methods(
    out: &Path,
    heldout: &HeldOut,
    methods: Vec<(String, Method)>,
    progress: &dyn Progress,
) -> Result<EvalReport> {
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
        let r = evaluate(&e, progress)?;
        if let Some((pair, cause)) = r.failed.first() {
            bail!("evaluating the held-out pair {pair}: {cause}");
        }
        report = Some(r);
    }
    Ok(report.expect("three methods were evaluated"))
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
    use eval::records::PairRecord;

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
        let full = eval::aggregate(&records);
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

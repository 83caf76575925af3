//! The demo's many-dates step: the world on six dates ([`eval::world_dates`]), the pairs chosen
//! from the cameras' dates and angles, their fused DSM, and the best-scored pair alone through
//! `reconstruct`, all scored against the exact truth.

use std::path::PathBuf;

use anyhow::{Context, Result};

use eval::metrics::DsmScores;
use eval::world_dates::{write_dated_stack, ACQUISITIONS};
use reconstruct::dsm::GridChoice;
use reconstruct::many::{reconstruct_many, ReconstructManyOptions};
use reconstruct::{reconstruct, ReconstructOptions};
use workflow::matcher::Matcher;
use workflow::progress::Progress;

use super::options::DemoOptions;

/// Side of the six-date world, pixels: at most the demo's, at most 384 (six renders and six
/// pairs stay within seconds).
pub const MANY_DATES_SIZE: usize = 384;

/// Pairs fused: the six best of the fifteen.
const PAIRS: usize = 6;

/// One chosen pair as the report lists it.
#[derive(Clone, Debug)]
pub struct ChosenPair {
    pub stem: String,
    pub days: Option<f64>,
    pub convergence_deg: f64,
    pub score: f64,
    /// The pair's own (unfilled) DSM against the truth.
    pub scores: Option<DsmScores>,
}

/// What the many-dates step measured.
#[derive(Clone, Debug)]
pub struct ManyDatesResult {
    pub size: usize,
    pub chosen: Vec<ChosenPair>,
    pub fused: DsmScores,
    /// The best-scored pair through `reconstruct` with its defaults.
    pub best_pair: (String, DsmScores),
    /// The stack, the fused DSM and the single pair's DSM.
    pub folder: PathBuf,
}

/// Renders the stack under `OUT/dates`, fuses the best pairs and reconstructs the best one alone.
pub fn run_many_dates(
    opts: &DemoOptions,
    matcher: &Matcher,
    progress: &dyn Progress,
) -> Result<ManyDatesResult> {
    let size = opts.size.min(MANY_DATES_SIZE);
    let folder = opts.out_dir.join("dates");
    let name = format!("WORLD_{}", opts.seed);
    let stack = write_dated_stack(size, opts.seed, &name, &ACQUISITIONS, &folder, progress)?;
    let grid = GridChoice::Like(stack.truth.clone());
    let mut many = ReconstructManyOptions::new(
        stack.images.clone(),
        Some(stack.rpc_dir.clone()),
        matcher.clone(),
        grid.clone(),
        folder.join("fused.tif"),
    );
    many.pairs = PAIRS;
    many.truth = Some(stack.truth.clone());
    many.overwrite = true;
    let summary = reconstruct_many(&many, progress).context("fusing the six-date world")?;
    let fused = summary
        .scores
        .clone()
        .context("the fused DSM of the six-date world has no score")?;
    let chosen: Vec<ChosenPair> = summary
        .chosen
        .iter()
        .zip(&summary.pairs)
        .map(|(c, p)| ChosenPair {
            stem: c.stem.clone(),
            days: c.terms.days,
            convergence_deg: c.terms.convergence_deg,
            score: c.terms.score,
            scores: p.scores.clone(),
        })
        .collect();

    let best = &summary.chosen[0];
    let (left, right) = (&summary.views[best.left], &summary.views[best.right]);
    let mut single = ReconstructOptions::new(
        left.image.clone(),
        right.image.clone(),
        matcher.clone(),
        grid,
        folder.join("best_pair.tif"),
    );
    single.rpc_left = left.rpc_file.clone();
    single.rpc_right = right.rpc_file.clone();
    single.truth = Some(stack.truth);
    let alone = reconstruct(&single, progress).context("the best pair of the six-date world")?;
    let best_scores = alone
        .scores
        .context("the best pair of the six-date world has no score")?;
    Ok(ManyDatesResult {
        size,
        chosen,
        fused,
        best_pair: (best.stem.clone(), best_scores),
        folder,
    })
}

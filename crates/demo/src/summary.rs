//! What the demo measured: the CLI prints these and the report tells them.

use std::path::PathBuf;

use eval::metrics::DsmScores;
use workflow::metrics::DisparityScores;

/// Altitude scores of one DSM: the benchmark's numbers and the MAE per ground-truth class.
#[derive(Clone, Debug)]
pub struct DsmResult {
    pub scores: DsmScores,
    /// (DFC class name, MAE in metres after the all-cells registration, cells) per class of the
    /// truth's `_CLS.tif`.
    pub by_class: Vec<(String, Option<f64>, usize)>,
    /// The DSM (float32 GeoTIFF on the truth's grid).
    pub path: PathBuf,
}

/// One pair the demo matched.
#[derive(Clone, Debug)]
pub struct PairResult {
    /// "synchronic" or "winter ↔ summer".
    pub name: String,
    /// Disparity scores over the pixels visible in both views.
    pub visible: DisparityScores,
    /// Disparity scores per class of the left view (visible pixels).
    pub by_class: Vec<(String, DisparityScores)>,
    pub dsm: DsmResult,
    /// The predicted disparity (NPY float32).
    pub disparity: PathBuf,
}

/// What the demo measured.
#[derive(Clone, Debug)]
pub struct DemoSummary {
    /// Synchronic pair: scores over the pixels visible in both views.
    pub visible: DisparityScores,
    /// Synchronic pair: scores per class of the left view (visible pixels).
    pub by_class: Vec<(String, DisparityScores)>,
    /// The synchronic pair, then the winter ↔ summer pair.
    pub pairs: Vec<PairResult>,
    /// Disparity range searched (from the cameras).
    pub range: (i32, i32),
    /// The six-date world: chosen pairs, fused DSM, the best pair alone.
    pub many_dates: super::ManyDatesResult,
    /// Wall-clock seconds per step.
    pub seconds: Vec<(String, f64)>,
    pub report: PathBuf,
}

//! Run logs: one CSV row per step (`metrics.csv`) and per validation (`validation.csv`), the
//! same scalars as TensorBoard events ([`crate::events`]), and the validation scores.
//!
//! The logs are appended to (one line per event, flushed), not rewritten: at 50,000 steps a
//! rewrite per step would cost quadratic time. On resume the rows past the resumed step (written
//! after the checkpoint by the interrupted run) are dropped (the file is rewritten atomically
//! once) so the log reads as one uninterrupted run.

use std::fs::{File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};

use dataset::scores::count_errors;

use crate::events::EventWriter;
use crate::loss::LossTerms;
use crate::TrainError;

/// Header of `metrics.csv`.
pub const METRICS_HEADER: &str =
    "step,lr,total,disp,photo,smooth,epe,within_1px,within_3px,grad_norm,clip_factor,seconds,its_per_s";
/// Header of `validation.csv`.
pub const VALIDATION_HEADER: &str =
    "step,epe,bad_1px,bad_3px,pairs,epe_synchronic,epe_diachronic,seconds";

/// One finished optimiser step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepRecord {
    /// Steps done after this one (1-based).
    pub step: usize,
    /// Total steps of the run.
    pub total_steps: usize,
    /// Base learning rate of this step (`feat_decoder` used `lr × feat_decoder_lr_factor`).
    pub lr: f64,
    /// The loss terms (λ- and sequence-weighted, summed as the release logs them).
    pub terms: LossTerms,
    /// Global gradient norm before clipping (`NaN` when the step was skipped).
    pub grad_norm: f64,
    /// Factor applied by the clipping (1 = not clipped).
    pub clip_factor: f64,
    /// True when the gradients were not finite and the update was skipped.
    pub skipped: bool,
    /// Wall time of this step, seconds.
    pub seconds: f64,
    /// Steps per second averaged over this session.
    pub its_per_s: f64,
}

/// One validation pass.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ValidationRecord {
    /// Steps done when it ran.
    pub step: usize,
    pub scores: ValidationScores,
    pub seconds: f64,
}

/// An append-only CSV log with a fixed header.
pub struct CsvLog {
    path: PathBuf,
    file: File,
}

impl CsvLog {
    /// Opens `path` for appending. With `resume_step = Some(s)` the rows whose first column is
    /// greater than `s` are removed first; without it the file is started afresh.
    pub fn open(path: &Path, header: &str, resume_step: Option<usize>) -> Result<Self, TrainError> {
        let keep: Vec<String> = match (resume_step, std::fs::read_to_string(path)) {
            (Some(s), Ok(text)) => text
                .lines()
                .skip(1)
                .filter(|l| {
                    l.split(',')
                        .next()
                        .and_then(|v| v.parse::<usize>().ok())
                        .is_some_and(|step| step <= s)
                })
                .map(str::to_string)
                .collect(),
            _ => Vec::new(),
        };
        raster::formats::write_atomically(path, |f| {
            writeln!(f, "{header}")?;
            for l in &keep {
                writeln!(f, "{l}")?;
            }
            Ok(())
        })
        .map_err(|e| TrainError::Io(e.to_string()))?;
        let file = OpenOptions::new()
            .append(true)
            .open(path)
            .map_err(|e| TrainError::io(path, e))?;
        Ok(Self {
            path: path.to_path_buf(),
            file,
        })
    }

    /// Appends one row (values joined by commas) and flushes it.
    pub fn row(&mut self, values: &[String]) -> Result<(), TrainError> {
        writeln!(self.file, "{}", values.join(","))
            .and_then(|_| self.file.flush())
            .map_err(|e| TrainError::io(&self.path, e))
    }
}

/// The logs of a run folder: `metrics.csv`, `validation.csv` and a TensorBoard event file.
pub struct RunLogs {
    metrics: CsvLog,
    validation: CsvLog,
    events: EventWriter,
}

impl RunLogs {
    /// Opens the logs in `dir`; `resumed_at` as in [`CsvLog::open`].
    pub fn open(dir: &Path, resumed_at: Option<usize>) -> Result<Self, TrainError> {
        Ok(Self {
            metrics: CsvLog::open(&dir.join("metrics.csv"), METRICS_HEADER, resumed_at)?,
            validation: CsvLog::open(&dir.join("validation.csv"), VALIDATION_HEADER, resumed_at)?,
            events: EventWriter::create(dir, resumed_at)?,
        })
    }

    /// Logs one optimiser step.
    pub fn step(&mut self, r: &StepRecord) -> Result<(), TrainError> {
        let t = &r.terms;
        self.metrics.row(&[
            r.step.to_string(),
            format!("{:e}", r.lr),
            t.total.to_string(),
            t.disp.to_string(),
            t.photo.to_string(),
            t.smooth.to_string(),
            t.epe.to_string(),
            t.within_1px.to_string(),
            t.within_3px.to_string(),
            r.grad_norm.to_string(),
            r.clip_factor.to_string(),
            format!("{:.4}", r.seconds),
            format!("{:.4}", r.its_per_s),
        ])?;
        self.events.scalars(
            r.step,
            &[
                ("loss/total", t.total.into()),
                ("loss/disp", t.disp.into()),
                ("loss/photo", t.photo.into()),
                ("loss/smooth", t.smooth.into()),
                ("train/epe", t.epe.into()),
                ("train/within_1px", t.within_1px.into()),
                ("train/within_3px", t.within_3px.into()),
                ("train/lr", r.lr),
                ("train/grad_norm", r.grad_norm),
                ("train/its_per_s", r.its_per_s),
            ],
        )
    }

    /// Logs a validation pass (nothing when no pair could be scored).
    pub fn validation(&mut self, r: &Option<ValidationRecord>) -> Result<(), TrainError> {
        let Some(r) = r else { return Ok(()) };
        let s = &r.scores;
        let opt = |v: Option<f64>| v.map_or(String::new(), |v| v.to_string());
        self.validation.row(&[
            r.step.to_string(),
            s.epe.to_string(),
            s.bad_1px.to_string(),
            s.bad_3px.to_string(),
            s.pairs.to_string(),
            opt(s.epe_synchronic),
            opt(s.epe_diachronic),
            format!("{:.3}", r.seconds),
        ])?;
        let mut scalars = vec![
            ("validation/epe", s.epe),
            ("validation/bad_1px", s.bad_1px),
            ("validation/bad_3px", s.bad_3px),
        ];
        scalars.extend(s.epe_synchronic.map(|v| ("validation/epe_synchronic", v)));
        scalars.extend(s.epe_diachronic.map(|v| ("validation/epe_diachronic", v)));
        self.events.scalars(r.step, &scalars)
    }
}

/// Disparity scores of a validation pass: mean end-point error and the fractions of pixels off
/// by more than 1 and 3 px, averaged per pair as the release does.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ValidationScores {
    pub epe: f64,
    pub bad_1px: f64,
    pub bad_3px: f64,
    /// Pairs scored (pairs whose mask is empty are skipped, as the release does).
    pub pairs: usize,
    pub epe_synchronic: Option<f64>,
    pub epe_diachronic: Option<f64>,
}

/// Per-pair accumulator of [`ValidationScores`].
#[derive(Debug, Clone, Default)]
pub struct ValidationAccumulator {
    sums: [f64; 3],
    pairs: usize,
    by_kind: [(f64, usize); 2],
}

/// One pair's (EPE, bad-1, bad-3) over `valid`, or `None` when no pixel is valid.
pub fn pair_scores(prediction: &[f32], truth: &[f32], valid: &[bool]) -> Option<[f64; 3]> {
    let c = count_errors(
        prediction
            .iter()
            .zip(truth)
            .zip(valid)
            .filter(|(_, &v)| v)
            .map(|((&p, &t), _)| (p, t)),
    );
    // A non-finite prediction counts as bad at every threshold; the EPE averages the finite
    // ones (it would otherwise be NaN).
    let n = c.evaluated as f64;
    let bad = |k: usize| (c.over[k] + c.unmatched()) as f64 / n;
    (c.evaluated > 0).then(|| [c.mae().unwrap_or(f64::NAN), bad(0), bad(2)])
}

impl ValidationAccumulator {
    /// Adds one pair's scores.
    pub fn add(&mut self, scores: [f64; 3], diachronic: bool) {
        for (s, v) in self.sums.iter_mut().zip(scores) {
            *s += v;
        }
        self.pairs += 1;
        let k = &mut self.by_kind[diachronic as usize];
        k.0 += scores[0];
        k.1 += 1;
    }

    /// The averages (`None` when no pair could be scored).
    pub fn finish(&self) -> Option<ValidationScores> {
        if self.pairs == 0 {
            return None;
        }
        let n = self.pairs as f64;
        let kind = |(s, c): (f64, usize)| (c > 0).then(|| s / c as f64);
        Some(ValidationScores {
            epe: self.sums[0] / n,
            bad_1px: self.sums[1] / n,
            bad_3px: self.sums[2] / n,
            pairs: self.pairs,
            epe_synchronic: kind(self.by_kind[0]),
            epe_diachronic: kind(self.by_kind[1]),
        })
    }
}

/// Peak resident memory of this process in bytes (Linux `VmHWM`; `None` elsewhere).
pub fn peak_rss_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

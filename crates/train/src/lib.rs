//! Fine-tuning MonSter++ with the SeasonStereo loss (paper Sec. 3.3 and 4.1, SPEC `train`).
//!
//! ```text
//! let config = TrainConfig::load("d-full", &["run.steps=1000".into()])?;   // preset or TOML file
//! let summary = train(&config, &TrainOptions::default(), &mut Quiet)?;
//! ```
//!
//! - [`config`]: one TOML per run with every hyper-parameter, shipped presets (`tiny`, `a-lidar`,
//!   `b-disp`, `c-photo`, `d-full`, `s1`–`s3`), `key=value` overrides;
//! - [`setup`]: MonSter++ from a preset, initial weights (`.pth` / safetensors, Depth Anything V2),
//!   mono branch frozen and 2-D BatchNorm on running statistics, on the autodiff device;
//! - [`loss`], [`mask`]: the SeasonStereo sequence loss and its validity masks;
//! - [`optim`]: AdamW with the `feat_decoder` group at half the rate, global gradient clipping,
//!   state save/restore; [`schedule`]: PyTorch's `OneCycleLR` (linear);
//! - [`data`]: deterministic batches from `(seed, step)`; [`trainer`]: the loop, validation,
//!   checkpoints ([`checkpoint`]), exact resume, Ctrl-C; [`metrics`]: CSV logs and scores.

pub mod bench;
pub mod checkpoint;
pub mod config;
pub mod data;
pub mod events;
pub mod loss;
pub mod mask;
pub mod metrics;
pub mod optim;
pub mod schedule;
pub mod setup;
pub mod trainer;

pub use config::TrainConfig;
pub use trainer::{
    train, Observer, Quiet, StepRecord, TrainOptions, TrainSummary, ValidationRecord,
};

use std::path::Path;

/// Errors of a training run; each names the file, key or sample at fault and the fix.
#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    #[error("{0}")]
    Config(String),
    #[error("{0}")]
    Data(String),
    #[error("{0}")]
    Weights(String),
    #[error("{0}")]
    Loss(String),
    #[error("{0}")]
    Checkpoint(String),
    #[error("{0}")]
    Io(String),
}

impl TrainError {
    /// An I/O error on `path`.
    pub fn io(path: &Path, e: std::io::Error) -> Self {
        TrainError::Io(format!("{}: {e}", path.display()))
    }
}

impl From<dataset::DatasetError> for TrainError {
    fn from(e: dataset::DatasetError) -> Self {
        TrainError::Data(e.to_string())
    }
}

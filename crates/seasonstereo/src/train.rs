//! Fine-tuning MonSter++ with the SeasonStereo loss (`seasonstereo train`; feature `network`):
//! a configuration from a preset or a TOML file, the run with its observer, an exact resume.

pub use ::train::config::PRESETS;
pub use ::train::trainer::{interrupt_flag, resume_config};
pub use ::train::{
    train, Observer, StepRecord, TrainConfig, TrainOptions, TrainSummary, ValidationRecord,
};

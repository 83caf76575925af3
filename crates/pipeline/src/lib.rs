//! Stages over pairs and datasets, between the libraries and the command line: predicting a
//! disparity for a pair, scoring it against ground truth, writing the procedural world in the public
//! release's folder layout, the end-to-end demo and its HTML report.
//!
//! Every stage reports progress through [`Progress`] so the CLI can draw bars while tests stay quiet.
//!
//! Shared by the stages: [`stage`] (the item loop with resume and `--shard`, atomic records,
//! folder claims), [`pairs`] (the rectified-pair folder), [`matcher`] (which matcher, and where a
//! pair's disparity range comes from). The learned networks sit behind the default feature
//! `network`; without it everything else builds and tests without burn.

pub mod demo;
pub mod dsm;
pub mod eval;
pub mod finished;
pub mod flags;
pub mod jobs;
pub mod matcher;
pub mod metrics;
pub mod outputs;
pub mod pairs;
pub mod predict;
pub mod progress;
pub mod provenance;
pub mod reconstruct;
pub mod rectify;
pub mod report;
pub mod score;
pub mod stage;
pub mod stages;
pub mod world_dates;
pub mod world_io;

pub use progress::{Progress, Silent};

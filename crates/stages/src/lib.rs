//! The dataset stages of SeasonStereo's training set, in the order they run (paper Sec. 3):
//! [`teacher`] labels every real synchronic pair, [`curate`] keeps the consistent ones,
//! [`synthesize`] makes their seasonal variants, [`masks`] segments every image once, and
//! [`dataset_build`] assembles the season combinations the trainer reads. [`world_training`]
//! runs the same stages on procedural worlds.
//!
//! Every stage is an options struct and a `run_*` function over items, on the shared stage loop
//! ([`workflow::stage`]: resume, `--shard`, atomic records) and the pair folder ([`workflow::pairs`]).

pub mod curate;
pub mod dataset_build;
pub mod masks;
pub mod synthesize;
pub mod teacher;
pub mod world_training;

//! The stages that build SeasonStereo's training set from real pairs, in the order they run
//! (paper Sec. 3): [`teacher`] labels every real synchronic pair, [`curate`] keeps the consistent
//! ones, [`synthesize`] makes their seasonal variants, [`masks`] segments every image once, and
//! [`dataset_build`] assembles the season combinations the trainer reads; [`world_training`]
//! runs the same stages on procedural worlds.
//!
//! Every stage works item by item: it skips the items a previous run finished, runs only its
//! share with a [`dataset::Shard`], writes its records atomically, and reports what it did.

use crate::{Progress, Result};

pub use workflow::stage::BatchSummary;
pub use stages::curate::{CurateOptions, CurateSummary};
pub use stages::dataset_build::{BuildOptions, BuildSummary, MaskDirs};
pub use stages::masks::MasksOptions;
pub use stages::synthesize::{SynthesizeOptions, SynthesizeSummary};
pub use stages::teacher::TeacherOptions;
pub use stages::world_training::{WorldTrainingOptions, WorldTrainingSummary};
pub use synth::SeasonGenerator;

/// Teacher disparities (SGM, or MonSter++ with weights) for every real synchronic pair of
/// `options.pairs_dir`: they supervise every synthetic combination of that pair.
pub fn teacher(options: &TeacherOptions, progress: &dyn Progress) -> Result<BatchSummary> {
    stages::teacher::run_teacher(options, progress)
}

/// Scores the consistency of the synchronic pairs (colour, SSIM, image features) and selects the
/// intersection of the two top-K rankings.
pub fn curate(options: &CurateOptions, progress: &dyn Progress) -> Result<CurateSummary> {
    stages::curate::run_curate(options, progress)
}

/// Seasonal variants of every image of the selected pairs by `generator`, each checked for
/// geometric fidelity and rectified with its pair's homography.
pub fn synthesize(
    options: &SynthesizeOptions,
    generator: &dyn SeasonGenerator,
    progress: &dyn Progress,
) -> Result<SynthesizeSummary> {
    stages::synthesize::run_synthesize(options, generator, progress)
}

/// Water, tree and building masks from one segmentation per image.
pub fn masks(options: &MasksOptions, progress: &dyn Progress) -> Result<BatchSummary> {
    stages::masks::run_masks(options, progress)
}

/// The training set in the layout the trainer reads: the season combinations of every pair,
/// their masks, the subsets S1/S2/S3 and the manifest.
pub fn dataset_build(options: &BuildOptions, progress: &dyn Progress) -> Result<BuildSummary> {
    stages::dataset_build::run_build(options, progress)
}

/// A small training set from procedural worlds, built by the same stages as real data.
pub fn world_training(
    options: &WorldTrainingOptions,
    progress: &dyn Progress,
) -> Result<WorldTrainingSummary> {
    stages::world_training::build_world_training(options, progress)
}

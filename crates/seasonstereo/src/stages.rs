//! The stages that build SeasonStereo's training set from real pairs, in the order they run
//! (paper Sec. 3): [`teacher`] labels every real synchronic pair, [`curate`] keeps the consistent
//! ones, [`synthesize`] makes their seasonal variants, [`masks`] segments every image once, and
//! [`dataset_build`] assembles the season combinations the trainer reads; [`world_training`]
//! runs the same stages on procedural worlds.
//!
//! Every stage works item by item: it skips the items a previous run finished, runs only its
//! share with a [`dataset::Shard`], writes its records atomically, and reports what it did.

use std::path::{Path, PathBuf};

use crate::{Progress, Result};

pub use dataset::Subset;
#[cfg(feature = "network")]
pub use stages::curate::features::Dinov3Similarity;
pub use stages::curate::features::{FeatureSimilarity, HistogramDescriptor};
pub use stages::curate::select::Keep;
pub use stages::curate::{ColourStatistic, SsimScale};
pub use stages::curate::{CurateOptions, CurateSummary};
pub use stages::dataset_build::{BuildOptions, BuildSummary, MaskDirs};
pub use stages::masks::heights::PairIndex;
pub use stages::masks::score::{FolderScore, ImageScore};
pub use stages::masks::MasksOptions;
#[cfg(feature = "network")]
pub use stages::masks::SegformerSegmenter;
pub use stages::masks::{ImageSegmenter, MasksRecord, OfflineSegmenter, RulesSegmenter};
pub use stages::synthesize::{SynthesizeOptions, SynthesizeSummary};
pub use stages::teacher::TeacherOptions;
pub use stages::world_training::{WorldTrainingOptions, WorldTrainingSummary};
pub use synth::api::{GeminiConfig, GeminiGenerator};
pub use synth::prompts::Prompts;
pub use synth::{BuiltinSeasons, Season, SeasonGenerator};
pub use workflow::stage::BatchSummary;

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

/// Scores the masks of `masks` (a [`masks`] output) against the DFC2019 classes beside the
/// truth DSM `truth` (or `classes`), projected into each image through the truth and the
/// image's camera `<rpc_dir>/<stem>.json`, the truth first registered by the median shift of
/// the `register` DSMs (none: no shift).
pub fn masks_score(
    masks: &Path,
    rpc_dir: &Path,
    truth: &Path,
    classes: Option<&Path>,
    register: &[PathBuf],
) -> Result<FolderScore> {
    stages::masks::score::score_folder(masks, rpc_dir, truth, classes, register)
}

/// The markdown table of [`masks_score`]'s scores: one row per image, the mean over images and
/// the pooled pixels, IoU / precision / recall per class.
pub fn masks_table(scores: &[ImageScore]) -> String {
    stages::masks::score::table(scores)
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

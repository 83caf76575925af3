//! What the demo runs on.

use std::path::PathBuf;

use matching::SgmParams;

/// What the demo runs on.
#[derive(Clone, Debug)]
pub struct DemoOptions {
    /// Image size of the world, pixels.
    pub size: usize,
    /// Seed of the world and of the built-in seasonal model.
    pub seed: u64,
    /// Folder of the report and its images.
    pub out_dir: PathBuf,
    pub sgm: SgmParams,
}

//! SeasonStereo's story on a procedural world as an HTML report (`seasonstereo demo`), and the
//! data ablation in miniature (`demo --ablation`, with the feature `network`), with the number
//! formats their reports use.

#[cfg(feature = "network")]
pub use ::demo::ablation::{run_ablation, AblationOptions, AblationSummary};
pub use ::demo::{metres, percent, pixels, run_demo, DemoOptions, DemoSummary, ManyDatesResult};

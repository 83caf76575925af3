//! Training sets on disk: the public release's training layout (read and write), experiment lists,
//! subsets S1/S2/S3, manifests and shards.
//!
//! # Layout
//!
//! The layout is the release's (`data/diachronic-stereo-synthetic/` of the SeasonStereo code), so a
//! set built here trains the released Python code and the other way round:
//!
//! ```text
//! <dataset>/
//!   train/                              one split (TrainLayout::root)
//!     L/<stem>.npy  R/<stem>.npy        rectified images, NPY float32 (H, W, C), 0–255, 0 outside
//!                                       the rectified footprint
//!     homography/<pair>.npz             Hleft, Hright: raw (cropped) image → rectified
//!     masks/{L,R}/<pair>.npy            1 = inside the rectified footprint (uint8)
//!     water_masks/{L,R}/<pair>.npy      KEEP masks: 1 = not water (and inside the footprint)
//!     tree_masks/{L,R}/<pair>.npy       KEEP masks: 1 = not tree
//!     building_masks/{L,R}/<pair>.npy   1 = building
//!     png/…                             optional previews of the above
//!   val/                                the same, plus disparity/<pair>.iio (ground truth)
//!   disparity_maps/<teacher>/<pair>.iio teacher disparity of every REAL pair (`monster++`, `sgm`)
//!   disparity_maps/GT/<pair>.iio        LiDAR-derived (or exact) disparity, optional
//!   experiments/<name>.csv              `filename[,diachronic]` lists: sub1_synchronic (S1),
//!                                       sub2_synchronic (S2), sub5_syndiach (S3),
//!                                       sub3_diachronic (all 25 combinations), sub_val
//!   train_aois.csv, val_aois.csv        one AOI per line (optional filters)
//!   manifest.json                       counts, generator, teacher, segmenter
//! ```
//!
//! `<stem>` = `<LEFTID>[__<tag>]-<RIGHTID>[__<tag>]`: no tag is the real image, a tag
//! (`summer`, `autumn`, `winter`, `spring`) a synthetic seasonal variant of it. `<pair>` is the
//! BASE pair `<LEFTID>-<RIGHTID>` (tags removed): masks, homographies and disparities are shared
//! by the 25 combinations of a pair, and the REAL pair `L/<pair>.npy`, `R/<pair>.npy` is the
//! photometric reference of every combination. The AOI of a stem is the first 7 characters of its
//! left image id (`JAX_004`), as the release does.

pub mod augment;
pub mod error;
pub mod experiment;
pub mod layout;
pub mod manifest;
pub mod masks;
pub mod rng;
pub mod sample;
pub mod scores;
pub mod segmentation;
pub mod shard;
pub mod stem;
pub mod subset;

pub use error::DatasetError;
pub use layout::{DatasetDir, Side, TrainLayout};
pub use sample::{load_sample, Sample, SampleIndex};
pub use shard::Shard;
pub use stem::{ImageRef, PairKind, PairStem};
pub use subset::Subset;

/// Result type of this crate.
pub type Result<T, E = DatasetError> = std::result::Result<T, E>;

//! Classical dense stereo matching: census transform + Semi-Global Matching (Hirschmüller 2008).
//!
//! # Why this crate exists
//!
//! It is the product's classical baseline and the offline teacher of the learned matchers: a
//! fast, deterministic, dependency-light matcher that gives a dense disparity map for any
//! rectified pair, whatever the radiometry of the two dates (census costs are invariant to any
//! monotonic change of the grey levels, so uint16 satellite images, 0–255 RGB and `[0, 1]`
//! floats all work without normalisation).
//!
//! # Conventions
//!
//! * The pair is rectified: epipolar lines are image rows.
//! * The disparity lives on the **left** view: a left pixel `(x, y)` matches the right pixel
//!   `(x − d, y)`. Positive `d` typically grows with altitude, but a range `[d_min, d_max]` may
//!   include negative values (swap the roles of the images and you get `−d`).
//! * Ranges are **inclusive** on both ends: `[d_min, d_max]` holds `d_max − d_min + 1`
//!   disparities.
//! * Invalid disparities (occluded, inconsistent left/right, ambiguous, NaN input) are NaN.
//!
//! # Memory
//!
//! The matcher keeps the whole cost volume in memory: **3 bytes per pixel per disparity**
//! (a `u8` census cost plus a `u16` aggregated cost), plus about 32 bytes per pixel (grey
//! images, census codes) and two sweep line buffers of `3 · width · (n_disp + 2)` `u16`; each
//! rayon thread only adds a few disparity vectors. A 1024² pair with 128 disparities needs
//! ≈ 0.42 GB; [`memory_bytes`] gives the figure, and [`SgmParams::max_memory`] turns an
//! oversized request into an error instead of an allocation failure. Larger scenes must be
//! tiled by the caller.
//!
//! # Pipeline
//!
//! 1. [`census`]: census transform of the grey images (default 9×7 window → 62 bits).
//! 2. `cost`: Hamming distances, `u8` volume `C[y][x][d − d_min]` (disparity innermost).
//! 3. `mgm` (default) or `aggregate`: More Global Matching over 8 directions, or 8 (or 4) path
//!    SGM, with penalties `P1`, `P2` (optionally adapted to the image gradient), vectorised
//!    over disparities.
//! 4. `select`: winner-take-all, sub-pixel fit, left–right check, uniqueness, 3×3 median.
//! 5. [`speckle`]: small connected regions of disparity are removed.
//! 6. [`estimate_range`]: coarse-to-fine range estimation when the caller has none.

mod aggregate;
pub mod census;
mod cost;
mod error;
mod mgm;
pub mod parallax;
mod range;
mod select;
mod sgm;
pub mod speckle;
pub mod tie;

pub use census::CensusWindow;
pub use error::MatchError;
pub use parallax::{vertical_parallax, Parallax};
pub use range::estimate_range;
pub use sgm::{
    disparity_count, match_pair, match_pair_with_confidence, match_pair_with_progress,
    memory_bytes, Aggregation, DisparityRange, Paths, SgmParams,
};
pub use speckle::{remove_speckles, Speckle};

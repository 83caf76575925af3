//! What every stage of seasonstereo shares, below the crates that do the work: the item loop
//! with resume and `--shard` and its atomic records ([`stage`]), the rectified-pair folder
//! ([`pairs`]), the matcher choice and a pair's disparity range ([`matcher`], [`predict`]),
//! the outputs' guards (an output never replaces an input; [`outputs`]), progress reports
//! ([`progress`]), shell words ([`shell`]), the finishing line of a long run ([`finished`]), and the pieces of the HTML
//! reports ([`report`], [`metrics`]).
//!
//! The learned matcher (MonSter++) sits behind the default feature `network` (burn); without
//! it everything here builds without burn.

pub mod finished;
pub mod matcher;
pub mod metrics;
pub mod outputs;
pub mod pairs;
pub mod predict;
pub mod progress;
pub mod report;
pub mod shell;
pub mod stage;

pub use progress::{Progress, Silent};

//! The helpers of the cluster jobs' front end beside the submissions of the crate's top level
//! ([`crate::submit_slurm_reconstruct`], [`crate::submit_slurm_chain`], ...): which kind of
//! submission a work folder holds, where its scripts and logs are, array specs and shell words.

pub use ::jobs::is_chain;
pub use ::jobs::record::jobs_dir;
pub use ::jobs::script::{quote, split};
pub use ::jobs::status::array_spec;

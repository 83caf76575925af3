//! Cluster jobs: a reconstruction submitted as a Slurm array of tile tasks plus a merge task,
//! its state read back from the work folder, and its failed tiles resubmitted.
//!
//! The work folder is the only shared state: every tile leaves `tiles/<id>.json` whatever the
//! scheduler says, so what is done, failed or missing is read from the folder ([`status`]), not
//! from the scheduler's accounting. A submission writes `jobs/` into the work folder: the two job
//! scripts (every argument shell-quoted, no `--wrap`), their logs, and `jobs/slurm.json`, the
//! record [`resubmit`] reads.
//!
//! What this module does not do: it never runs a tile itself (the scripts call the
//! `seasonstereo` binary, which calls [`crate::reconstruct`]), and it never decides what a tile
//! is ([`crate::reconstruct::plan`] does).

pub mod record;
pub mod script;
pub mod slurm;
pub mod status;

pub use slurm::{resubmit, submit_reconstruct, Resources, SlurmRequest, Submitted};
pub use status::{status, JobStatus};

//! Cluster jobs: a reconstruction submitted as a Slurm array of tile tasks plus a merge task, or
//! a chain of sharded stages (the training-set build) as one array per stage with a check step
//! between them; their state read back from the work folder, and what failed resubmitted.
//!
//! The work folder is the only shared state: every tile leaves `tiles/<id>.json` whatever the
//! scheduler says, so what is done, failed or missing is read from the folder ([`status`]), not
//! from the scheduler's accounting. A submission writes `jobs/` into the work folder: the two job
//! scripts (every argument shell-quoted, no `--wrap`), their logs, and `jobs/slurm.json`, the
//! record [`resubmit`] reads. A chain's tasks each leave a shard marker (their exit code) in
//! `jobs/shards/<stage>/`, which [`chain_status`] and the check steps read; its record is
//! `jobs/chain.json`. Both kinds share the script writer ([`script`]), `sbatch` ([`sbatch`]) and
//! the unit states ([`status::Units`]).
//!
//! What this module does not do: it never runs a tile itself (the scripts call the
//! `seasonstereo` binary, which calls [`reconstruct`]), and it never decides what a tile
//! is ([`reconstruct::plan`] does).

pub mod chain;
pub mod chain_record;
pub mod record;
pub mod sbatch;
pub mod script;
pub mod slurm;
pub mod status;

pub use chain::{resubmit_chain, submit_chain, ChainRequest, ChainSubmitted, StageLine};
pub use chain_record::{chain_status, is_chain, ChainStatus, StageStatus};

pub use slurm::{resubmit, submit_reconstruct, Resources, SlurmRequest, Submitted};
pub use status::{status, JobStatus, Units};

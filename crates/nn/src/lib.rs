//! Neural networks on burn for seasonstereo: the MonSter++ stereo network (accuracy model), its
//! weight import from PyTorch/safetensors checkpoints, and inference.
//!
//! The default backend is burn's pure-Rust CPU backend `flex`; GPU backends are opt-in features
//! (`wgpu`, `cuda`). Layout of the network: `../shared/design/monsterpp.md`.
//!
//! Status: under construction (issue 4) — the modules below are being ported and checked for
//! numerical parity against the upstream fixtures one by one.

pub mod config;
pub mod monster;
pub mod weights;

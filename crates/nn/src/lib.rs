//! Neural networks on burn for seasonstereo: the MonSter++ stereo network (accuracy model), its
//! weight import from PyTorch/safetensors checkpoints, and inference; and the two networks of the
//! dataset stages, [`dinov3`] (DINOv3 ViT features for the curation similarity score) and
//! [`segformer`] (SegFormer OpenEarthMap segmentation for the water, tree and building masks),
//! each with the exact pre- and post-processing of the release and parity tests against the
//! upstream fixtures.
//!
//! The default backend is burn's pure-Rust CPU backend `flex`; GPU backends are opt-in features
//! (`wgpu`, `cuda`). Layout of the network: `../shared/design/monsterpp.md`.
//!
//! # The model
//!
//! [`monster::Monster`] is the whole upstream `Monster` (MonSter / MonSter++ accuracy model,
//! identical architectures): build it from a [`config::MonsterConfig`] preset (`vitl` for the
//! released `*_large.pth` / `mix_all.pth` checkpoints, also `vitb`, `vits`, and `tiny` for the
//! parity fixture), load a whole checkpoint with one [`weights::load_weights`] (upstream `.pth`
//! with or without `model`/`state_dict` wrappers and `module.` prefixes, or safetensors; the
//! report names every missing or mis-shaped key), then call
//! [`forward`](monster::Monster::forward)`(left, right, iters, test_mode)` on B×3×H×W RGB 0–255
//! images with H, W multiples of 32 (pad first; see [`infer`]). `test_mode = true` returns the
//! final disparity (and `depth_mono`); `false` also returns every intermediate prediction in
//! upstream order and `init_disp_up` for the training loss. [`weights::save_checkpoint`] writes
//! safetensors in PyTorch naming that load back (and into upstream PyTorch) unchanged.
//!
//! End-to-end parity with upstream PyTorch (tiny fixture, 64×128, 8 iterations, f32 on `flex`):
//! max abs error of the output disparity 2.7e-5 px, of all 15 train-mode predictions 6.1e-5 px
//! (`tests/model.rs`; the per-part checks are in `tests/parity_*.rs`). Parameter counts match
//! upstream exactly (vitl: 388.69 M, 53.38 M trainable; vitb 129.39 / 31.92 M; vits 47.79 / 23.00 M).
//!
//! # Training
//!
//! Upstream freezes the mono branch (`mono_encoder` = DINOv2 and `mono_decoder` = DPT depth head)
//! and trains everything else (`feat_decoder` at half the learning rate), with
//! `model.train(); model.freeze_bn()`: BatchNorm2d layers use running statistics while the
//! BatchNorm3d of the cost aggregation keep training.
//! [`monster::Monster::freeze_for_training`] does both (call it on a model built on the autodiff
//! device, `Device::flex().autodiff()`); [`monster::upsample::freeze_bn`] is the per-subtree
//! helper. [`monster::Monster::num_trainable_params`] counts what remains trainable.

pub mod activation;
pub mod attention;
pub mod batch_norm;
pub mod bench;
pub mod config;
pub mod conv;
mod cpu_mode;
mod custom_op;
pub mod device;
pub mod dinov3;
pub mod fastmath;
mod flex_tensor;
pub mod gate;
pub mod grid_sample;
pub mod infer;
pub mod interp;
mod matmul;
pub mod monster;
pub mod photometric;
pub mod pool;
pub mod profile;
pub mod resize;
pub mod segformer;
pub mod weights;

#[cfg(test)]
mod test_support;

//! DINOv3 ViT image features and the curation similarity score.
//!
//! Port of Hugging Face `DINOv3ViTModel` (transformers 4.57) and of the SeasonStereo
//! `compute_metrics.py --similarity_metric dinov3` score (design note
//! `../shared/design/segformer-dinov3.md`, Part B). Upstream default model:
//! `facebook/dinov3-vitl16-pretrain-sat493m` = [`Dinov3Config::vitl16`].
//!
//! # Use
//!
//! [`Dinov3Features::from_file`]`(path, config, device)` loads an HF checkpoint
//! (`model.safetensors`, or a `.pth` state dict; F16/BF16 upcast to f32) strictly: a missing,
//! mis-shaped or unexpected key is an error whose report uses the HF names. Then
//! [`Dinov3Features::similarity`]`(left, left_hat, valid)` gives the score of a pair and
//! [`Dinov3Features::features`] the `pooler_output` of one image. The warp that produces
//! `left_hat` and `valid` is `raster::geometry::warp_by_disparity_grid_sample` (the reference's
//! `grid_sample` semantics); the final mask is its validity ∧ finite(warp disparity) ∧
//! finite(ground truth).
//!
//! # What is reproduced
//!
//! - Score: pixels outside the mask → 0 in both images, uint8 **truncation**
//!   ([`preprocess::mask_to_u8`]), processor = `x · f32(1/255)`, torch antialiased bilinear
//!   resize to 224×224 (square; [`raster::resize::resize_antialias_bilinear`]), `(x − mean)/std`
//!   in f32 with mean/std a setting ([`Normalization`], default ImageNet — the **open point** of
//!   the design note: confirm against the real `preprocessor_config.json` of the SAT model),
//!   batch [left, left_hat], `pooler_output` = CLS after the final LayerNorm, torch
//!   `F.cosine_similarity` with eps 1e-8 ([`cosine_similarity`]).
//! - Network ([`model`]): patch conv 16×16 (remainder dropped), tokens [CLS, 4 registers,
//!   patches] with no absolute position embedding, 2-D RoPE on the patch tokens only
//!   ([`rope`]), pre-norm layers with separate q/k/v projections (no key bias), layer scale,
//!   GELU (erf) MLP, final LayerNorm (eps 1e-5).
//!
//! # Parity with the reference
//!
//! `../shared/fixtures/dinov3-tiny` (HF transformers 4.57.6 / torch 2.4.1, CPU f32, eager
//! attention, random F16-rounded weights, hidden 128, 4 layers, head_dim 64), checked by
//! `tests/parity_dinov3.rs`; max abs differences measured on the `flex` backend:
//!
//! | tensor | max abs diff | asserted |
//! |---|---|---|
//! | `warp.left_hat` (`warp_by_disparity_grid_sample`) | 0 (bit-exact) | exact |
//! | `warp.valid`, `warp.final_mask`, `pre.left_u8`, `pre.left_hat_u8` | exact | exact |
//! | `pre.resized` (antialiased resize) | 0 (bit-exact) | exact (raster tests) |
//! | `input.pixel_values` from the images, `pre224.pixel_values` | 0 (bit-exact) | 1e-6 |
//! | `inter.embeddings` | 0 | 1e-5 |
//! | `inter.rope_cos`, `inter.rope_sin` | 6.0e-8 (1 ulp) | 1e-6 |
//! | `inter.layer0.{norm1, q_proj, attn, mlp, out}` | 9.5e-7, 1.4e-6, 7.7e-7, 2.5e-6, 2.0e-6 | 1e-5 |
//! | `inter.layer{1,2,3}.out` | 1.7e-6, 2.4e-6, 2.9e-6 | 5e-5 |
//! | `output.last_hidden_state`, `output.pooler_output` | 2.1e-6, 1.8e-6 | 1e-4 |
//! | `output224.last_hidden_state`, `output224.pooler_output` (201 tokens) | 2.1e-6, 1.2e-6 | 1e-4 |
//! | `output.cosine_similarity` (from `pixel_values`, and end to end from `input.left/right/gt_disp`) | 6.0e-8 | 1e-6 |
//!
//! Upstream runs on CUDA by default (TF32 patch conv, SDPA attention: ~1e-6 away from the CPU
//! eager reference on this fixture), so real upstream scores can differ from this port by more
//! than the table shows; 1e-5 on the score is the realistic expectation (design note B.5).
//!
//! Speed (random weights, `cargo run --release -p nn --example dinov3_forward`): BENCHMARKS.md,
//! "DINOv3 and SegFormer"; ViT-L/16, the upstream default, is much slower than ViT-S/16.
//!
//! Not ported: the `--dinov3_repo_path` mode (original facebookresearch checkpoints, no resize
//! and no normalisation) and gated-MLP models (ViT-7B/H+).

pub mod config;
pub mod features;
pub mod load;
pub mod model;
pub mod preprocess;
pub mod rope;

pub use config::{Dinov3Config, Dinov3ConfigError};
pub use features::{cosine_similarity, Dinov3Error, Dinov3Features};
pub use load::{hf_keys, load_dinov3};
pub use model::Dinov3Vit;
pub use preprocess::{mask_to_u8, Dinov3Preprocess, Normalization};
pub use rope::Rope;

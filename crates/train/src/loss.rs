//! The SeasonStereo training loss (paper Sec. 3.3, eqs. 3–7; SPEC `train`), as the public release
//! computes it (`losses/self_supervised.py`, `self_supervised_sequence_loss`).
//!
//! Per prediction `D̂` (eq. 4): `λ_disp·L_disp + λ_photo·L_photo + λ_smooth·L_smooth` with
//! - `L_disp`: penalty of `D̂ − target` over the supervision mask `V` (teacher disparity of the
//!   REAL synchronic pair; LiDAR in configuration (a));
//! - `L_photo`: `α(1−SSIM)/2 + (1−α)|·|` between the REAL left image and the REAL right image
//!   warped by `D̂`, over `V` ∧ warp-in-bounds ∧ z-buffer-visible ∧ `V_B`;
//! - `L_smooth`: edge-aware first-order smoothness of `D̂ / mean(D̂)` weighted by the INPUT left
//!   image's gradients.
//!
//! Over the sequence (eq. 3): `init_weight·L(init_disp_up) + Σ_k γ'^(N−k) L(disp_preds[k])`,
//! `γ' = γ^(15/(N−1))`, `N = disp_preds.len()`.
//!
//! Where the release departs from the paper's text the release is the default and a
//! [`LossConfig`] switch gives the paper's variant: smooth-L1 (not L1) disparity penalty, 11×11
//! (not 3×3) SSIM window, `L_smooth` unmasked, z-buffer only in `L_photo`.
//!
//! Use: build a [`LossBatch`] from the step's samples ([`BatchItem`]s, images in `[0, 1]`), run
//! the model in train mode, then `sequence_loss(&config, &batch, init_disp_up, &disp_preds)` and
//! call `.backward()` on `output.total`; `output.terms` holds the values to log.

mod batch;
mod config;
mod sequence;
pub mod terms;

pub use batch::{BatchItem, LossBatch};
pub use config::{DisparityPenalty, Experiment, LossConfig, SupervisionTarget};
pub use sequence::{
    prediction_loss, sequence_loss, sequence_weights, LossOutput, LossTerms, PredictionLoss,
};

/// Errors of the loss: a bad configuration or inputs that do not fit together.
#[derive(Debug, thiserror::Error)]
pub enum LossError {
    #[error("invalid loss configuration: {0}")]
    Config(String),
    #[error("{0}")]
    Input(String),
}

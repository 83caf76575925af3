//! [`LossConfig`]: every weight and switch of the SeasonStereo loss, with the paper's and the
//! release's values as defaults and presets for the configurations (a)–(d) of Table 1.

use serde::{Deserialize, Serialize};

use super::LossError;

/// Which disparity supervises `L_disp`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SupervisionTarget {
    /// The frozen teacher's disparity of the REAL synchronic pair (configurations (b)–(d)).
    Teacher,
    /// The LiDAR-derived disparity (configuration (a)); pixels without LiDAR are unsupervised.
    Lidar,
}

/// The per-pixel penalty of `L_disp`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum DisparityPenalty {
    /// Huber / `F.smooth_l1_loss(beta)`: what the release trains with (`pseudo_gt_loss`,
    /// beta = 1): quadratic below `beta` pixels, `|e| − beta/2` above.
    SmoothL1 { beta: f32 },
    /// Plain `|e|`: the paper's eq. 5.
    L1,
}

/// Every weight and switch of the loss (paper eqs. 3–7). `Default` is configuration (d), the
/// paper's final model, with the release's implementation choices; see the field docs for where
/// the release departs from the paper's text.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LossConfig {
    /// λ_disp (paper 0.05).
    pub lambda_disp: f32,
    /// λ_photo (paper 0.1; 0 turns the term off).
    pub lambda_photo: f32,
    /// λ_smooth (paper 0.1; 0 turns the term off).
    pub lambda_smooth: f32,
    /// γ of the sequence loss; the per-prediction weight is `γ^(15/(N−1))^(N−k)` (0.9).
    pub gamma: f32,
    /// Weight of the upstream initial-disparity term (`init_disp_up`), which gets the same
    /// multi-term loss as every iteration (release: 1.0).
    pub init_weight: f32,
    /// Teacher or LiDAR supervision.
    pub target: SupervisionTarget,
    /// Penalty of `L_disp` (release: smooth L1 with beta 1; paper text: L1).
    pub disparity_penalty: DisparityPenalty,
    /// Targets with `|d| ≥ max_disp` are unsupervised (release: 576).
    pub max_disp: f32,
    /// Frame removed from every mask on each side (release: 32 px).
    pub ignore_border: usize,
    /// α of the photometric error `α(1−SSIM)/2 + (1−α)|·|` (0.85).
    pub ssim_alpha: f32,
    /// Side of the SSIM box window (release: 11, zero-padded average pooling that counts the
    /// padding; Monodepth, which the paper cites, uses 3).
    pub ssim_window: usize,
    /// Restrict `L_photo` to the building mask `V_B` (paper and release: true).
    pub photometric_on_buildings_only: bool,
    /// Divide the disparity by its per-image mean before the smoothness gradients (release: true;
    /// makes `L_smooth` scale-free).
    pub smooth_normalise_by_mean: bool,
    /// Average `L_smooth` over the supervision mask `V` (paper eq. 7) instead of over every pixel
    /// (release: false).
    pub smooth_over_valid: bool,
    /// Also remove z-buffer-occluded pixels from `L_disp` and `L_smooth` (paper text: V excludes
    /// occluded pixels for every term). The release applies the z-buffer to `L_photo` only
    /// (false).
    pub occlusion_in_all_terms: bool,
}

impl Default for LossConfig {
    fn default() -> Self {
        Self::full()
    }
}

/// The paper's Table 1 configurations.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Experiment {
    /// (a) L_disp against LiDAR-derived disparities.
    A,
    /// (b) L_disp against the teacher.
    B,
    /// (c) L_disp + L_photo (buildings).
    C,
    /// (d) L_disp + L_photo (buildings) + L_smooth: the final model.
    D,
}

impl LossConfig {
    /// Configuration (d) (release `exp4-pseudoGT_0.05-photo_0.1_buildings-smooth_0.1.yaml`).
    pub fn full() -> Self {
        Self {
            lambda_disp: 0.05,
            lambda_photo: 0.1,
            lambda_smooth: 0.1,
            gamma: 0.9,
            init_weight: 1.0,
            target: SupervisionTarget::Teacher,
            disparity_penalty: DisparityPenalty::SmoothL1 { beta: 1.0 },
            max_disp: 576.0,
            ignore_border: 32,
            ssim_alpha: 0.85,
            ssim_window: 11,
            photometric_on_buildings_only: true,
            smooth_normalise_by_mean: true,
            smooth_over_valid: false,
            occlusion_in_all_terms: false,
        }
    }

    /// The loss of one of the paper's configurations (release `exp1`–`exp4` yaml files).
    pub fn preset(experiment: Experiment) -> Self {
        let full = Self::full();
        match experiment {
            Experiment::A => Self {
                target: SupervisionTarget::Lidar,
                lambda_photo: 0.0,
                lambda_smooth: 0.0,
                ..full
            },
            Experiment::B => Self {
                lambda_photo: 0.0,
                lambda_smooth: 0.0,
                ..full
            },
            Experiment::C => Self {
                lambda_smooth: 0.0,
                ..full
            },
            Experiment::D => full,
        }
    }

    /// Checks every value; the error names the field and the fix.
    pub fn validate(&self) -> Result<(), LossError> {
        let bad = |field: &str, why: String| Err(LossError::Config(format!("loss.{field}: {why}")));
        for (field, v) in [
            ("lambda_disp", self.lambda_disp),
            ("lambda_photo", self.lambda_photo),
            ("lambda_smooth", self.lambda_smooth),
            ("init_weight", self.init_weight),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return bad(field, format!("must be a finite number ≥ 0, got {v}"));
            }
        }
        if self.lambda_disp + self.lambda_photo + self.lambda_smooth == 0.0 {
            return bad(
                "lambda_*",
                "every term is switched off; set at least one λ > 0".into(),
            );
        }
        if !(self.gamma > 0.0 && self.gamma <= 1.0) {
            return bad("gamma", format!("must be in (0, 1], got {}", self.gamma));
        }
        if !(self.max_disp.is_finite() && self.max_disp > 0.0) {
            return bad("max_disp", format!("must be > 0, got {}", self.max_disp));
        }
        if !(0.0..=1.0).contains(&self.ssim_alpha) {
            return bad(
                "ssim_alpha",
                format!("must be in [0, 1], got {}", self.ssim_alpha),
            );
        }
        if self.ssim_window.is_multiple_of(2) {
            return bad(
                "ssim_window",
                format!("must be odd and ≥ 1 (release 11), got {}", self.ssim_window),
            );
        }
        if let DisparityPenalty::SmoothL1 { beta } = self.disparity_penalty {
            if !(beta > 0.0 && beta.is_finite()) {
                return bad("disparity_penalty.beta", format!("must be > 0, got {beta}"));
            }
        }
        Ok(())
    }

    /// Whether the photometric term (and so the z-buffer on every prediction) is computed.
    pub fn uses_photometric(&self) -> bool {
        self.lambda_photo > 0.0
    }
}

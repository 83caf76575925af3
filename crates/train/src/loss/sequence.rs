//! The per-prediction multi-term loss (paper eq. 4) and the sequence loss over MonSter++'s
//! predictions (eq. 3), as the release's `self_supervised_sequence_loss` combines them.

use burn::tensor::{Bool, Device, Tensor, TensorData};
use serde::{Deserialize, Serialize};

use super::batch::{bool_tensor, LossBatch};
use super::config::LossConfig;
use super::terms::{disparity_error_map, masked_mean, photometric_error_map, smoothness_term};
use super::LossError;
use crate::mask::{photometric_mask, zbuffer_visible};

/// Weights `w(k) = γ'^(N−k)`, `k = 1..=N`, `γ' = γ^(15/(N−1))`, of the `N` iterative predictions
/// (release: `loss_gamma ** (15 / (n − 1))` raised to `n − i − 1` for `i = 0..n`), computed in f64
/// like the release's Python floats. The last prediction weighs 1 and the first `γ^15` whatever
/// `N`; `N = 1` gives `[1]` (Python's `0.0 ** 0`).
pub fn sequence_weights(n: usize, gamma: f32) -> Vec<f32> {
    if n == 1 {
        return vec![1.0];
    }
    let adjusted = (gamma as f64).powf(15.0 / (n as f64 - 1.0));
    (0..n)
        .map(|i| adjusted.powi((n - i - 1) as i32) as f32)
        .collect()
}

/// The weighted terms of one prediction: `λ_disp·L_disp`, `λ_photo·L_photo`, `λ_smooth·L_smooth`
/// and their sum (`L^(k)` of eq. 4). A switched-off term is an exact 0.
#[derive(Clone, Debug)]
pub struct PredictionLoss {
    pub total: Tensor<1>,
    pub disp: Tensor<1>,
    pub photo: Tensor<1>,
    pub smooth: Tensor<1>,
}

/// `L^(k)` of one prediction `[B, 1, H, W]`.
///
/// Masks (release semantics, see [`crate::mask`]): `L_disp` over `V` minus non-finite predictions;
/// `L_photo` over `V` ∧ warp in bounds ∧ z-buffer-visible ∧ `V_B` (the z-buffer on the detached
/// prediction); `L_smooth` over every pixel (or `V`, see [`LossConfig::smooth_over_valid`]).
/// Non-finite predictions are zeroed (with zero gradient) before any term, so one bad pixel
/// cannot turn the whole loss into NaN.
pub fn prediction_loss(
    config: &LossConfig,
    batch: &LossBatch,
    prediction: Tensor<4>,
) -> Result<PredictionLoss, LossError> {
    let [b, h, w] = batch.dims();
    if prediction.dims() != [b, 1, h, w] {
        return Err(LossError::Input(format!(
            "prediction_loss: prediction is {:?}, the batch is [{b}, 1, {h}, {w}]",
            prediction.dims()
        )));
    }
    let device = prediction.device();
    let finite = prediction.clone().is_finite();
    let prediction = prediction.mask_fill(finite.clone().bool_not(), 0.0);

    // CPU copies of the detached prediction, only where the z-buffer needs it.
    let needs_zbuffer = config.uses_photometric() || config.occlusion_in_all_terms;
    let values: Vec<f32> = if needs_zbuffer {
        prediction_values(&prediction)?
    } else {
        Vec::new()
    };
    let visible = if config.occlusion_in_all_terms {
        Some(visibility(&values, [b, h, w], &device)?)
    } else {
        None
    };
    let zero = || Tensor::<1>::zeros([1], &device);

    let mut disp_keep = batch.supervision_t.clone().bool_and(finite);
    if let Some(v) = &visible {
        disp_keep = disp_keep.bool_and(v.clone());
    }
    let disp = if config.lambda_disp > 0.0 {
        disparity_term(config, batch, &prediction, &disp_keep)
    } else {
        zero()
    };
    let photo = if config.uses_photometric() {
        photometric_term(config, batch, &prediction, &values)?
    } else {
        zero()
    };
    let smooth = if config.lambda_smooth > 0.0 {
        smooth_term(config, batch, &prediction, &disp_keep, visible.as_ref())
    } else {
        zero()
    };

    Ok(PredictionLoss {
        total: disp.clone() + photo.clone() + smooth.clone(),
        disp,
        photo,
        smooth,
    })
}

/// Z-buffer visibility of each prediction of the batch (`values`, `[B, H, W]` row-major): what
/// `occlusion_in_all_terms` removes from every term.
fn visibility(
    values: &[f32],
    [b, h, w]: [usize; 3],
    device: &Device,
) -> Result<Tensor<4, Bool>, LossError> {
    let mut all = Vec::with_capacity(b * h * w);
    for chunk in values.chunks_exact(h * w) {
        all.extend(zbuffer_visible(chunk, w).map_err(mask_error)?);
    }
    Ok(bool_tensor(&all, [b, 1, h, w], device))
}

/// `λ_disp·L_disp`: the disparity penalty against the target, averaged over `keep`.
fn disparity_term(
    config: &LossConfig,
    batch: &LossBatch,
    prediction: &Tensor<4>,
    keep: &Tensor<4, Bool>,
) -> Tensor<1> {
    let map = disparity_error_map(
        prediction.clone(),
        batch.target.clone(),
        config.disparity_penalty,
    );
    masked_mean(map, keep.clone()).mul_scalar(config.lambda_disp)
}

/// `λ_photo·L_photo`: the SSIM/L1 error of the warped real right view, averaged over each
/// sample's photometric mask (built on the detached prediction `values`).
fn photometric_term(
    config: &LossConfig,
    batch: &LossBatch,
    prediction: &Tensor<4>,
    values: &[f32],
) -> Result<Tensor<1>, LossError> {
    let [b, h, w] = batch.dims();
    let mut keep = Vec::with_capacity(b * h * w);
    let sup = batch.supervision();
    let building = batch.building();
    for i in 0..b {
        let range = i * h * w..(i + 1) * h * w;
        let building = config
            .photometric_on_buildings_only
            .then(|| &building[range.clone()]);
        keep.extend(
            photometric_mask(&sup[range.clone()], &values[range], w, building)
                .map_err(mask_error)?,
        );
    }
    let map = photometric_error_map(
        batch.real_left.clone(),
        batch.real_right.clone(),
        prediction.clone(),
        config.ssim_alpha,
        config.ssim_window,
    );
    let keep = bool_tensor(&keep, [b, 1, h, w], &prediction.device());
    Ok(masked_mean(map, keep).mul_scalar(config.lambda_photo))
}

/// `λ_smooth·L_smooth`: edge-aware smoothness over every pixel pair, or only the pairs inside
/// the disparity mask (`smooth_over_valid`) or the z-buffer visibility.
fn smooth_term(
    config: &LossConfig,
    batch: &LossBatch,
    prediction: &Tensor<4>,
    disp_keep: &Tensor<4, Bool>,
    visible: Option<&Tensor<4, Bool>>,
) -> Tensor<1> {
    let keep = (config.smooth_over_valid || visible.is_some()).then(|| {
        let k = if config.smooth_over_valid {
            disp_keep.clone()
        } else {
            visible.expect("checked").clone()
        };
        pair_masks(k, batch.dims())
    });
    smoothness_term(
        prediction.clone(),
        batch.input_left.clone(),
        config.smooth_normalise_by_mean,
        keep,
    )
    .mul_scalar(config.lambda_smooth)
}

/// Pixel pairs `(x, x+1)` and `(y, y+1)` that both pass `keep`.
fn pair_masks(keep: Tensor<4, Bool>, [b, h, w]: [usize; 3]) -> (Tensor<4, Bool>, Tensor<4, Bool>) {
    let kx = keep
        .clone()
        .slice([0..b, 0..1, 0..h, 0..w.saturating_sub(1)])
        .bool_and(keep.clone().slice([0..b, 0..1, 0..h, 1.min(w)..w]));
    let ky = keep
        .clone()
        .slice([0..b, 0..1, 0..h.saturating_sub(1), 0..w])
        .bool_and(keep.slice([0..b, 0..1, 1.min(h)..h, 0..w]));
    (kx, ky)
}

fn prediction_values(prediction: &Tensor<4>) -> Result<Vec<f32>, LossError> {
    prediction
        .clone()
        .detach()
        .into_data()
        .convert::<f32>()
        .try_into_vec::<f32>()
        .map_err(|e| {
            LossError::Input(format!(
                "prediction_loss: cannot read the prediction: {e:?}"
            ))
        })
}

fn mask_error(e: crate::mask::MaskError) -> LossError {
    LossError::Input(e.to_string())
}

/// Values of one step for logging, weighted as the release logs them: each term summed over the
/// initial prediction (weight `init_weight`) and the sequence (weights [`sequence_weights`]),
/// λ included, so `disp + photo + smooth == total`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LossTerms {
    pub total: f32,
    pub disp: f32,
    pub photo: f32,
    pub smooth: f32,
    /// Mean |last prediction − target| over `V` (px).
    pub epe: f32,
    /// Fractions of `V` with error below 1, 3 and 5 px.
    pub within_1px: f32,
    pub within_3px: f32,
    pub within_5px: f32,
    /// |V| / (B·H·W).
    pub valid_fraction: f32,
    /// |V_B| / (B·H·W).
    pub building_fraction: f32,
    /// Non-finite pixels in the last prediction (0 in a healthy run).
    pub non_finite_pixels: u32,
}

/// The differentiable total and the logged values.
#[derive(Clone, Debug)]
pub struct LossOutput {
    /// `init_weight·L(init) + Σ_k w(k)·L(k)`: call `.backward()` on it.
    pub total: Tensor<1>,
    pub terms: LossTerms,
}

/// The sequence loss of one training step (paper eq. 3 with the upstream initial term):
/// `L = init_weight·L(init_disp_up) + Σ_{k=1..N} γ'^(N−k) L(disp_preds[k−1])`, every `L(·)` the
/// multi-term loss of [`prediction_loss`]. `init_disp_up` and `disp_preds` are
/// `nn::monster::MonsterOutput`'s train-mode outputs (`N = iters + 7` predictions for MonSter++).
pub fn sequence_loss(
    config: &LossConfig,
    batch: &LossBatch,
    init_disp_up: Tensor<4>,
    disp_preds: &[Tensor<4>],
) -> Result<LossOutput, LossError> {
    config.validate()?;
    let last = disp_preds.last().ok_or_else(|| {
        LossError::Input("sequence_loss: no predictions (run the model in train mode)".into())
    })?;
    let weights = sequence_weights(disp_preds.len(), config.gamma);

    let init = prediction_loss(config, batch, init_disp_up)?;
    let scale = |t: Tensor<1>, wgt: f32| t.mul_scalar(wgt);
    let mut total = scale(init.total, config.init_weight);
    let mut disp = scale(init.disp.detach(), config.init_weight);
    let mut photo = scale(init.photo.detach(), config.init_weight);
    let mut smooth = scale(init.smooth.detach(), config.init_weight);
    for (prediction, &wgt) in disp_preds.iter().zip(&weights) {
        let l = prediction_loss(config, batch, prediction.clone())?;
        total = total + scale(l.total, wgt);
        disp = disp + scale(l.disp.detach(), wgt);
        photo = photo + scale(l.photo.detach(), wgt);
        smooth = smooth + scale(l.smooth.detach(), wgt);
    }

    // Metrics of the last prediction over V (release: train/epe, 1px, 3px, 5px).
    let last = last.clone().detach();
    let finite = last.clone().is_finite();
    let non_finite = finite.clone().bool_not().int().sum();
    let keep = batch.supervision_t.clone().bool_and(finite.clone());
    let error = (last.mask_fill(finite.bool_not(), 0.0) - batch.target.clone()).abs();
    let within = |t: f32| masked_mean(error.clone().lower_elem(t).float(), keep.clone());
    let scalars = Tensor::cat(
        vec![
            total.clone().detach(),
            disp,
            photo,
            smooth,
            masked_mean(error.clone(), keep.clone()),
            within(1.0),
            within(3.0),
            within(5.0),
            non_finite.float(),
        ],
        0,
    );
    let v = read_scalars(scalars)?;
    let [b, h, w] = batch.dims();
    let n = (b * h * w).max(1) as f32;
    let count = |m: &[bool]| m.iter().filter(|&&x| x).count() as f32 / n;
    Ok(LossOutput {
        total,
        terms: LossTerms {
            total: v[0],
            disp: v[1],
            photo: v[2],
            smooth: v[3],
            epe: v[4],
            within_1px: v[5],
            within_3px: v[6],
            within_5px: v[7],
            valid_fraction: count(batch.supervision()),
            building_fraction: count(batch.building()),
            non_finite_pixels: v[8] as u32,
        },
    })
}

fn read_scalars(t: Tensor<1>) -> Result<Vec<f32>, LossError> {
    let data: TensorData = t.into_data();
    data.convert::<f32>()
        .try_into_vec::<f32>()
        .map_err(|e| LossError::Input(format!("sequence_loss: cannot read the loss values: {e:?}")))
}

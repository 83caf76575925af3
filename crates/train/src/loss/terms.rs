//! The three differentiable terms of one prediction (paper eqs. 5–7) as burn tensor code, each
//! reduced with [`masked_mean`] so that an empty mask gives exactly 0 (and zero gradients).
//!
//! Conventions: images `[B, C, H, W]` in `[0, 1]` (the release divides its 0–255 model inputs by
//! 255 before every image term), disparities `[B, 1, H, W]` in pixels with `x_R = x_L − d`, masks
//! `[B, 1, H, W]` booleans (true = counted).

use burn::tensor::ops::{GridSampleOptions, GridSamplePaddingMode, InterpolateMode};
use burn::tensor::{Bool, Tensor};
use nn::photometric::{photometric_map, Photometric};
use nn::pool::avg_pool2d_box;

use super::config::DisparityPenalty;

/// SSIM stabilisers of the release (and Monodepth) for images in `[0, 1]`: `C1 = 0.01²`,
/// `C2 = 0.03²`.
pub const SSIM_C1: f32 = 0.01 * 0.01;
/// See [`SSIM_C1`].
pub const SSIM_C2: f32 = 0.03 * 0.03;

/// Mean of `map` over the pixels where `keep` is true, pooled over the whole batch (as the
/// release's `(map · mask).sum() / mask.sum().clamp(min = 1)`). Excluded pixels are replaced by 0
/// before the sum, so a NaN or infinity there can neither leak into the value nor into the
/// gradient; an empty mask gives 0.
pub fn masked_mean(map: Tensor<4>, keep: Tensor<4, Bool>) -> Tensor<1> {
    let count = keep.clone().float().sum().clamp_min(1.0);
    map.mask_fill(keep.bool_not(), 0.0).sum() / count
}

/// Per-pixel `L_disp` penalty of `prediction − target` (`[B, 1, H, W]`).
pub fn disparity_error_map(
    prediction: Tensor<4>,
    target: Tensor<4>,
    penalty: DisparityPenalty,
) -> Tensor<4> {
    let abs = (prediction - target).abs();
    match penalty {
        DisparityPenalty::L1 => abs,
        DisparityPenalty::SmoothL1 { beta } => {
            let quadratic = abs.clone().powi_scalar(2).mul_scalar(0.5 / beta);
            let linear = abs.clone().sub_scalar(0.5 * beta);
            linear.mask_where(abs.lower_elem(beta), quadratic)
        }
    }
}

/// Warps the right image to the left view by a left disparity: `out(x, y) = R(x − d, y)`, bilinear
/// with zero padding, differentiable in both the image and the disparity. As the release's
/// `warp_image`: `grid_sample(align_corners=True)` on the grid `(x − d, y)` normalised by
/// `size − 1`, i.e. the exact sub-pixel position, no half-pixel shift.
pub fn warp_right_to_left(right: Tensor<4>, disparity: Tensor<4>) -> Tensor<4> {
    // The same `(x − d, y)` grid as MonSter++'s own warp; only the sampling options differ.
    let grid = nn::monster::warp::disp_warp_grid(disparity);
    let opts = GridSampleOptions::new(InterpolateMode::Bilinear)
        .with_padding_mode(GridSamplePaddingMode::Zeros)
        .with_align_corners(true);
    nn::grid_sample::grid_sample_2d(right, grid, opts)
}

/// The release's `ssim_loss_map`: `(1 − SSIM)/2` averaged over channels, `[B, 1, H, W]`, with
/// `window × window` box statistics from zero-padded average pooling that counts the padding
/// (torch `avg_pool2d(k, 1, k/2)`), and the denominator clamped to ≥ 1e-8.
pub fn ssim_loss_map(x: Tensor<4>, y: Tensor<4>, window: usize) -> Tensor<4> {
    // The zero-padded box mean is separable (the padding is a product domain), so two 1-D
    // pools give exactly the 2-D one at 2k instead of k² taps per pixel, forward and backward.
    let r = window / 2;
    let pool = |t: Tensor<4>| {
        let rows = avg_pool2d_box(t, [1, window], [1, 1], [0, r]);
        avg_pool2d_box(rows, [window, 1], [1, 1], [r, 0])
    };
    let mu_x = pool(x.clone());
    let mu_y = pool(y.clone());
    let mu_x2 = mu_x.clone().powi_scalar(2);
    let mu_y2 = mu_y.clone().powi_scalar(2);
    let mu_xy = mu_x * mu_y;
    let sig_x = pool(x.clone().powi_scalar(2)) - mu_x2.clone();
    let sig_y = pool(y.clone().powi_scalar(2)) - mu_y2.clone();
    let sig_xy = pool(x * y) - mu_xy.clone();
    let num =
        (mu_xy.mul_scalar(2.0).add_scalar(SSIM_C1)) * (sig_xy.mul_scalar(2.0).add_scalar(SSIM_C2));
    let den = (mu_x2 + mu_y2).add_scalar(SSIM_C1) * (sig_x + sig_y).add_scalar(SSIM_C2);
    let ssim = num / den.clamp_min(1e-8);
    ssim.neg().add_scalar(1.0).mul_scalar(0.5).mean_dim(1)
}

/// Per-pixel photometric error `α(1 − SSIM)/2 + (1 − α)|·|` (channel means, `[B, 1, H, W]`)
/// between the real left image (data: no gradient flows to it) and the real right image warped
/// by `disparity`; one fused operation on the CPU device ([`nn::photometric`]).
pub fn photometric_error_map(
    real_left: Tensor<4>,
    real_right: Tensor<4>,
    disparity: Tensor<4>,
    alpha: f32,
    ssim_window: usize,
) -> Tensor<4> {
    let reconstruction = warp_right_to_left(real_right, disparity);
    let options = Photometric {
        alpha,
        window: ssim_window,
    };
    if let Some(map) = photometric_map(real_left.clone(), reconstruction.clone(), options) {
        return map;
    }
    let real_left = real_left.detach();
    let l1 = (real_left.clone() - reconstruction.clone())
        .abs()
        .mean_dim(1);
    ssim_loss_map(real_left, reconstruction, ssim_window)
        .mul_scalar(alpha)
        .add(l1.mul_scalar(1.0 - alpha))
}

/// Edge-aware first-order smoothness (paper eq. 7, release `edge_aware_smoothness_map`):
/// `mean|∂x D̂| e^{−|∂x I|} + mean|∂y D̂| e^{−|∂y I|}` with forward differences, image gradients
/// averaged over channels, `D̂ = D / mean(D)` per image when `normalise_by_mean` (the mean clamped
/// to ≥ 1e-7, as the release). The means run over the pixel pairs whose `keep_x` / `keep_y` is true
/// (`[B, 1, H, W−1]` / `[B, 1, H−1, W]`); `None` averages over every pair (the release).
pub fn smoothness_term(
    disparity: Tensor<4>,
    image: Tensor<4>,
    normalise_by_mean: bool,
    keep: Option<(Tensor<4, Bool>, Tensor<4, Bool>)>,
) -> Tensor<1> {
    let [b, _, h, w] = disparity.dims();
    let device = disparity.device();
    let disparity = if normalise_by_mean {
        let mean = disparity.clone().mean_dims(&[2, 3]).clamp_min(1e-7);
        disparity / mean
    } else {
        disparity
    };
    let (keep_x, keep_y) = match keep {
        Some((kx, ky)) => (Some(kx), Some(ky)),
        None => (None, None),
    };
    let reduce = |map: Tensor<4>, keep: Option<Tensor<4, Bool>>| match keep {
        Some(k) => masked_mean(map, k),
        None => map.mean(),
    };
    let zero = || Tensor::<1>::zeros([1], &device);
    let x_term = if w > 1 {
        let dd = (disparity.clone().slice([0..b, 0..1, 0..h, 0..w - 1])
            - disparity.clone().slice([0..b, 0..1, 0..h, 1..w]))
        .abs();
        let c = image.dims()[1];
        let di = (image.clone().slice([0..b, 0..c, 0..h, 0..w - 1])
            - image.clone().slice([0..b, 0..c, 0..h, 1..w]))
        .abs()
        .mean_dim(1);
        reduce(dd * di.neg().exp(), keep_x)
    } else {
        zero()
    };
    let y_term = if h > 1 {
        let dd = (disparity.clone().slice([0..b, 0..1, 0..h - 1, 0..w])
            - disparity.slice([0..b, 0..1, 1..h, 0..w]))
        .abs();
        let c = image.dims()[1];
        let di = (image.clone().slice([0..b, 0..c, 0..h - 1, 0..w])
            - image.slice([0..b, 0..c, 1..h, 0..w]))
        .abs()
        .mean_dim(1);
        reduce(dd * di.neg().exp(), keep_y)
    } else {
        zero()
    };
    x_term + y_term
}

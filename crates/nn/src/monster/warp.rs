//! `disp_warp` (upstream `core/warp.py`): warp the right image/features to the left view with a
//! horizontal disparity, reproducing the upstream normalisation mismatch exactly.
//!
//! Upstream builds the grid `(x - d, y)` and normalises it with `2·v/(size-1) - 1` (the
//! align_corners=True convention), but samples with `grid_sample(bilinear, padding='border')` and
//! the default `align_corners=False`. The effective source position is therefore
//! `u = (x - d)·W/(W-1) - 0.5` and — easy to miss — `v = y·H/(H-1) - 0.5` (rows are blended too),
//! both clamped to the border. We build the very same normalised grid and call burn's
//! `grid_sample_2d` with the same options, so the quirk is reproduced by construction. The
//! upstream valid mask is unused by MonSter and not computed.

use burn::tensor::ops::{GridSampleOptions, GridSamplePaddingMode, InterpolateMode};
use burn::tensor::{Int, Tensor};

/// Normalised sampling grid `[B, H, W, 2]` of upstream `disp_warp` for a disparity `[B, 1, H, W]`.
pub fn disp_warp_grid(disp: Tensor<4>) -> Tensor<4> {
    let [b, _, h, w] = disp.dims();
    let device = disp.device();
    let xs = Tensor::<1, Int>::arange(0..w as i64, &device)
        .float()
        .reshape([1, 1, 1, w]);
    let ys = Tensor::<1, Int>::arange(0..h as i64, &device)
        .float()
        .reshape([1, 1, h, 1]);
    // Same f32 operation order as upstream: 2 * (v / (size - 1)) - 1.
    let gx = (xs - disp)
        .div_scalar((w as f32 - 1.0).max(1.0))
        .mul_scalar(2.0)
        .sub_scalar(1.0); // [B,1,H,W]
    let gy = ys
        .div_scalar((h as f32 - 1.0).max(1.0))
        .mul_scalar(2.0)
        .sub_scalar(1.0)
        .expand([b, 1, h, w]);
    // Concatenated along the last axis (a fresh, contiguous `[B, H, W, 2]`), not permuted from
    // `[B, 2, H, W]`: burn-cubecl's `grid_sample` kernel (wgpu/CUDA, burn 0.22.1) reads `gy` at
    // `grid[offset + 1]`, ignoring the grid's last-axis stride, so a permuted view samples the
    // wrong rows there.
    let [gx, gy] = [gx, gy].map(|g| g.permute([0, 2, 3, 1]));
    Tensor::cat(vec![gx, gy], 3)
}

/// Upstream `disp_warp(img, disp)[0]`: `img` `[B, C, H, W]`, `disp` `[B, 1, H, W]` (positive,
/// in pixels of this resolution). Bilinear, border padding, align_corners=False on a grid
/// normalised with `(size-1)` (see the module docs).
pub fn disp_warp(img: Tensor<4>, disp: Tensor<4>) -> Tensor<4> {
    let grid = disp_warp_grid(disp);
    let opts = GridSampleOptions::new(InterpolateMode::Bilinear)
        .with_padding_mode(GridSamplePaddingMode::Border)
        .with_align_corners(false);
    crate::grid_sample::grid_sample_2d(img, grid, opts)
}

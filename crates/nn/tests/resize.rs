//! `nn::resize`: the select-based bilinear resize (the path taken inside autodiff graphs, which
//! the GPU backends can differentiate) and the CPU kernels (inference, and training with their
//! adjoint) against burn's `interpolate` kernel, forward and backward, both PyTorch conventions,
//! up and down.

use burn::tensor::module::interpolate;
use burn::tensor::ops::{InterpolateMode, InterpolateOptions};
use burn::tensor::{Device, Tensor, TensorData};
use nn::resize::{resize_bilinear, resize_bilinear_separable};

fn input(h: usize, w: usize, device: &Device) -> Tensor<4> {
    let data: Vec<f32> = (0..2 * 3 * h * w)
        .map(|i| ((i * 7919) % 211) as f32 / 17.0 - 5.0)
        .collect();
    Tensor::from_data(TensorData::new(data, [2, 3, h, w]), device)
}

fn native(x: Tensor<4>, size: [usize; 2], align_corners: bool) -> Tensor<4> {
    interpolate(
        x,
        InterpolateOptions::new(InterpolateMode::Bilinear)
            .with_output_size(size)
            .with_align_corners(align_corners),
    )
}

fn max_abs_diff(a: Tensor<4>, b: Tensor<4>) -> f32 {
    (a - b).abs().max().into_scalar()
}

const CASES: [([usize; 2], [usize; 2]); 7] = [
    ([5, 7], [11, 13]),
    ([12, 16], [3, 4]),
    ([8, 8], [8, 17]),
    ([9, 6], [1, 1]),
    ([6, 10], [21, 7]),
    // The MonSter++ ConvGRU's ×2 resizes.
    ([16, 32], [32, 64]),
    ([31, 17], [62, 34]),
];

/// `resize` against burn's kernel on every case, both conventions. Both paths of ours compute
/// source positions in f32 as PyTorch does; burn's kernel differs from them by that rounding
/// (about 2e-6 relative).
fn matches_the_kernel(resize: fn(Tensor<4>, [usize; 2], bool) -> Tensor<4>) {
    let device = Device::flex();
    for (from, to) in CASES {
        for align_corners in [true, false] {
            let x = input(from[0], from[1], &device);
            let d = max_abs_diff(
                resize(x.clone(), to, align_corners),
                native(x, to, align_corners),
            );
            assert!(
                d < 2e-5,
                "{from:?} → {to:?}, align_corners {align_corners}: {d}"
            );
        }
    }
}

#[test]
fn separable_matches_the_kernel() {
    matches_the_kernel(resize_bilinear_separable);
}

/// The plain-buffer kernel (what `resize_bilinear` runs on the CPU inference device).
#[test]
fn cpu_inference_kernel_matches_the_kernel() {
    matches_the_kernel(resize_bilinear);
}

/// The input gradient of `resize` under autodiff on the CPU against burn's kernel's.
fn gradients_match_the_kernel(resize: fn(Tensor<4>, [usize; 2], bool) -> Tensor<4>) {
    let device = Device::flex().autodiff();
    for (from, to) in CASES {
        for align_corners in [true, false] {
            let upstream = input(to[0], to[1], &device);
            let grad = |resize: fn(Tensor<4>, [usize; 2], bool) -> Tensor<4>| {
                let x = input(from[0], from[1], &device).require_grad();
                let y = resize(x.clone(), to, align_corners);
                let grads = (y * upstream.clone()).sum().backward();
                x.grad(&grads).expect("input gradient")
            };
            let (ours, kernel) = (grad(resize), grad(native));
            let d: f32 = (ours - kernel).abs().max().into_scalar();
            assert!(
                d < 1e-4,
                "{from:?} → {to:?}, align_corners {align_corners}: {d}"
            );
        }
    }
}

#[test]
fn separable_gradients_match_the_kernel() {
    gradients_match_the_kernel(resize_bilinear_separable);
}

/// The CPU training path: the plain-buffer kernel as a burn operation with its adjoint.
#[test]
fn cpu_training_gradients_match_the_kernel() {
    gradients_match_the_kernel(resize_bilinear);
    let x = input(5, 7, &Device::flex().autodiff());
    let d = max_abs_diff(
        resize_bilinear(x.clone(), [11, 13], false),
        native(x, [11, 13], false),
    );
    assert!(d < 2e-5, "forward: {d}");
}

#[test]
fn same_size_is_identity_and_graphs_are_told_apart() {
    let device = Device::flex().autodiff();
    let x = input(4, 5, &device).require_grad();
    assert!(x.is_tracked() && x.device().inner() == Device::flex());
    for align_corners in [true, false] {
        let same = resize_bilinear(x.clone(), [4, 5], align_corners);
        assert_eq!(max_abs_diff(same, x.clone()), 0.0);
    }
    assert!(!input(4, 5, &Device::flex()).is_tracked());
}

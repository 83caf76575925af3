//! Convolutions for inference on the CPU (`flex`) device, on the `gemm` crate with every
//! thread: stride-1 layers as one GEMM per kernel tap over the zero-padded NCHW input (read in
//! place through the GEMM's strides), strided and thin layers through an unfolded input,
//! transposed layers as one GEMM and a scatter; bias, an inference BatchNorm and the activation
//! are applied while the output is written ([`conv2d_fused`], [`conv_transpose2d_fused`]).
//!
//! Why: burn's CPU convolution builds im2col tiles of 512 pixels, converts the input to NHWC and
//! re-lays out the weights at every call, then BatchNorm and the activation each make another pass;
//! on MonSter++ that ran well below the GEMM's own speed (BENCHMARKS.md, "MonSter++ against
//! PyTorch, and where the time goes"). Everything these kernels do not cover (other devices,
//! autodiff, groups, `Same` padding) keeps burn's layers, so the functions here are drop-ins for
//! `forward`.

mod epilogue;
mod geometry;
mod gradients;
mod kernels;
mod prepared;
mod scratch;
mod trainable;
mod volume;
mod winograd;

use std::sync::Arc;

use burn::nn::conv::{Conv2d, ConvTranspose2d};
use burn::nn::{BatchNorm, PaddingConfig2d};
use burn::tensor::{Tensor, TensorData};

use crate::activation::{leaky_relu, relu};
use crate::cpu_mode::{cpu_mode, CpuMode};
use crate::flex_tensor::f32_vec;

pub use crate::cpu_mode::{on_cpu_inference, on_cpu_training};

pub use epilogue::{Activation, Epilogue};
pub use geometry::{Geometry, Nchw, TransposeGeometry};
pub use kernels::{conv2d_nchw, conv_transpose2d_nchw};
pub(crate) use prepared::prepared;
pub use prepared::{with_prepared_weights, LayerWeights};
pub use volume::{conv3d_forward, conv_transpose3d_forward, Geometry3};

/// `conv.forward(x)`.
pub fn conv2d_forward(conv: &Conv2d, x: Tensor<4>) -> Tensor<4> {
    conv2d_fused(conv, None, Activation::Identity, x)
}

/// `act(bn(conv(x)))` (`bn` in inference mode: its running statistics), in one pass over the
/// output where [`geometry`] applies, else through burn's layers.
pub fn conv2d_fused(
    conv: &Conv2d,
    bn: Option<&BatchNorm>,
    act: Activation,
    x: Tensor<4>,
) -> Tensor<4> {
    let bias = conv.bias.as_ref().map(|b| b.val());
    match (layer_geometry(conv), cpu_mode(&x)) {
        (Some(geometry), Some(CpuMode::Inference)) => {
            conv2d_prepared(x, &layer_weights(conv), bias, geometry, bn, act)
        }
        (Some(geometry), Some(CpuMode::Training)) => burn_layers(
            trainable::conv2d(x, conv.weight.val(), bias, geometry),
            bn,
            act,
        ),
        _ => burn_layers(conv.forward(x), bn, act),
    }
}

/// `conv`'s weights for the kernels, prepared once per [`with_prepared_weights`] scope.
pub fn layer_weights(conv: &Conv2d) -> Arc<LayerWeights> {
    prepared(conv.weight.id, "conv2d", || {
        let [co, _, kh, kw] = conv.weight.dims();
        LayerWeights::new(f32_vec(conv.weight.val()), co, kh * kw)
    })
}

/// [`conv2d_fused`] on bare tensors (`weight` `[co, ci, kh, kw]`), for layers that are not a
/// `Conv2d`; the caller has checked [`on_cpu_inference`].
pub fn conv2d_with(
    x: Tensor<4>,
    weight: Tensor<4>,
    bias: Option<Tensor<1>>,
    geometry: Geometry,
    bn: Option<&BatchNorm>,
    act: Activation,
) -> Tensor<4> {
    let [co, _, kh, kw] = weight.dims();
    let weights = LayerWeights::new(f32_vec(weight), co, kh * kw);
    conv2d_prepared(x, &weights, bias, geometry, bn, act)
}

/// [`conv2d_with`] on prepared weights.
fn conv2d_prepared(
    x: Tensor<4>,
    weights: &LayerWeights,
    bias: Option<Tensor<1>>,
    geometry: Geometry,
    bn: Option<&BatchNorm>,
    act: Activation,
) -> Tensor<4> {
    let device = x.device();
    let [b, c, h, w] = x.dims();
    let co = weights.co();
    let input = f32_vec(x);
    let (scale, shift) = affine(bias.map(f32_vec), bn);
    let epilogue = Epilogue {
        scale: scale.as_deref(),
        shift: shift.as_deref(),
        act,
    };
    let shape = Nchw { b, c, h, w };
    let (out, [oh, ow]) = conv2d_nchw(&input, shape, weights, geometry, epilogue);
    Tensor::from_data(TensorData::new(out, [b, co, oh, ow]), &device)
}

/// `conv.forward(x)` for a transposed convolution.
pub fn conv_transpose2d_forward(conv: &ConvTranspose2d, x: Tensor<4>) -> Tensor<4> {
    conv_transpose2d_fused(conv, None, Activation::Identity, x)
}

/// `act(bn(conv(x)))` for a transposed convolution (see [`conv2d_fused`]).
pub fn conv_transpose2d_fused(
    conv: &ConvTranspose2d,
    bn: Option<&BatchNorm>,
    act: Activation,
    x: Tensor<4>,
) -> Tensor<4> {
    let geometry = TransposeGeometry {
        kernel: conv.kernel_size,
        stride: conv.stride,
        padding: conv.padding,
        dilation: conv.dilation,
        padding_out: conv.padding_out,
    };
    let bias = conv.bias.as_ref().map(|b| b.val());
    match (conv.groups, cpu_mode(&x)) {
        (1, Some(CpuMode::Inference)) => {
            conv_transpose2d_with(x, conv.weight.val(), bias, geometry, bn, act)
        }
        (1, Some(CpuMode::Training)) => burn_layers(
            trainable::conv_transpose2d(x, conv.weight.val(), bias, geometry),
            bn,
            act,
        ),
        _ => burn_layers(conv.forward(x), bn, act),
    }
}

/// [`conv_transpose2d_fused`] on bare tensors (`weight` `[ci, co, kh, kw]`, one group); the
/// caller has checked [`on_cpu_inference`].
pub fn conv_transpose2d_with(
    x: Tensor<4>,
    weight: Tensor<4>,
    bias: Option<Tensor<1>>,
    geometry: TransposeGeometry,
    bn: Option<&BatchNorm>,
    act: Activation,
) -> Tensor<4> {
    let device = x.device();
    let [b, c, h, w] = x.dims();
    let [_, co, _, _] = weight.dims();
    let input = f32_vec(x);
    let weight = f32_vec(weight);
    let bias = bias.map(f32_vec);
    // The bias goes in before the scatter; the BatchNorm's shift after it.
    let (scale, shift) = affine(None, bn);
    let epilogue = Epilogue {
        scale: scale.as_deref(),
        shift: shift.as_deref(),
        act,
    };
    let shape = Nchw { b, c, h, w };
    let (out, [oh, ow]) = conv_transpose2d_nchw(
        &input,
        shape,
        &weight,
        co,
        geometry,
        bias.as_deref(),
        epilogue,
    );
    Tensor::from_data(TensorData::new(out, [b, co, oh, ow]), &device)
}

/// The kernels' geometry of `conv` on `x` when they apply: the CPU inference device, one
/// group, explicit or no padding.
pub fn geometry(conv: &Conv2d, x: &Tensor<4>) -> Option<Geometry> {
    layer_geometry(conv).filter(|_| on_cpu_inference(x))
}

/// The kernels' geometry of `conv` when they can run it: one group, explicit or no padding.
fn layer_geometry(conv: &Conv2d) -> Option<Geometry> {
    if conv.groups != 1 {
        return None;
    }
    let padding = match conv.padding {
        PaddingConfig2d::Explicit(t, l, b, r) => [t, l, b, r],
        PaddingConfig2d::Valid => [0; 4],
        PaddingConfig2d::Same => return None,
    };
    Some(Geometry {
        kernel: conv.kernel_size,
        stride: conv.stride,
        padding,
        dilation: conv.dilation,
    })
}

/// Per-channel `(scale, shift)` of `bn(y + bias)`: `scale = γ/√(σ²+ε)`,
/// `shift = β + (bias − μ)·scale`; without `bn`, just the bias.
fn affine(bias: Option<Vec<f32>>, bn: Option<&BatchNorm>) -> (Option<Vec<f32>>, Option<Vec<f32>>) {
    let Some(bn) = bn else {
        return (None, bias);
    };
    let gamma = f32_vec(bn.gamma.val());
    let beta = f32_vec(bn.beta.val());
    let mean = f32_vec(bn.running_mean.value());
    let var = f32_vec(bn.running_var.value());
    let scale: Vec<f32> = gamma
        .iter()
        .zip(&var)
        .map(|(g, v)| g / (v + bn.epsilon as f32).sqrt())
        .collect();
    let shift = (0..scale.len())
        .map(|c| beta[c] + (bias.as_ref().map_or(0.0, |b| b[c]) - mean[c]) * scale[c])
        .collect();
    (Some(scale), Some(shift))
}

/// `act(bn(y))` on burn's layers (the fallback).
fn burn_layers(y: Tensor<4>, bn: Option<&BatchNorm>, act: Activation) -> Tensor<4> {
    let y = match bn {
        Some(bn) => bn.forward(y),
        None => y,
    };
    match act {
        Activation::Identity => y,
        Activation::Relu => relu(y),
        Activation::LeakyRelu(slope) => leaky_relu(y, slope),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::module::Param;
    use burn::nn::conv::{Conv2dConfig, ConvTranspose2dConfig};
    use burn::nn::BatchNormConfig;
    use burn::tensor::{Device, Distribution};

    fn close(a: Tensor<4>, b: Tensor<4>) {
        assert_eq!(a.dims(), b.dims());
        let (a, b) = (f32_vec(a), f32_vec(b));
        let scale = b.iter().fold(0.0f32, |m, v| m.max(v.abs())).max(1.0);
        let worst = a
            .iter()
            .zip(&b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0f32, f32::max);
        assert!(
            worst <= 2e-5 * scale,
            "max difference {worst} (scale {scale})"
        );
    }

    fn random(dims: [usize; 4]) -> Tensor<4> {
        Tensor::random(dims, Distribution::Normal(0.0, 1.0), &Device::flex())
    }

    /// A BatchNorm with running statistics far from the identity, so that folding it shows.
    fn trained_bn(c: usize) -> BatchNorm {
        let device = Device::flex();
        let mut bn = BatchNormConfig::new(c).init(&device);
        let uniform = |lo, hi| Tensor::<1>::random([c], Distribution::Uniform(lo, hi), &device);
        bn.gamma = Param::from_tensor(uniform(0.5, 2.0));
        bn.beta = Param::from_tensor(uniform(-1.0, 1.0));
        bn.running_mean = burn::module::RunningState::new(uniform(-0.5, 0.5));
        bn.running_var = burn::module::RunningState::new(uniform(0.2, 3.0));
        bn
    }

    // (input dims, [out channels, kernel], stride, dilation, padding, bias)
    type Case = ([usize; 4], [usize; 2], usize, usize, PaddingConfig2d, bool);

    /// The kernels against burn's convolution on the shapes MonSter++ uses and the edge cases:
    /// Winograd (3×3 with 16+ channels each side on 32+ output tiles: odd sizes, asymmetric or
    /// no padding, batch 2), tap GEMMs (3×3 on small maps, a 1-pixel image, 1×1, 7×7,
    /// asymmetric padding, dilation, no bias, batch 2, a 1-pixel-wide image) and the unfolded
    /// path (strides 2 and 4 with and without dilation, thin inputs, odd sizes).
    #[test]
    fn matches_burn_convolution() {
        let explicit = PaddingConfig2d::Explicit;
        let cases: [Case; 18] = [
            ([1, 20, 12, 13], [16, 3], 1, 1, explicit(0, 1, 2, 1), true),
            ([2, 16, 15, 13], [24, 3], 1, 1, PaddingConfig2d::Valid, true),
            ([2, 16, 7, 5], [24, 3], 1, 1, PaddingConfig2d::Valid, true),
            ([1, 32, 1, 1], [16, 3], 1, 1, explicit(1, 1, 1, 1), false),
            ([1, 24, 9, 13], [16, 3], 1, 1, explicit(1, 1, 1, 1), true),
            ([2, 17, 7, 6], [4, 1], 1, 1, PaddingConfig2d::Valid, true),
            ([1, 16, 12, 10], [8, 7], 1, 1, explicit(3, 3, 3, 3), true),
            ([1, 16, 8, 9], [3, 3], 1, 2, explicit(2, 2, 2, 2), false),
            ([1, 20, 8, 9], [3, 3], 1, 1, explicit(0, 1, 2, 1), true),
            ([1, 16, 5, 1], [2, 3], 1, 1, explicit(1, 1, 1, 1), true),
            ([1, 18, 6, 6], [5, 3], 1, 1, PaddingConfig2d::Valid, true),
            ([1, 40, 70, 90], [33, 3], 1, 1, explicit(1, 1, 1, 1), true),
            ([1, 3, 17, 22], [32, 3], 2, 1, explicit(1, 1, 1, 1), false),
            ([2, 24, 16, 20], [48, 3], 2, 2, explicit(2, 2, 2, 2), true),
            ([1, 1, 12, 16], [64, 7], 1, 1, explicit(3, 3, 3, 3), true),
            ([1, 3, 28, 42], [8, 14], 14, 1, PaddingConfig2d::Valid, true),
            ([1, 16, 15, 9], [6, 4], 3, 1, explicit(0, 2, 1, 0), true),
            ([1, 64, 130, 66], [48, 3], 2, 1, explicit(1, 1, 1, 1), false),
        ];
        for (dims, [co, k], stride, dilation, padding, bias) in cases {
            let conv = Conv2dConfig::new([dims[1], co], [k, k])
                .with_stride([stride, stride])
                .with_dilation([dilation, dilation])
                .with_padding(padding.clone())
                .with_bias(bias)
                .init(&Device::flex());
            let x = random(dims);
            assert!(
                geometry(&conv, &x).is_some(),
                "{padding:?} takes the kernels"
            );
            close(conv2d_forward(&conv, x.clone()), conv.forward(x));
        }
    }

    /// Conv + BatchNorm + activation in one pass equals burn's three layers (Winograd at
    /// stride 1, unfolded at stride 2).
    #[test]
    fn fused_batch_norm_and_activation_match_burn() {
        for (stride, act) in [
            (1, Activation::Relu),
            (2, Activation::LeakyRelu(0.2)),
            (1, Activation::Identity),
        ] {
            let conv = Conv2dConfig::new([24, 20], [3, 3])
                .with_stride([stride, stride])
                .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
                .init(&Device::flex());
            let bn = trained_bn(20);
            let x = random([1, 24, 13, 18]);
            let expected = burn_layers(conv.forward(x.clone()), Some(&bn), act);
            close(conv2d_fused(&conv, Some(&bn), act, x), expected);
        }
    }

    /// Transposed convolutions of MonSter++ (k4 s2 p1, k2 s2, k = s = 4, the bias-free
    /// U-Net one with BatchNorm + ReLU) and an odd one (k3 s2 p1 with output padding, dilation).
    #[test]
    fn transposed_matches_burn() {
        // (input dims, out channels, kernel, stride, padding, padding_out, dilation, bias, bn)
        type TCase = (
            [usize; 4],
            usize,
            usize,
            usize,
            usize,
            usize,
            usize,
            bool,
            bool,
        );
        let cases: [TCase; 5] = [
            ([1, 32, 8, 12], 16, 4, 2, 1, 0, 1, true, false),
            ([2, 20, 5, 7], 9, 2, 2, 0, 0, 1, true, false),
            ([1, 24, 4, 6], 12, 4, 4, 0, 0, 1, true, false),
            ([1, 48, 8, 16], 32, 4, 2, 1, 0, 1, false, true),
            ([1, 16, 6, 5], 8, 3, 2, 1, 1, 2, true, false),
        ];
        for (dims, co, k, s, p, p_out, d, bias, with_bn) in cases {
            let conv = ConvTranspose2dConfig::new([dims[1], co], [k, k])
                .with_stride([s, s])
                .with_padding([p, p])
                .with_padding_out([p_out, p_out])
                .with_dilation([d, d])
                .with_bias(bias)
                .init(&Device::flex());
            let bn = with_bn.then(|| trained_bn(co));
            let act = if with_bn {
                Activation::Relu
            } else {
                Activation::Identity
            };
            let x = random(dims);
            let expected = burn_layers(conv.forward(x.clone()), bn.as_ref(), act);
            close(conv_transpose2d_fused(&conv, bn.as_ref(), act, x), expected);
        }
    }

    #[test]
    fn other_convolutions_keep_burn() {
        let device = Device::flex();
        let x = random([1, 16, 8, 8]);
        let grouped = Conv2dConfig::new([16, 4], [3, 3])
            .with_groups(2)
            .init(&device);
        assert!(geometry(&grouped, &x).is_none());
        let same = Conv2dConfig::new([16, 4], [3, 3])
            .with_padding(PaddingConfig2d::Same)
            .init(&device);
        assert!(geometry(&same, &x).is_none());
        close(conv2d_forward(&grouped, x.clone()), grouped.forward(x));
        let tracked = Tensor::<4>::random(
            [1, 16, 8, 8],
            Distribution::Normal(0.0, 1.0),
            &device.clone().autodiff(),
        );
        let plain = Conv2dConfig::new([16, 4], [3, 3]).init(&device.autodiff());
        assert!(
            geometry(&plain, &tracked).is_none(),
            "autodiff keeps burn's"
        );
    }
}

//! Stereo features (design §2.2): `Feat_transfer` on the DPT paths, the instance-normalised conv
//! stems on the normalised image, and the matching descriptors `desc(conv(features[0]))`.
//!
//! Field names mirror the upstream state-dict keys: [`StereoFeatures`] holds the root-level
//! modules `feat_transfer`, `stem_{2,4,8,16}`, `conv` and `desc`, so it loads from a full
//! checkpoint with an **empty** key prefix (the other root keys are simply not used).
//!
//! Shapes (h = H/4, w = W/4, F = DPT `features`: 64 for vits and the tiny fixture, 128 vitb, 256 vitl):
//! - DPT paths `[F×h×w, F×H/8×W/8, F×H/16×W/16, F×H/32×W/32]`
//! - `Feat_transfer` → `[48×h×w, 64×H/8, 192×H/16, 160×H/32]`
//! - stems → `[32×H/2, 48×H/4, 96×H/8, 192×H/16]`
//! - `features[0] = cat(f4, stem_4)` → 96×h×w; matching features 96×h×w.

use burn::module::Module;
use burn::nn::conv::{Conv2d, Conv2dConfig, ConvTranspose2d, ConvTranspose2dConfig};
use burn::nn::PaddingConfig2d;
use burn::tensor::{Device, Tensor};

use crate::activation::{leaky_relu, relu};
use crate::conv::{conv2d_forward, conv_transpose2d_forward};

/// Slope of PyTorch's default `nn.LeakyReLU()`, used by `BasicConv`/`BasicConv_IN`.
pub const LEAKY_SLOPE: f32 = 0.01;
/// `nn.InstanceNorm2d` default epsilon.
pub const IN_EPS: f64 = 1e-5;

/// `InstanceNorm` without affine parameters and always with instance statistics (PyTorch's
/// `nn.InstanceNorm2d(c)` default): per sample and channel over all remaining axes, biased variance.
/// Works for any rank ≥ 3 (`[B, C, ...]`).
pub fn instance_norm<const D: usize>(x: Tensor<D>) -> Tensor<D> {
    let dims = x.dims();
    let (b, c) = (dims[0], dims[1]);
    let n: usize = dims[2..].iter().product();
    let x3: Tensor<3> = x.reshape([b, c, n]);
    let mean = x3.clone().mean_dim(2);
    let centered = x3 - mean;
    let var = centered.clone().square().mean_dim(2);
    let out = centered / var.add_scalar(IN_EPS).sqrt();
    out.reshape(dims)
}

/// Conv2d with symmetric padding, optional bias.
/// A convolution's square window: kernel size, stride and zero padding (upstream
/// `BasicConv`'s arguments after the channels).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Window {
    pub size: usize,
    pub stride: usize,
    pub pad: usize,
}

impl Window {
    pub const fn new(size: usize, stride: usize, pad: usize) -> Self {
        Self { size, stride, pad }
    }

    /// A 2-D convolution over this window.
    pub fn conv2d(self, c_in: usize, c_out: usize, bias: bool, device: &Device) -> Conv2d {
        conv2d(c_in, c_out, self.size, self.stride, self.pad, bias, device)
    }
}

pub(crate) fn conv2d(
    c_in: usize,
    c_out: usize,
    k: usize,
    stride: usize,
    pad: usize,
    bias: bool,
    device: &Device,
) -> Conv2d {
    Conv2dConfig::new([c_in, c_out], [k, k])
        .with_stride([stride, stride])
        .with_padding(PaddingConfig2d::Explicit(pad, pad, pad, pad))
        .with_bias(bias)
        .init(device)
}

/// `BasicConv_IN` (2-D, no deconv): Conv (no bias) → InstanceNorm → LeakyReLU(0.01). Key: `conv.weight`.
#[derive(Module, Debug)]
pub struct BasicConvIn {
    pub conv: Conv2d,
}

impl BasicConvIn {
    pub fn new(c_in: usize, c_out: usize, window: Window, device: &Device) -> Self {
        Self {
            conv: window.conv2d(c_in, c_out, false, device),
        }
    }

    /// `[B, c_in, H, W]` → `[B, c_out, H/stride, W/stride]`.
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        leaky_relu(instance_norm(conv2d_forward(&self.conv, x)), LEAKY_SLOPE)
    }
}

/// A stem (`stem_N`, also `spx_4`): `Sequential(BasicConv_IN(c_in, c_out, 3, stride, 1),
/// Conv2d(c_out, c_out, 3, 1, 1, bias=False), InstanceNorm2d, ReLU)`. Keys `0.conv.weight`, `1.weight`.
pub type ConvInBlock = (BasicConvIn, Conv2d);

/// Builds a [`ConvInBlock`].
pub fn conv_in_block(c_in: usize, c_out: usize, stride: usize, device: &Device) -> ConvInBlock {
    (
        BasicConvIn::new(c_in, c_out, Window::new(3, stride, 1), device),
        conv2d(c_out, c_out, 3, 1, 1, false, device),
    )
}

/// Forward of a [`ConvInBlock`].
pub fn conv_in_block_forward(block: &ConvInBlock, x: Tensor<4>) -> Tensor<4> {
    relu(instance_norm(conv2d_forward(&block.1, block.0.forward(x))))
}

/// `Conv2d → InstanceNorm → ReLU` as `nn.Sequential` (only the conv has weights, key `0.*`).
pub type ConvInRelu = [Conv2d; 1];

fn conv_in_relu_forward(block: &ConvInRelu, x: Tensor<4>) -> Tensor<4> {
    relu(instance_norm(conv2d_forward(&block[0], x)))
}

fn conv_up(c_in: usize, c_out: usize, device: &Device) -> ConvTranspose2d {
    ConvTranspose2dConfig::new([c_in, c_out], [3, 3])
        .with_stride([2, 2])
        .with_padding([1, 1])
        .with_padding_out([1, 1])
        .with_bias(false)
        .init(device)
}

/// `Feat_transfer` (shared by the left and the right image).
#[derive(Module, Debug)]
pub struct FeatTransfer {
    pub conv4x: ConvInRelu,
    pub conv8x: ConvInRelu,
    pub conv16x: ConvInRelu,
    pub conv32x: ConvInRelu,
    pub conv_up_32x: ConvTranspose2d,
    pub conv_up_16x: ConvTranspose2d,
    pub conv_up_8x: ConvTranspose2d,
    pub res_16x: Conv2d,
    pub res_8x: Conv2d,
    pub res_4x: Conv2d,
}

impl FeatTransfer {
    /// `f` = DPT `features` (channels of every DPT path).
    pub fn new(f: usize, device: &Device) -> Self {
        Self {
            conv4x: [conv2d(48 + f, 48, 5, 1, 2, true, device)],
            conv8x: [conv2d(64 + f, 64, 5, 1, 2, true, device)],
            conv16x: [conv2d(192 + f, 192, 5, 1, 2, true, device)],
            conv32x: [conv2d(f, 160, 3, 1, 1, true, device)],
            conv_up_32x: conv_up(160, 192, device),
            conv_up_16x: conv_up(192, 64, device),
            conv_up_8x: conv_up(64, 48, device),
            res_16x: conv2d(f, 192, 1, 1, 0, true, device),
            res_8x: conv2d(f, 64, 1, 1, 0, true, device),
            res_4x: conv2d(f, 48, 1, 1, 0, true, device),
        }
    }

    /// DPT paths `[F×h×w, F×H/8, F×H/16, F×H/32]` → `[f4 48×h×w, f8 64×H/8, f16 192×H/16, f32 160×H/32]`.
    pub fn forward(&self, paths: [Tensor<4>; 4]) -> [Tensor<4>; 4] {
        let [p4, p8, p16, p32] = paths;
        let f32_ = conv_in_relu_forward(&self.conv32x, p32);
        let up = conv_transpose2d_forward(&self.conv_up_32x, f32_.clone());
        let f16 = conv_in_relu_forward(&self.conv16x, Tensor::cat(vec![p16.clone(), up], 1))
            + conv2d_forward(&self.res_16x, p16);
        let up = conv_transpose2d_forward(&self.conv_up_16x, f16.clone());
        let f8 = conv_in_relu_forward(&self.conv8x, Tensor::cat(vec![p8.clone(), up], 1))
            + conv2d_forward(&self.res_8x, p8);
        let up = conv_transpose2d_forward(&self.conv_up_8x, f8.clone());
        let f4 = conv_in_relu_forward(&self.conv4x, Tensor::cat(vec![p4.clone(), up], 1))
            + conv2d_forward(&self.res_4x, p4);
        [f4, f8, f16, f32_]
    }
}

/// Output of [`StereoFeatures::forward`] for one image.
#[derive(Debug, Clone)]
pub struct FeatureOutput {
    /// `[cat(f4, stem_4) 96×h×w, f8 64×H/8, f16 192×H/16, f32 160×H/32]` (upstream `features_left/right`).
    pub features: [Tensor<4>; 4],
    /// Stems in order `[stem_2 32×H/2, stem_4 48×H/4, stem_8 96×H/8, stem_16 192×H/16]`; only the
    /// first two when `full_stems` is false (the right image upstream).
    pub stems: Vec<Tensor<4>>,
    /// Matching features `desc(conv(features[0]))`, 96×h×w.
    pub matching: Tensor<4>,
}

/// The stereo feature modules at the root of the upstream `Monster` (keys `feat_transfer.*`,
/// `stem_{2,4,8,16}.*`, `conv.*`, `desc.*`).
#[derive(Module, Debug)]
pub struct StereoFeatures {
    pub feat_transfer: FeatTransfer,
    pub stem_2: ConvInBlock,
    pub stem_4: ConvInBlock,
    pub stem_8: ConvInBlock,
    pub stem_16: ConvInBlock,
    /// `BasicConv_IN(96, 96, 3, padding 1)`.
    pub conv: BasicConvIn,
    /// `Conv2d(96, 96, 1)` with bias.
    pub desc: Conv2d,
}

impl StereoFeatures {
    /// `f` = DPT `features` (64 vits, 128 vitb, 256 vitl).
    pub fn new(f: usize, device: &Device) -> Self {
        Self {
            feat_transfer: FeatTransfer::new(f, device),
            stem_2: conv_in_block(3, 32, 2, device),
            stem_4: conv_in_block(32, 48, 2, device),
            stem_8: conv_in_block(48, 96, 2, device),
            stem_16: conv_in_block(96, 192, 2, device),
            conv: BasicConvIn::new(96, 96, Window::new(3, 1, 1), device),
            desc: conv2d(96, 96, 1, 1, 0, true, device),
        }
    }

    /// Stems on the normalised image `2·img/255 − 1` (`[B, 3, H, W]`): `[stem_2, stem_4]`, then
    /// `stem_8, stem_16` too when `full` (the left image).
    pub fn stems(&self, image_normalised: Tensor<4>, full: bool) -> Vec<Tensor<4>> {
        let s2 = conv_in_block_forward(&self.stem_2, image_normalised);
        let s4 = conv_in_block_forward(&self.stem_4, s2.clone());
        if !full {
            return vec![s2, s4];
        }
        let s8 = conv_in_block_forward(&self.stem_8, s4.clone());
        let s16 = conv_in_block_forward(&self.stem_16, s8.clone());
        vec![s2, s4, s8, s16]
    }

    /// Matching descriptors `desc(conv(features0))`: `[B, 96, h, w]` → `[B, 96, h, w]`.
    pub fn matching(&self, features0: Tensor<4>) -> Tensor<4> {
        conv2d_forward(&self.desc, self.conv.forward(features0))
    }

    /// One image: DPT paths of the feature decoder (`feat_decoder`) and the normalised image.
    pub fn forward(
        &self,
        dpt_paths: [Tensor<4>; 4],
        image_normalised: Tensor<4>,
        full_stems: bool,
    ) -> FeatureOutput {
        let [f4, f8, f16, f32_] = self.feat_transfer.forward(dpt_paths);
        let stems = self.stems(image_normalised, full_stems);
        let f0 = Tensor::cat(vec![f4, stems[1].clone()], 1);
        let matching = self.matching(f0.clone());
        FeatureOutput {
            features: [f0, f8, f16, f32_],
            stems,
            matching,
        }
    }
}

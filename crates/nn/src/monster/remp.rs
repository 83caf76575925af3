//! REMP (upstream `core/refinement.py`): the full-resolution refinement run once, at the last
//! iteration. Returns `LeakyReLU(0.01)(disp_up + residual)`; note that `Monster` then adds
//! `disp_up` **again** (quirk 4): `disp_final = disp_up + REMP(mono_up, disp_up, left, right)`.
//! H and W must be multiples of 16 (the U-Net downsamples ×16).

#![allow(non_snake_case)]

use burn::module::Module;
use burn::nn::conv::{Conv2d, Conv2dConfig, ConvTranspose2d};
use burn::nn::{BatchNorm, BatchNormConfig, PaddingConfig2d, Relu};
use burn::tensor::module::adaptive_avg_pool2d;
use burn::tensor::{Device, Tensor};

use crate::activation::{leaky_relu, relu, sigmoid};
use crate::conv::{conv2d_forward, conv2d_fused, conv_transpose2d_fused, Activation};

use super::upsample::deconv_4x4_s2;
use super::warp::disp_warp;

#[allow(clippy::too_many_arguments)] // mirrors PyTorch's Conv2d signature, one call per layer
fn conv2d(
    c_in: usize,
    c_out: usize,
    k: usize,
    stride: usize,
    pad: usize,
    dil: usize,
    bias: bool,
    device: &Device,
) -> Conv2d {
    Conv2dConfig::new([c_in, c_out], [k, k])
        .with_stride([stride, stride])
        .with_dilation([dil, dil])
        .with_padding(PaddingConfig2d::Explicit(pad, pad, pad, pad))
        .with_bias(bias)
        .init(device)
}

/// Upstream `refinement.conv2d(c_in, c_out)`: `Sequential(Conv2d 3×3 p1 no bias, BatchNorm2d,
/// LeakyReLU(0.2))` → keys `.0.weight`, `.1.*`.
fn conv_bn_lrelu(c_in: usize, c_out: usize, device: &Device) -> (Conv2d, BatchNorm) {
    (
        conv2d(c_in, c_out, 3, 1, 1, 1, false, device),
        BatchNormConfig::new(c_out).init(device),
    )
}

fn apply_conv_bn_lrelu(m: &(Conv2d, BatchNorm), x: Tensor<4>) -> Tensor<4> {
    conv2d_fused(&m.0, Some(&m.1), Activation::LeakyRelu(0.2), x)
}

/// Upstream `BasicConv_now` (2-D): conv (no bias) + BatchNorm2d + ReLU.
#[derive(Module, Debug)]
pub struct BasicConvNow {
    pub conv: Conv2d,
    pub bn: BatchNorm,
}

impl BasicConvNow {
    pub fn new(
        c_in: usize,
        c_out: usize,
        stride: usize,
        pad: usize,
        dil: usize,
        device: &Device,
    ) -> Self {
        Self {
            conv: conv2d(c_in, c_out, 3, stride, pad, dil, false, device),
            bn: BatchNormConfig::new(c_out).init(device),
        }
    }

    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        conv2d_fused(&self.conv, Some(&self.bn), Activation::Relu, x)
    }
}

/// Upstream `BasicConv_now(deconv=True)`: ConvTranspose2d k4 s2 p1 (no bias) + BN + ReLU.
#[derive(Module, Debug)]
pub struct BasicDeconvNow {
    pub conv: ConvTranspose2d,
    pub bn: BatchNorm,
}

impl BasicDeconvNow {
    pub fn new(c_in: usize, c_out: usize, device: &Device) -> Self {
        Self {
            conv: deconv_4x4_s2(c_in, c_out, device),
            bn: BatchNormConfig::new(c_out).init(device),
        }
    }

    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        conv_transpose2d_fused(&self.conv, Some(&self.bn), Activation::Relu, x)
    }
}

/// Upstream `Conv2x_now(c_in, c_out, deconv=True)` (concat): `conv1` = BasicDeconvNow (k4 s2 p1,
/// upsampling ×2), `cat(x, rem)`, `conv2` = BasicConv_now 2·c_out → c_out (3×3).
#[derive(Module, Debug)]
pub struct Conv2xNowUp {
    pub conv1: BasicDeconvNow,
    pub conv2: BasicConvNow,
}

impl Conv2xNowUp {
    pub fn new(c_in: usize, c_out: usize, device: &Device) -> Self {
        Self {
            conv1: BasicDeconvNow::new(c_in, c_out, device),
            conv2: BasicConvNow::new(2 * c_out, c_out, 1, 1, 1, device),
        }
    }

    pub fn forward(&self, x: Tensor<4>, rem: Tensor<4>) -> Tensor<4> {
        merge_with_skip(&self.conv2, self.conv1.forward(x), rem)
    }
}

/// Upstream `Conv2x_now(c_in, c_out, deconv=False)` (concat): `conv1` = BasicConv_now k3 s2 p1
/// (downsampling ×2), `cat(x, rem)`, `conv2` = BasicConv_now 2·c_out → c_out (3×3).
#[derive(Module, Debug)]
pub struct Conv2xNowDown {
    pub conv1: BasicConvNow,
    pub conv2: BasicConvNow,
}

impl Conv2xNowDown {
    pub fn new(c_in: usize, c_out: usize, device: &Device) -> Self {
        Self {
            conv1: BasicConvNow::new(c_in, c_out, 2, 1, 1, device),
            conv2: BasicConvNow::new(2 * c_out, c_out, 1, 1, 1, device),
        }
    }

    pub fn forward(&self, x: Tensor<4>, rem: Tensor<4>) -> Tensor<4> {
        merge_with_skip(&self.conv2, self.conv1.forward(x), rem)
    }
}

/// `Conv2x_now`'s second half: `conv2(cat(x, rem))` of the resampled `x` and the skip `rem`.
fn merge_with_skip(conv2: &BasicConvNow, x: Tensor<4>, rem: Tensor<4>) -> Tensor<4> {
    assert_eq!(
        x.dims(),
        rem.dims(),
        "Conv2x_now: shapes differ (H, W must be multiples of 16)"
    );
    conv2.forward(Tensor::cat(vec![x, rem], 1))
}

/// Upstream `Simple_UNet(C)`.
#[derive(Module, Debug)]
pub struct SimpleUnet {
    pub conv1a: BasicConvNow,
    pub conv2a: BasicConvNow,
    pub conv3a: BasicConvNow,
    pub conv4a: BasicConvNow,
    pub deconv4a: Conv2xNowUp,
    pub deconv3a: Conv2xNowUp,
    pub deconv2a: Conv2xNowUp,
    pub deconv1a: Conv2xNowUp,
    pub conv1b: Conv2xNowDown,
    pub conv2b: Conv2xNowDown,
    pub conv3b: Conv2xNowDown,
    pub conv4b: Conv2xNowDown,
    pub deconv4b: Conv2xNowUp,
    pub deconv3b: Conv2xNowUp,
    pub deconv2b: Conv2xNowUp,
    pub deconv1b: Conv2xNowUp,
}

impl SimpleUnet {
    pub fn new(c: usize, device: &Device) -> Self {
        Self {
            conv1a: BasicConvNow::new(c, 48, 2, 1, 1, device),
            conv2a: BasicConvNow::new(48, 64, 2, 1, 1, device),
            conv3a: BasicConvNow::new(64, 96, 2, 2, 2, device),
            conv4a: BasicConvNow::new(96, 128, 2, 2, 2, device),
            deconv4a: Conv2xNowUp::new(128, 96, device),
            deconv3a: Conv2xNowUp::new(96, 64, device),
            deconv2a: Conv2xNowUp::new(64, 48, device),
            deconv1a: Conv2xNowUp::new(48, 32, device),
            conv1b: Conv2xNowDown::new(32, 48, device),
            conv2b: Conv2xNowDown::new(48, 64, device),
            conv3b: Conv2xNowDown::new(64, 96, device),
            conv4b: Conv2xNowDown::new(96, 128, device),
            deconv4b: Conv2xNowUp::new(128, 96, device),
            deconv3b: Conv2xNowUp::new(96, 64, device),
            deconv2b: Conv2xNowUp::new(64, 48, device),
            deconv1b: Conv2xNowUp::new(48, c, device),
        }
    }

    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let rem0 = x.clone();
        let x = self.conv1a.forward(x);
        let rem1 = x.clone();
        let x = self.conv2a.forward(x);
        let rem2 = x.clone();
        let x = self.conv3a.forward(x);
        let rem3 = x.clone();
        let x = self.conv4a.forward(x);
        let rem4 = x.clone();

        let x = self.deconv4a.forward(x, rem3);
        let rem3 = x.clone();
        let x = self.deconv3a.forward(x, rem2);
        let rem2 = x.clone();
        let x = self.deconv2a.forward(x, rem1);
        let rem1 = x.clone();
        let x = self.deconv1a.forward(x, rem0);
        let rem0 = x.clone();

        let x = self.conv1b.forward(x, rem1);
        let rem1 = x.clone();
        let x = self.conv2b.forward(x, rem2);
        let rem2 = x.clone();
        let x = self.conv3b.forward(x, rem3);
        let rem3 = x.clone();
        let x = self.conv4b.forward(x, rem4);

        let x = self.deconv4b.forward(x, rem3);
        let x = self.deconv3b.forward(x, rem2);
        let x = self.deconv2b.forward(x, rem1);
        self.deconv1b.forward(x, rem0)
    }
}

/// Upstream `REMP` (field names = state-dict keys under `REMP.`).
#[derive(Module, Debug)]
pub struct Remp {
    pub conv1_mono: (Conv2d, BatchNorm),
    pub conv1_stereo: (Conv2d, BatchNorm),
    pub conv2_mono: (Conv2d, BatchNorm),
    pub conv2_stereo: (Conv2d, BatchNorm),
    pub conv_start: BasicConvNow,
    pub RefinementBlock: SimpleUnet,
    /// `Sequential(Conv1×1 32→64, ReLU, Conv1×1 64→32, Sigmoid)` (keys `.0`, `.2`).
    pub LFE: (Conv2d, Relu, Conv2d),
    /// `Sequential(Conv3×3 32→32, Conv3×3 32→64, ReLU, Conv3×3 64→32, Sigmoid)` (keys `.0`, `.1`, `.3`).
    pub LMC: (Conv2d, Conv2d, Relu, Conv2d),
    pub final_conv: Conv2d,
}

impl Remp {
    pub fn new(device: &Device) -> Self {
        let ch = 32;
        Self {
            conv1_mono: conv_bn_lrelu(6, 16, device),
            conv1_stereo: conv_bn_lrelu(6, 16, device),
            conv2_mono: conv_bn_lrelu(1, 16, device),
            conv2_stereo: conv_bn_lrelu(1, 16, device),
            conv_start: BasicConvNow::new(64, ch, 1, 2, 2, device),
            RefinementBlock: SimpleUnet::new(ch, device),
            LFE: (
                conv2d(ch, 2 * ch, 1, 1, 0, 1, true, device),
                Relu::new(),
                conv2d(2 * ch, ch, 1, 1, 0, 1, true, device),
            ),
            LMC: (
                conv2d(ch, ch, 3, 1, 1, 1, true, device),
                conv2d(ch, 2 * ch, 3, 1, 1, 1, true, device),
                Relu::new(),
                conv2d(2 * ch, ch, 3, 1, 1, 1, true, device),
            ),
            final_conv: conv2d(ch, 1, 3, 1, 1, 1, true, device),
        }
    }

    /// `disp_mono`, `disp_stereo`: `[B,1,H,W]` full-resolution disparities (`mono_up`, `disp_up`);
    /// `left`, `right`: normalised images `2·(img/255) - 1`. Returns
    /// `LeakyReLU(0.01)(disp_stereo + residual)` (upstream's return value, *not* the final
    /// disparity: Monster adds `disp_stereo` once more).
    pub fn forward(
        &self,
        disp_mono: Tensor<4>,
        disp_stereo: Tensor<4>,
        left: Tensor<4>,
        right: Tensor<4>,
    ) -> Tensor<4> {
        let flaw_mono = disp_warp(right.clone(), disp_mono.clone()) - left.clone();
        let flaw_stereo = disp_warp(right, disp_stereo.clone()) - left.clone();
        let ref_mono = apply_conv_bn_lrelu(
            &self.conv1_mono,
            Tensor::cat(vec![flaw_mono, left.clone()], 1),
        );
        let ref_stereo =
            apply_conv_bn_lrelu(&self.conv1_stereo, Tensor::cat(vec![flaw_stereo, left], 1));
        let d_mono = apply_conv_bn_lrelu(&self.conv2_mono, disp_mono);
        let d_stereo = apply_conv_bn_lrelu(&self.conv2_stereo, disp_stereo.clone());
        let x = Tensor::cat(vec![ref_mono, d_mono, ref_stereo, d_stereo], 1);
        let x = self.conv_start.forward(x);
        let x = self.RefinementBlock.forward(x);
        let low = sigmoid(conv2d_forward(
            &self.LFE.2,
            relu(conv2d_forward(
                &self.LFE.0,
                adaptive_avg_pool2d(x.clone(), [1, 1]),
            )),
        ));
        let motif = sigmoid(conv2d_forward(
            &self.LMC.3,
            relu(conv2d_forward(
                &self.LMC.1,
                conv2d_forward(&self.LMC.0, x.clone()),
            )),
        ));
        let x = motif.clone().neg().add_scalar(1.0) * low + motif * x;
        let x = conv2d_forward(&self.final_conv, x);
        leaky_relu(disp_stereo + x, 0.01)
    }
}

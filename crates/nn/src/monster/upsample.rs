//! Full-resolution upsampling of the 1/4 disparity (upstream `Monster.upsample_disp` and IGEV's
//! `context_upsample`), shared by the stereo and mono branches (the same `spx_2_gru`/`spx_gru`
//! weights).

use burn::module::Module;
use burn::nn::conv::{Conv2d, Conv2dConfig, ConvTranspose2d, ConvTranspose2dConfig};
use burn::nn::{BatchNorm, BatchNormConfig, PaddingConfig2d};
use burn::tensor::activation::softmax;
use burn::tensor::module::interpolate;
use burn::tensor::ops::{InterpolateMode, InterpolateOptions};
use burn::tensor::{Device, Tensor};

use crate::conv::{conv2d_fused, conv_transpose2d_forward, conv_transpose2d_fused, Activation};

/// Upstream `BasicConv` (2-D, no deconv): Conv2d (no bias) + BatchNorm2d (eval: running stats)
/// + LeakyReLU(0.01). Keys `conv.weight`, `bn.{weight,bias,running_mean,running_var}`.
#[derive(Module, Debug)]
pub struct BasicConv {
    pub conv: Conv2d,
    pub bn: BatchNorm,
}

impl BasicConv {
    /// 3×3, stride 1, padding 1 (the only use here).
    pub fn new(c_in: usize, c_out: usize, device: &Device) -> Self {
        Self {
            conv: Conv2dConfig::new([c_in, c_out], [3, 3])
                .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
                .with_bias(false)
                .init(device),
            bn: BatchNormConfig::new(c_out).init(device),
        }
    }

    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        conv2d_fused(&self.conv, Some(&self.bn), Activation::LeakyRelu(0.01), x)
    }
}

/// The ×2 upsampling of upstream's `BasicConv(deconv=True)` blocks: ConvTranspose2d k4 s2 p1
/// without bias.
pub(super) fn deconv_4x4_s2(c_in: usize, c_out: usize, device: &Device) -> ConvTranspose2d {
    ConvTranspose2dConfig::new([c_in, c_out], [4, 4])
        .with_stride([2, 2])
        .with_padding([1, 1])
        .with_bias(false)
        .init(device)
}

/// Upstream `BasicConv(deconv=True)`: ConvTranspose2d k4 s2 p1 (no bias) + BatchNorm2d + LeakyReLU(0.01).
#[derive(Module, Debug)]
pub struct BasicDeconv {
    pub conv: ConvTranspose2d,
    pub bn: BatchNorm,
}

impl BasicDeconv {
    pub fn new(c_in: usize, c_out: usize, device: &Device) -> Self {
        Self {
            conv: deconv_4x4_s2(c_in, c_out, device),
            bn: BatchNormConfig::new(c_out).init(device),
        }
    }

    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        conv_transpose2d_fused(&self.conv, Some(&self.bn), Activation::LeakyRelu(0.01), x)
    }
}

/// Upstream `Conv2x(c_in, c_out, deconv=True)` (2-D, concat, keep_concat): `conv1` = BasicDeconv
/// c_in→c_out, nearest-resized to `rem` if the shapes differ, `cat(x, rem)`, `conv2` = BasicConv
/// 2·c_out→2·c_out (3×3). Used as `spx_2_gru = Conv2x(32, 32, True)`.
#[derive(Module, Debug)]
pub struct Conv2x {
    pub conv1: BasicDeconv,
    pub conv2: BasicConv,
}

impl Conv2x {
    pub fn new(c_in: usize, c_out: usize, device: &Device) -> Self {
        Self {
            conv1: BasicDeconv::new(c_in, c_out, device),
            conv2: BasicConv::new(2 * c_out, 2 * c_out, device),
        }
    }

    pub fn forward(&self, x: Tensor<4>, rem: Tensor<4>) -> Tensor<4> {
        let mut x = self.conv1.forward(x);
        let [_, _, rh, rw] = rem.dims();
        let [_, _, xh, xw] = x.dims();
        if [xh, xw] != [rh, rw] {
            // F.interpolate(mode='nearest'): src = floor(dst · in/out) (burn's `Nearest`).
            x = interpolate(
                x,
                InterpolateOptions::new(InterpolateMode::Nearest)
                    .with_align_corners(false)
                    .with_output_size([rh, rw]),
            );
        }
        self.conv2.forward(Tensor::cat(vec![x, rem], 1))
    }
}

/// The `spx_gru` head: `nn.Sequential(ConvTranspose2d(64, 9, k4, s2, p1))` (bias). Stored in a
/// `Vec` of one element so that the key is `spx_gru.0.{weight,bias}`.
pub fn spx_gru_init(device: &Device) -> Vec<ConvTranspose2d> {
    vec![ConvTranspose2dConfig::new([64, 9], [4, 4])
        .with_stride([2, 2])
        .with_padding([1, 1])
        .init(device)]
}

/// IGEV's `context_upsample(disp_low, up_weights)`: `disp_low` `[B, 1, h, w]` (the caller scales
/// it, upstream passes `disp·4`), `up_weights` `[B, 9, 4h, 4w]` (softmaxed). The 3×3 neighbourhood
/// of every low-resolution pixel (zero padding, tap order `ky·3 + kx`, like `F.unfold(·, 3, 1, 1)`)
/// is nearest-upsampled ×4 and blended with the weights. Returns `[B, 1, 4h, 4w]` (upstream
/// returns `[B, 4h, 4w]` and its callers `unsqueeze(1)`).
pub fn context_upsample(disp_low: Tensor<4>, up_weights: Tensor<4>) -> Tensor<4> {
    let [b, c, h, w] = disp_low.dims();
    assert_eq!(c, 1, "context_upsample: one channel");
    let [_, k, hu, wu] = up_weights.dims();
    assert_eq!(k, 9, "context_upsample: 9 weights");
    let (fy, fx) = (hu / h, wu / w);
    assert_eq!(
        [hu, wu],
        [h * fy, w * fx],
        "context_upsample: integer factor"
    );
    let padded = Tensor::<4>::zeros([b, 1, h + 2, w + 2], &disp_low.device())
        .slice_assign([0..b, 0..1, 1..h + 1, 1..w + 1], disp_low);
    let mut taps = Vec::with_capacity(9);
    for ky in 0..3 {
        for kx in 0..3 {
            taps.push(padded.clone().slice([0..b, 0..1, ky..ky + h, kx..kx + w]));
        }
    }
    let unfolded = Tensor::cat(taps, 1); // [B, 9, h, w]
                                         // Nearest ×f (exact integer factor): repeat every pixel f×f times.
    let up = unfolded
        .reshape([b, 9, h, 1, w, 1])
        .expand([b, 9, h, fy, w, fx])
        .reshape([b, 9, hu, wu]);
    (up * up_weights).sum_dim(1)
}

/// Upstream `Monster.upsample_disp(disp, mask_feat_4, stem_2x)`: `spx_2_gru(mask_feat_4, stem_2x)`
/// → `spx_gru` → softmax over the 9 channels → `context_upsample(disp·4, ·)`. `disp` `[B,1,h,w]`,
/// `mask_feat_4` `[B,32,h,w]`, `stem_2x` `[B,32,2h,2w]` → `[B,1,4h,4w]` (in full-resolution pixels).
pub fn upsample_disp(
    spx_2_gru: &Conv2x,
    spx_gru: &ConvTranspose2d,
    disp: Tensor<4>,
    mask_feat_4: Tensor<4>,
    stem_2x: Tensor<4>,
) -> Tensor<4> {
    let xspx = spx_2_gru.forward(mask_feat_4, stem_2x);
    let spx_pred = softmax(conv_transpose2d_forward(spx_gru, xspx), 1);
    context_upsample(disp.mul_scalar(4.0), spx_pred)
}

/// Upstream `Monster.freeze_bn()` for a sub-tree: every BatchNorm (2-D) switches to running
/// statistics (its `training` flag is disabled) while the parameters stay trainable. Training
/// upstream calls `model.train(); model.freeze_bn()`, so `spx_2_gru` and `REMP` (whose norms are
/// all BatchNorm2d) always use running statistics. Note: this disables **every** module-owned
/// training flag in the tree (there are no dropouts here). Do not apply it to the 3-D
/// aggregation (BatchNorm3d keeps training upstream).
pub fn freeze_bn<M: Module>(module: M) -> M {
    struct Mapper;
    impl burn::module::ModuleMapper for Mapper {
        fn map_flag(
            &mut self,
            flag: burn::module::Param<burn::module::Flag>,
        ) -> burn::module::Param<burn::module::Flag> {
            flag.with_value(false)
        }
    }
    module.map(&mut Mapper)
}

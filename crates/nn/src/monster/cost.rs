//! Cost volume, 3-D aggregation and initial disparity (design §2.3): `build_gwc_volume`,
//! `corr_stem` + `corr_feature_att`, the 3-D `hourglass` (`cost_agg`), `classifier` + softmax +
//! disparity regression, and the train-only superpixel head `spx_4 → spx_2 → spx`.
//!
//! Field names mirror the upstream state-dict keys: [`CostAggregation`] holds the root-level
//! modules `corr_stem`, `corr_feature_att`, `cost_agg`, `classifier`; [`SpxHead`] holds
//! `spx_4`, `spx_2`, `spx`. Both load from a full checkpoint with an **empty** key prefix.
//!
//! BatchNorm: every BN here runs in inference mode (running statistics) unless the layer is on an
//! autodiff device with training enabled (burn's rule). Upstream training keeps the BatchNorm3d
//! of `corr_stem`/`cost_agg` in train mode and freezes only BatchNorm2d (the FeatureAtt BNs).
//!
//! Shapes (h = H/4, w = W/4, D = max_disp/4, a multiple of 8):
//! gwc / geo volume `[B, 8, D, h, w]`; `init_disp` `[B, 1, h, w]` (1/4-resolution pixels).

use burn::module::Module;
use burn::nn::conv::{
    Conv2d, Conv3d, Conv3dConfig, ConvTranspose2d, ConvTranspose2dConfig, ConvTranspose3d,
    ConvTranspose3dConfig,
};
use burn::nn::{BatchNorm, BatchNormConfig, PaddingConfig3d};
use burn::tensor::activation::softmax;
use burn::tensor::ops::PadMode;
use burn::tensor::{Device, Tensor};

use crate::activation::{leaky_relu, sigmoid};
use crate::batch_norm::batch_norm;
use crate::conv::{
    conv2d_forward, conv2d_fused, conv3d_forward, conv_transpose2d_forward,
    conv_transpose3d_forward, Activation,
};

use super::features::{
    conv2d, conv_in_block, conv_in_block_forward, instance_norm, BasicConvIn, ConvInBlock, Window,
    LEAKY_SLOPE,
};

/// Number of channel groups of the group-wise correlation volume.
pub const GWC_GROUPS: usize = 8;

/// Group-wise correlation volume (`build_gwc_volume`): `left`, `right` `[B, C, h, w]` →
/// `[B, groups, max_disp, h, w]` with `vol[:, g, d, :, x] = mean_{c∈g}(L[c, :, x]·R[c, :, x−d])` for
/// x ≥ d and 0 for x < d. `max_disp` is D (already divided by 4).
pub fn build_gwc_volume(
    left: Tensor<4>,
    right: Tensor<4>,
    max_disp: usize,
    groups: usize,
) -> Tensor<5> {
    let [b, c, h, w] = left.dims();
    assert_eq!(
        c % groups,
        0,
        "channels {c} not divisible by {groups} groups"
    );
    let cg = c / groups;
    let mut slices = Vec::with_capacity(max_disp);
    for d in 0..max_disp {
        let slice: Tensor<4> = if d == 0 {
            group_mean(left.clone() * right.clone(), b, groups, cg, h, w)
        } else if d >= w {
            Tensor::zeros([b, groups, h, w], &left.device())
        } else {
            let l = left.clone().narrow(3, d, w - d);
            let r = right.clone().narrow(3, 0, w - d);
            group_mean(l * r, b, groups, cg, h, w - d)
                .pad([(0, 0), (0, 0), (0, 0), (d, 0)], PadMode::Constant(0.0))
        };
        slices.push(slice);
    }
    Tensor::stack(slices, 2)
}

fn group_mean(
    prod: Tensor<4>,
    b: usize,
    groups: usize,
    cg: usize,
    h: usize,
    w: usize,
) -> Tensor<4> {
    let p: Tensor<5> = prod.reshape([b, groups, cg, h, w]);
    p.mean_dim(2).reshape([b, groups, h, w])
}

/// `disparity_regression`: probabilities `[B, D, h, w]` → `Σ_d p_d·d`, `[B, 1, h, w]`.
pub fn disparity_regression(prob: Tensor<4>) -> Tensor<4> {
    let [_, d, _, _] = prob.dims();
    let values: Vec<f32> = (0..d).map(|i| i as f32).collect();
    let values = Tensor::<1>::from_floats(values.as_slice(), &prob.device()).reshape([1, d, 1, 1]);
    (prob * values).sum_dim(1)
}

fn bn(c: usize, device: &Device) -> BatchNorm {
    BatchNormConfig::new(c).init(device)
}

/// `BasicConv` 2-D (no deconv) with BatchNorm2d and LeakyReLU(0.01). Keys `conv.weight`, `bn.*`.
#[derive(Module, Debug)]
pub struct BasicConv2d {
    pub conv: Conv2d,
    pub bn: BatchNorm,
}

impl BasicConv2d {
    pub fn new(c_in: usize, c_out: usize, window: Window, device: &Device) -> Self {
        Self {
            conv: window.conv2d(c_in, c_out, false, device),
            bn: bn(c_out, device),
        }
    }

    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        conv2d_fused(
            &self.conv,
            Some(&self.bn),
            Activation::LeakyRelu(LEAKY_SLOPE),
            x,
        )
    }
}

/// `BasicConv(is_3d=True)`: Conv3d (no bias) → BatchNorm3d → LeakyReLU(0.01).
#[derive(Module, Debug)]
pub struct BasicConv3d {
    pub conv: Conv3d,
    pub bn: BatchNorm,
}

impl BasicConv3d {
    pub fn new(c_in: usize, c_out: usize, window: Window, device: &Device) -> Self {
        let Window {
            size: k,
            stride,
            pad,
        } = window;
        let conv = Conv3dConfig::new([c_in, c_out], [k, k, k])
            .with_stride([stride, stride, stride])
            .with_padding(PaddingConfig3d::Explicit(pad, pad, pad))
            .with_bias(false)
            .init(device);
        Self {
            conv,
            bn: bn(c_out, device),
        }
    }

    pub fn forward(&self, x: Tensor<5>) -> Tensor<5> {
        leaky_relu(
            batch_norm(&self.bn, conv3d_forward(&self.conv, x)),
            LEAKY_SLOPE,
        )
    }
}

/// `BasicConv(deconv=True, is_3d=True, kernel 4, stride 2, padding 1)`: ConvTranspose3d (no bias),
/// then BatchNorm3d + LeakyReLU when `bn_relu`. `conv1_up` upstream has `bn=False, relu=False` but
/// still owns (unused) BN parameters in the state dict, so the BN is always present.
#[derive(Module, Debug)]
pub struct BasicDeconv3d {
    pub conv: ConvTranspose3d,
    pub bn: BatchNorm,
    pub bn_relu: bool,
}

impl BasicDeconv3d {
    pub fn new(c_in: usize, c_out: usize, bn_relu: bool, device: &Device) -> Self {
        let conv = ConvTranspose3dConfig::new([c_in, c_out], [4, 4, 4])
            .with_stride([2, 2, 2])
            .with_padding([1, 1, 1])
            .with_bias(false)
            .init(device);
        Self {
            conv,
            bn: bn(c_out, device),
            bn_relu,
        }
    }

    /// `[B, c_in, D, H, W]` → `[B, c_out, 2D, 2H, 2W]`.
    pub fn forward(&self, x: Tensor<5>) -> Tensor<5> {
        let y = conv_transpose3d_forward(&self.conv, x);
        if self.bn_relu {
            leaky_relu(batch_norm(&self.bn, y), LEAKY_SLOPE)
        } else {
            y
        }
    }
}

/// `FeatureAtt(cv_c, feat_c)`: `cv · sigmoid(Conv1×1(feat_c/2→cv_c)(BasicConv2d(feat_c→feat_c/2, 1×1)(feat)))`
/// broadcast over D. Keys `feat_att.0.conv.weight`, `feat_att.0.bn.*`, `feat_att.1.{weight,bias}`.
#[derive(Module, Debug)]
pub struct FeatureAtt {
    pub feat_att: (BasicConv2d, Conv2d),
}

impl FeatureAtt {
    pub fn new(cv_c: usize, feat_c: usize, device: &Device) -> Self {
        Self {
            feat_att: (
                BasicConv2d::new(feat_c, feat_c / 2, Window::new(1, 1, 0), device),
                conv2d(feat_c / 2, cv_c, 1, 1, 0, true, device),
            ),
        }
    }

    /// `cv` `[B, cv_c, D, h, w]`, `feat` `[B, feat_c, h, w]` → `[B, cv_c, D, h, w]`.
    pub fn forward(&self, cv: Tensor<5>, feat: Tensor<4>) -> Tensor<5> {
        let att = conv2d_forward(&self.feat_att.1, self.feat_att.0.forward(feat));
        let att: Tensor<5> = sigmoid(att).unsqueeze_dim(2);
        cv * att
    }
}

type Pair3d = (BasicConv3d, BasicConv3d);
type Triple3d = (BasicConv3d, BasicConv3d, BasicConv3d);

/// The 3-D `hourglass(8)` (`cost_agg`).
#[derive(Module, Debug)]
pub struct Hourglass {
    pub conv1: Pair3d,
    pub conv2: Pair3d,
    pub conv3: Pair3d,
    pub conv3_up: BasicDeconv3d,
    pub conv2_up: BasicDeconv3d,
    pub conv1_up: BasicDeconv3d,
    pub agg_0: Triple3d,
    pub agg_1: Triple3d,
    pub feature_att_8: FeatureAtt,
    pub feature_att_16: FeatureAtt,
    pub feature_att_32: FeatureAtt,
    pub feature_att_up_16: FeatureAtt,
    pub feature_att_up_8: FeatureAtt,
}

fn pair3d(c_in: usize, c_out: usize, device: &Device) -> Pair3d {
    (
        BasicConv3d::new(c_in, c_out, Window::new(3, 2, 1), device),
        BasicConv3d::new(c_out, c_out, Window::new(3, 1, 1), device),
    )
}

fn triple3d(c_in: usize, c_out: usize, device: &Device) -> Triple3d {
    (
        BasicConv3d::new(c_in, c_out, Window::new(1, 1, 0), device),
        BasicConv3d::new(c_out, c_out, Window::new(3, 1, 1), device),
        BasicConv3d::new(c_out, c_out, Window::new(3, 1, 1), device),
    )
}

impl Hourglass {
    /// `c` = input channels (8 upstream).
    pub fn new(c: usize, device: &Device) -> Self {
        Self {
            conv1: pair3d(c, 2 * c, device),
            conv2: pair3d(2 * c, 4 * c, device),
            conv3: pair3d(4 * c, 6 * c, device),
            conv3_up: BasicDeconv3d::new(6 * c, 4 * c, true, device),
            conv2_up: BasicDeconv3d::new(4 * c, 2 * c, true, device),
            conv1_up: BasicDeconv3d::new(2 * c, 8, false, device),
            agg_0: triple3d(8 * c, 4 * c, device),
            agg_1: triple3d(4 * c, 2 * c, device),
            feature_att_8: FeatureAtt::new(2 * c, 64, device),
            feature_att_16: FeatureAtt::new(4 * c, 192, device),
            feature_att_32: FeatureAtt::new(6 * c, 160, device),
            feature_att_up_16: FeatureAtt::new(4 * c, 192, device),
            feature_att_up_8: FeatureAtt::new(2 * c, 64, device),
        }
    }

    /// `x` `[B, c, D, h, w]` and the stereo `features` (`[96×h×w, 64×H/8, 192×H/16, 160×H/32]`; only
    /// 1..=3 are used) → geometry encoding volume `[B, 8, D, h, w]`.
    pub fn forward(&self, x: Tensor<5>, features: &[Tensor<4>; 4]) -> Tensor<5> {
        let conv1 = self.conv1.1.forward(self.conv1.0.forward(x));
        let conv1 = self.feature_att_8.forward(conv1, features[1].clone());
        let conv2 = self.conv2.1.forward(self.conv2.0.forward(conv1.clone()));
        let conv2 = self.feature_att_16.forward(conv2, features[2].clone());
        let conv3 = self.conv3.1.forward(self.conv3.0.forward(conv2.clone()));
        let conv3 = self.feature_att_32.forward(conv3, features[3].clone());

        let up = (&self.conv3_up, &self.agg_0, &self.feature_att_up_16);
        let conv2 = up_and_merge(up, conv3, conv2, features[2].clone());
        let up = (&self.conv2_up, &self.agg_1, &self.feature_att_up_8);
        let conv1 = up_and_merge(up, conv2, conv1, features[1].clone());
        self.conv1_up.forward(conv1)
    }
}

/// One step up the hourglass: `x` upsampled by `up`, concatenated with the `skip` of the way
/// down, aggregated by `agg` and weighted by `att` from the stereo `feature`.
fn up_and_merge(
    (up, agg, att): (&BasicDeconv3d, &Triple3d, &FeatureAtt),
    x: Tensor<5>,
    skip: Tensor<5>,
    feature: Tensor<4>,
) -> Tensor<5> {
    let merged = Tensor::cat(vec![up.forward(x), skip], 1);
    let merged = agg.2.forward(agg.1.forward(agg.0.forward(merged)));
    att.forward(merged, feature)
}

/// Output of [`CostAggregation::forward`].
#[derive(Debug, Clone)]
pub struct CostOutput {
    /// Geometry encoding volume `[B, 8, D, h, w]` (input of the Combined Geo Encoding Volume).
    pub geo_volume: Tensor<5>,
    /// Initial disparity (soft-argmin over D) `[B, 1, h, w]`, 1/4-resolution pixels.
    pub init_disp: Tensor<4>,
}

/// The root-level cost modules of the upstream `Monster`: `corr_stem`, `corr_feature_att`,
/// `cost_agg`, `classifier`.
#[derive(Module, Debug)]
pub struct CostAggregation {
    /// `BasicConv(8, 8, is_3d, k3, p1)` with BatchNorm3d + LeakyReLU.
    pub corr_stem: BasicConv3d,
    /// `FeatureAtt(8, 96)` on `features[0]`.
    pub corr_feature_att: FeatureAtt,
    /// `hourglass(8)`.
    pub cost_agg: Hourglass,
    /// `Conv3d(8, 1, 3, 1, 1, bias=False)`.
    pub classifier: Conv3d,
}

impl CostAggregation {
    pub fn new(device: &Device) -> Self {
        Self {
            corr_stem: BasicConv3d::new(GWC_GROUPS, GWC_GROUPS, Window::new(3, 1, 1), device),
            corr_feature_att: FeatureAtt::new(GWC_GROUPS, 96, device),
            cost_agg: Hourglass::new(GWC_GROUPS, device),
            classifier: Conv3dConfig::new([GWC_GROUPS, 1], [3, 3, 3])
                .with_padding(PaddingConfig3d::Explicit(1, 1, 1))
                .with_bias(false)
                .init(device),
        }
    }

    /// `corr_stem(gwc)` then `corr_feature_att(·, features[0])` (`[B, 8, D, h, w]`).
    pub fn stem(&self, gwc_volume: Tensor<5>, features0: Tensor<4>) -> Tensor<5> {
        self.corr_feature_att
            .forward(self.corr_stem.forward(gwc_volume), features0)
    }

    /// Classifier logits `[B, D, h, w]` of a geometry encoding volume.
    pub fn logits(&self, geo_volume: Tensor<5>) -> Tensor<4> {
        let l: Tensor<5> = conv3d_forward(&self.classifier, geo_volume);
        l.squeeze_dim(1)
    }

    /// Full path: matching features `[B, 96, h, w]` (left, right), the left stereo features (see
    /// [`Hourglass::forward`]) and D = max_disp/4 (a multiple of 8).
    pub fn forward(
        &self,
        match_left: Tensor<4>,
        match_right: Tensor<4>,
        features_left: &[Tensor<4>; 4],
        d: usize,
    ) -> CostOutput {
        let gwc = build_gwc_volume(match_left, match_right, d, GWC_GROUPS);
        let vol = self.stem(gwc, features_left[0].clone());
        let geo_volume = self.cost_agg.forward(vol, features_left);
        let prob = softmax(self.logits(geo_volume.clone()), 1);
        let init_disp = disparity_regression(prob);
        CostOutput {
            geo_volume,
            init_disp,
        }
    }
}

/// `Conv2x_IN(24, 32, deconv=True)` (`spx_2`): `conv1` = ConvT 24→32 k4 s2 p1 (no bias) + IN +
/// LeakyReLU; cat with `stem_2x`; `conv2` = `BasicConv_IN(64, 64, 3, 1, 1)`.
#[derive(Module, Debug)]
pub struct Conv2xIn {
    pub conv1: BasicDeconvIn,
    pub conv2: BasicConvIn,
}

/// `BasicConv_IN(deconv=True)` 2-D, kernel 4, stride 2, padding 1. Key `conv.weight`.
#[derive(Module, Debug)]
pub struct BasicDeconvIn {
    pub conv: ConvTranspose2d,
}

impl BasicDeconvIn {
    pub fn new(c_in: usize, c_out: usize, device: &Device) -> Self {
        let conv = ConvTranspose2dConfig::new([c_in, c_out], [4, 4])
            .with_stride([2, 2])
            .with_padding([1, 1])
            .with_bias(false)
            .init(device);
        Self { conv }
    }

    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        leaky_relu(
            instance_norm(conv_transpose2d_forward(&self.conv, x)),
            LEAKY_SLOPE,
        )
    }
}

impl Conv2xIn {
    pub fn new(c_in: usize, c_out: usize, device: &Device) -> Self {
        Self {
            conv1: BasicDeconvIn::new(c_in, c_out, device),
            conv2: BasicConvIn::new(2 * c_out, 2 * c_out, Window::new(3, 1, 1), device),
        }
    }

    /// `x` `[B, c_in, h, w]`, `rem` `[B, c_out, 2h, 2w]` → `[B, 2·c_out, 2h, 2w]`. (The upstream
    /// nearest-resize on a shape mismatch cannot happen for inputs that are multiples of 32.)
    pub fn forward(&self, x: Tensor<4>, rem: Tensor<4>) -> Tensor<4> {
        let x = self.conv1.forward(x);
        assert_eq!(
            x.dims(),
            rem.dims(),
            "Conv2x_IN: upsampled shape differs from the skip"
        );
        self.conv2.forward(Tensor::cat(vec![x, rem], 1))
    }
}

/// Train-only superpixel head for `init_disp_up`: root keys `spx_4`, `spx_2`, `spx`.
#[derive(Module, Debug)]
pub struct SpxHead {
    /// `Sequential(BasicConv_IN(96, 24), Conv2d(24, 24, bias=False), IN, ReLU)`.
    pub spx_4: ConvInBlock,
    /// `Conv2x_IN(24, 32, deconv=True)`.
    pub spx_2: Conv2xIn,
    /// `Sequential(ConvTranspose2d(64, 9, 4, 2, 1))` with bias.
    pub spx: [ConvTranspose2d; 1],
}

impl SpxHead {
    pub fn new(device: &Device) -> Self {
        Self {
            spx_4: conv_in_block(96, 24, 1, device),
            spx_2: Conv2xIn::new(24, 32, device),
            spx: [ConvTranspose2dConfig::new([64, 9], [4, 4])
                .with_stride([2, 2])
                .with_padding([1, 1])
                .init(device)],
        }
    }

    /// `features0` `[B, 96, h, w]` (= `cat(f4, stem_4)`), `stem_2x` `[B, 32, H/2, W/2]` → softmaxed
    /// context-upsampling weights `[B, 9, H, W]` (for `context_upsample(init_disp·4, ·)`).
    pub fn forward(&self, features0: Tensor<4>, stem_2x: Tensor<4>) -> Tensor<4> {
        let x = conv_in_block_forward(&self.spx_4, features0);
        let x = self.spx_2.forward(x, stem_2x);
        softmax(conv_transpose2d_forward(&self.spx[0], x), 1)
    }
}

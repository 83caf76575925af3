//! The two DPT heads of the mono branch (`monsterpp.md` §2.1 step 3): `mono_decoder` (the
//! Depth-Anything-V2 `DPTHead`, → `depth_mono`) and `feat_decoder` (`DPTHead_decoder`, → the four
//! feature paths). Field names mirror the PyTorch keys (`projects.N`, `resize_layers.{0,1,3}`,
//! `scratch.layerN_rn`, `scratch.refinenetN.resConfUnit{1,2}.conv{1,2}`, `scratch.output_conv*`).

#![allow(non_snake_case)]

use burn::module::{Module, Param};
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::nn::{Initializer, PaddingConfig2d};
use burn::tensor::module::{conv2d, conv_transpose2d};
use burn::tensor::ops::{ConvOptions, ConvTransposeOptions};
use burn::tensor::{Device, Tensor};

use crate::activation::relu;
use crate::config::DptConfig;
use crate::conv::{
    conv2d_forward, conv2d_fused, conv2d_with, conv_transpose2d_with, Activation, Geometry,
    TransposeGeometry,
};
use crate::cpu_mode::on_cpu_inference;
use crate::monster::vit::VitFeatures;
use crate::resize::resize_bilinear;

fn conv(c_in: usize, c_out: usize, k: usize, bias: bool, device: &Device) -> Conv2d {
    Conv2dConfig::new([c_in, c_out], [k, k])
        .with_padding(PaddingConfig2d::Explicit(k / 2, k / 2, k / 2, k / 2))
        .with_bias(bias)
        .init(device)
}

/// One entry of `resize_layers`: ConvTranspose2d (k = s, p 0; levels 0 and 1) or Conv2d 3×3 s2 p1
/// (level 3). Weight layout as in PyTorch (`[c_in, c_out, k, k]` for the transposed conv).
#[derive(Module, Debug)]
pub struct ResizeLayer {
    /// Kernel.
    pub weight: Param<Tensor<4>>,
    /// Bias.
    pub bias: Param<Tensor<1>>,
    transposed: bool,
    stride: usize,
    padding: usize,
}

impl ResizeLayer {
    fn up(c: usize, k: usize, device: &Device) -> Self {
        let fan = c * k * k;
        let b = 1.0 / (fan as f64).sqrt();
        Self {
            weight: Initializer::Uniform { min: -b, max: b }.init([c, c, k, k], device),
            bias: Initializer::Uniform { min: -b, max: b }.init([c], device),
            transposed: true,
            stride: k,
            padding: 0,
        }
    }

    fn down(c: usize, device: &Device) -> Self {
        let fan = c * 9;
        let b = 1.0 / (fan as f64).sqrt();
        Self {
            weight: Initializer::Uniform { min: -b, max: b }.init([c, c, 3, 3], device),
            bias: Initializer::Uniform { min: -b, max: b }.init([c], device),
            transposed: false,
            stride: 2,
            padding: 1,
        }
    }

    /// Applies the layer.
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let (s, p) = (self.stride, self.padding);
        let [_, _, k, _] = self.weight.dims();
        let fast = on_cpu_inference(&x);
        let (weight, bias) = (self.weight.val(), Some(self.bias.val()));
        match (self.transposed, fast) {
            (true, true) => {
                let geometry = TransposeGeometry {
                    kernel: [k, k],
                    stride: [s, s],
                    padding: [p, p],
                    dilation: [1, 1],
                    padding_out: [0, 0],
                };
                conv_transpose2d_with(x, weight, bias, geometry, None, Activation::Identity)
            }
            (false, true) => {
                let geometry = Geometry {
                    kernel: [k, k],
                    stride: [s, s],
                    padding: [p; 4],
                    dilation: [1, 1],
                };
                conv2d_with(x, weight, bias, geometry, None, Activation::Identity)
            }
            (true, false) => conv_transpose2d(
                x,
                weight,
                bias,
                ConvTransposeOptions::new([s, s], [p, p], [0, 0], [1, 1], 1),
            ),
            (false, false) => conv2d(x, weight, bias, ConvOptions::new([s, s], [p, p], [1, 1], 1)),
        }
    }
}

/// `x + conv2(relu(conv1(relu(x))))`, 3×3 convs with bias, no BN.
#[derive(Module, Debug)]
pub struct ResidualConvUnit {
    /// First 3×3 conv.
    pub conv1: Conv2d,
    /// Second 3×3 conv.
    pub conv2: Conv2d,
}

impl ResidualConvUnit {
    fn new(f: usize, device: &Device) -> Self {
        Self {
            conv1: conv(f, f, 3, true, device),
            conv2: conv(f, f, 3, true, device),
        }
    }

    /// Applies the unit.
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let out = conv2d_forward(
            &self.conv2,
            conv2d_fused(&self.conv1, None, Activation::Relu, relu(x.clone())),
        );
        out + x
    }
}

/// `FeatureFusionBlock`: out = x0 (+ RCU1(x1)); RCU2; bilinear (align_corners = True) resize;
/// 1×1 out_conv.
#[derive(Module, Debug)]
pub struct FeatureFusionBlock {
    /// 1×1 conv with bias.
    pub out_conv: Conv2d,
    /// Applied to the skip input.
    pub resConfUnit1: ResidualConvUnit,
    /// Applied after the sum.
    pub resConfUnit2: ResidualConvUnit,
}

impl FeatureFusionBlock {
    fn new(f: usize, device: &Device) -> Self {
        Self {
            out_conv: conv(f, f, 1, true, device),
            resConfUnit1: ResidualConvUnit::new(f, device),
            resConfUnit2: ResidualConvUnit::new(f, device),
        }
    }

    /// `size = None` means `scale_factor = 2`.
    pub fn forward(
        &self,
        x0: Tensor<4>,
        x1: Option<Tensor<4>>,
        size: Option<[usize; 2]>,
    ) -> Tensor<4> {
        let mut out = x0;
        if let Some(x1) = x1 {
            out = out + self.resConfUnit1.forward(x1);
        }
        let out = self.resConfUnit2.forward(out);
        let [_, _, h, w] = out.dims();
        let size = size.unwrap_or([2 * h, 2 * w]);
        conv2d_forward(&self.out_conv, resize_bilinear(out, size, true))
    }
}

/// `scratch`: the `layerN_rn` convs, the fusion blocks and (depth head only) the output convs.
#[derive(Module, Debug)]
pub struct Scratch {
    /// 3×3 oc[0]→F, no bias.
    pub layer1_rn: Conv2d,
    /// 3×3 oc[1]→F, no bias.
    pub layer2_rn: Conv2d,
    /// 3×3 oc[2]→F, no bias.
    pub layer3_rn: Conv2d,
    /// 3×3 oc[3]→F, no bias.
    pub layer4_rn: Conv2d,
    /// Fusion at 1/4 (→ ×2).
    pub refinenet1: FeatureFusionBlock,
    /// Fusion at 1/8.
    pub refinenet2: FeatureFusionBlock,
    /// Fusion at 1/16.
    pub refinenet3: FeatureFusionBlock,
    /// Fusion at 1/32.
    pub refinenet4: FeatureFusionBlock,
    /// 3×3 F→F/2 (depth head only).
    pub output_conv1: Option<Conv2d>,
    /// `[3×3 F/2→32, ReLU, 1×1 32→1, ReLU, Identity]` (depth head only).
    pub output_conv2: Option<Vec<Option<Conv2d>>>,
}

/// Shared skeleton of both heads.
#[derive(Module, Debug)]
pub struct DptHead {
    /// 1×1 E→oc[i] with bias.
    pub projects: Vec<Conv2d>,
    /// `[ConvT k4 s4, ConvT k2 s2, Identity, Conv3×3 s2 p1]`.
    pub resize_layers: Vec<Option<ResizeLayer>>,
    /// Fusion part.
    pub scratch: Scratch,
}

impl DptHead {
    /// `with_output`: the depth head (`DPTHead`, with output convs); otherwise `DPTHead_decoder`.
    pub fn new(embed_dim: usize, cfg: &DptConfig, with_output: bool, device: &Device) -> Self {
        let oc = cfg.out_channels;
        let f = cfg.features;
        let projects = oc
            .iter()
            .map(|&c| conv(embed_dim, c, 1, true, device))
            .collect();
        let resize_layers = vec![
            Some(ResizeLayer::up(oc[0], 4, device)),
            Some(ResizeLayer::up(oc[1], 2, device)),
            None,
            Some(ResizeLayer::down(oc[3], device)),
        ];
        let scratch = Scratch {
            layer1_rn: conv(oc[0], f, 3, false, device),
            layer2_rn: conv(oc[1], f, 3, false, device),
            layer3_rn: conv(oc[2], f, 3, false, device),
            layer4_rn: conv(oc[3], f, 3, false, device),
            refinenet1: FeatureFusionBlock::new(f, device),
            refinenet2: FeatureFusionBlock::new(f, device),
            refinenet3: FeatureFusionBlock::new(f, device),
            refinenet4: FeatureFusionBlock::new(f, device),
            output_conv1: with_output.then(|| conv(f, f / 2, 3, true, device)),
            output_conv2: with_output.then(|| {
                vec![
                    Some(conv(f / 2, 32, 3, true, device)),
                    None,
                    Some(conv(32, 1, 1, true, device)),
                    None,
                    None,
                ]
            }),
        };
        Self {
            projects,
            resize_layers,
            scratch,
        }
    }

    /// Tokens → per level B×E×gh×gw → project → resize → `layerN_rn`: [l1, l2, l3, l4].
    fn levels(&self, feats: &VitFeatures) -> Vec<Tensor<4>> {
        let (gh, gw) = feats.grid;
        let rn = [
            &self.scratch.layer1_rn,
            &self.scratch.layer2_rn,
            &self.scratch.layer3_rn,
            &self.scratch.layer4_rn,
        ];
        feats
            .tokens
            .iter()
            .enumerate()
            .map(|(i, t)| {
                let [b, n, e] = t.dims();
                debug_assert_eq!(n, gh * gw);
                let x = t.clone().swap_dims(1, 2).reshape([b, e, gh, gw]);
                let x = conv2d_forward(&self.projects[i], x);
                let x = match &self.resize_layers[i] {
                    Some(layer) => layer.forward(x),
                    None => x,
                };
                rn[i].forward(x)
            })
            .collect()
    }

    /// `DPTHead.forward` + MonSter's post-processing: ReLU, then bilinear (align_corners = False)
    /// to `out_size` (the original H×W) → `depth_mono` B×1×H×W. Needs the output convs.
    pub fn forward_depth(&self, feats: &VitFeatures, out_size: [usize; 2]) -> Tensor<4> {
        let l = self.levels(feats);
        let s = &self.scratch;
        let size = |t: &Tensor<4>| {
            let d = t.dims();
            [d[2], d[3]]
        };
        let p4 = s.refinenet4.forward(l[3].clone(), None, Some(size(&l[2])));
        let p3 = s
            .refinenet3
            .forward(p4, Some(l[2].clone()), Some(size(&l[1])));
        let p2 = s
            .refinenet2
            .forward(p3, Some(l[1].clone()), Some(size(&l[0])));
        let p1 = s.refinenet1.forward(p2, Some(l[0].clone()), None);
        let oc1 = s
            .output_conv1
            .as_ref()
            .expect("forward_depth needs the depth head (output_conv1)");
        let oc2 = s
            .output_conv2
            .as_ref()
            .expect("forward_depth needs the depth head (output_conv2)");
        let out = conv2d_forward(oc1, p1);
        let (gh, gw) = feats.grid;
        let out = resize_bilinear(out, [gh * 14, gw * 14], true);
        let out = conv2d_fused(
            oc2[0].as_ref().expect("output_conv2.0"),
            None,
            Activation::Relu,
            out,
        );
        let out = conv2d_fused(
            oc2[2].as_ref().expect("output_conv2.2"),
            None,
            Activation::Relu,
            out,
        );
        // MonSter: F.relu (a no-op after the last ReLU) then resize to the input size.
        resize_bilinear(relu(out), out_size, false)
    }

    /// `DPTHead_decoder.forward`: `[path1 (1/4), path2 (1/8), path3 (1/16), path4 (1/32)]`, F channels.
    pub fn forward_features(&self, feats: &VitFeatures) -> [Tensor<4>; 4] {
        let l = self.levels(feats);
        let s = &self.scratch;
        let size = |t: &Tensor<4>| {
            let d = t.dims();
            [d[2], d[3]]
        };
        let p4 = s.refinenet4.forward(l[3].clone(), None, Some(size(&l[3])));
        let up4 = resize_bilinear(p4.clone(), size(&l[2]), true);
        let p3 = s
            .refinenet3
            .forward(up4, Some(l[2].clone()), Some(size(&l[2])));
        let up3 = resize_bilinear(p3.clone(), size(&l[1]), true);
        let p2 = s
            .refinenet2
            .forward(up3, Some(l[1].clone()), Some(size(&l[1])));
        let up2 = resize_bilinear(p2.clone(), size(&l[0]), true);
        let p1 = s
            .refinenet1
            .forward(up2, Some(l[0].clone()), Some(size(&l[0])));
        [p1, p2, p3, p4]
    }
}

/// Outputs of the mono branch (`Monster.infer_mono`).
#[derive(Debug, Clone)]
pub struct MonoOutput {
    /// Relative inverse depth of the left image, B×1×H×W.
    pub depth_mono: Tensor<4>,
    /// `feat_decoder` paths of the left image `[1/4, 1/8, 1/16, 1/32]`, F channels.
    pub features_left: [Tensor<4>; 4],
    /// The same for the right image.
    pub features_right: [Tensor<4>; 4],
}

/// `Monster.infer_mono` on the **normalised** images (`2·img/255 − 1`, B×3×H×W, H and W
/// multiples of 32): ×14/16 resize, DINOv2 on each image, `mono_decoder` on the left one,
/// `feat_decoder` on both.
pub fn infer_mono(
    mono_encoder: &crate::monster::vit::DinoVisionTransformer,
    mono_decoder: &DptHead,
    feat_decoder: &DptHead,
    left_normalized: Tensor<4>,
    right_normalized: Tensor<4>,
) -> MonoOutput {
    use crate::monster::vit::mono_input;
    use crate::profile::span;
    let [_, _, h, w] = left_normalized.dims();
    let (fl, fr) = span("dinov2", || {
        (
            mono_encoder.forward_intermediate(mono_input(left_normalized)),
            mono_encoder.forward_intermediate(mono_input(right_normalized)),
        )
    });
    span("dpt heads", || MonoOutput {
        depth_mono: mono_decoder.forward_depth(&fl, [h, w]),
        features_left: feat_decoder.forward_features(&fl),
        features_right: feat_decoder.forward_features(&fr),
    })
}

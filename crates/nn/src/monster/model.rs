//! The assembled MonSter++ accuracy model (upstream `core/monster.py::Monster`,
//! `../shared/design/monsterpp.md` §2).
//!
//! [`Monster`] holds every upstream root module under its state-dict name (`mono_encoder`,
//! `feat_transfer`, `stem_2`, …, `REMP`), so a whole upstream checkpoint (or one saved with
//! [`crate::weights::save_checkpoint`]) loads with a single [`crate::weights::load_weights`]:
//!
//! ```no_run
//! use burn::tensor::Device;
//! use nn::config::MonsterConfig;
//! use nn::monster::Monster;
//!
//! let device = Device::flex();
//! let mut model = Monster::new(&MonsterConfig::vitl(), &device);
//! let report = nn::weights::load_weights(&mut model, "Mix_all_large.pth").unwrap();
//! assert!(report.is_complete());
//! # let (left, right): (burn::tensor::Tensor<4>, burn::tensor::Tensor<4>) = todo!();
//! let out = model.forward(left, right, 32, true); // RGB 0–255, B×3×H×W, H, W multiples of 32
//! let disparity = out.disp; // B×1×H×W, full-resolution pixels
//! ```
//!
//! The forward pass chains the parts exactly as upstream: mono branch (DINOv2 on both images,
//! depth head on the left one, the trainable DPT copy on both) → stereo features and stems →
//! group-wise correlation volume → 3-D hourglass → soft-argmin `init_disp` → context → the
//! `iters` refinement iterations (the last 7 dual-branch, with the mono scale/shift alignment at
//! iteration `iters − 7` and REMP at the last one).
//!
//! Training: upstream freezes the mono branch (`mono_encoder`, `mono_decoder`:
//! `requires_grad_(False)`) and calls `model.train(); model.freeze_bn()`, which puts only the
//! **BatchNorm2d** layers in eval mode (the BatchNorm3d of `corr_stem`/`cost_agg` keep training).
//! [`Monster::freeze_for_training`] does both on a burn module (use it on the autodiff device, after
//! loading); `feat_decoder` is trained with half the learning rate upstream (a separate optimizer
//! group, §5).

#![allow(non_snake_case)]

use burn::module::Module;
use burn::nn::conv::{Conv2d, Conv3d, ConvTranspose2d};
use burn::tensor::activation::{softmax, tanh};
use burn::tensor::{Device, Tensor};

use super::context::FeatTransferCnet;
use super::cost::{
    build_gwc_volume, disparity_regression, BasicConv3d, Conv2xIn, CostAggregation, FeatureAtt,
    Hourglass, SpxHead, GWC_GROUPS,
};
use super::dpt::{infer_mono, DptHead};
use super::features::{
    conv2d, conv_in_block_forward, BasicConvIn, ConvInBlock, FeatTransfer, StereoFeatures,
};
use super::geometry::{GeoEncodingVolume, GEO};
use super::remp::Remp;
use super::update::{
    iterate, BasicMultiUpdateBlock, BasicMultiUpdateBlockMix2, GruContext, IterationBlocks,
    IterationInputs,
};
use super::upsample::{context_upsample, freeze_bn, spx_gru_init, Conv2x};
use super::vit::{normalize_image, DinoVisionTransformer};

/// Profile group of the stereo feature stems and the GRU context.
const STEMS: &str = "feature stems + context";
use crate::activation::relu;
use crate::config::MonsterConfig;
use crate::conv::{conv2d_forward, conv_transpose2d_forward, with_prepared_weights};
use crate::device::on_cpu_pool;
use crate::profile::span;
use crate::resize::resize_bilinear;
use crate::weights::{load_submodule, module_keys, LoadReport, WeightsError};

/// Channels of the stereo matching features (`features[0] = cat(f4 48, stem_4 48)`).
const FEATURE0_CHANNELS: usize = 96;

/// The MonSter++ accuracy model. Field names are the upstream root state-dict keys.
#[derive(Module, Debug)]
pub struct Monster {
    /// DINOv2 (frozen during training).
    pub mono_encoder: DinoVisionTransformer,
    /// DPT depth head (frozen during training).
    pub mono_decoder: DptHead,
    /// Trainable DPT copy (no output convs) giving the stereo feature paths.
    pub feat_decoder: DptHead,
    pub feat_transfer: FeatTransfer,
    pub stem_2: ConvInBlock,
    pub stem_4: ConvInBlock,
    pub stem_8: ConvInBlock,
    pub stem_16: ConvInBlock,
    /// `BasicConv_IN(96, 96, 3)` before `desc`.
    pub conv: BasicConvIn,
    /// `Conv2d(96, 96, 1)`: matching descriptors.
    pub desc: Conv2d,
    pub corr_stem: BasicConv3d,
    pub corr_feature_att: FeatureAtt,
    pub cost_agg: Hourglass,
    pub classifier: Conv3d,
    /// Train-only superpixel head for `init_disp_up`.
    pub spx_4: ConvInBlock,
    pub spx_2: Conv2xIn,
    pub spx: [ConvTranspose2d; 1],
    pub feat_transfer_cnet: FeatTransferCnet,
    /// Three `Conv2d(C, 3C, 3)`, one per GRU level `[1/4, 1/8, 1/16]`.
    pub context_zqr_convs: Vec<Conv2d>,
    pub update_block: BasicMultiUpdateBlock,
    pub update_block_mix_stereo: BasicMultiUpdateBlockMix2,
    pub update_block_mix_mono: BasicMultiUpdateBlockMix2,
    /// Shared by the stereo and mono upsampling.
    pub spx_2_gru: Conv2x,
    pub spx_gru: Vec<ConvTranspose2d>,
    pub REMP: Remp,
    #[module(skip)]
    config: MonsterConfig,
}

/// Result of [`Monster::forward`].
#[derive(Debug, Clone)]
pub struct MonsterOutput {
    /// Final disparity `B×1×H×W` in full-resolution pixels (REMP-refined last prediction).
    pub disp: Tensor<4>,
    /// Train mode: every prediction in upstream order (`iters − 7` stereo-only ones, then per
    /// dual-branch iteration `[mono_up, stereo_up]`; `iters + 7` in all, the last equals `disp`).
    /// Empty in test mode.
    pub disp_preds: Vec<Tensor<4>>,
    /// Train mode: the superpixel-upsampled initial disparity `B×1×H×W` (`None` in test mode).
    pub init_disp_up: Option<Tensor<4>>,
    /// Relative inverse depth of the left image from the mono branch, `B×1×H×W`.
    pub depth_mono: Tensor<4>,
    /// `(scale, shift)` per batch sample of the mono-to-stereo alignment at iteration `iters − 7`.
    pub scale_shift: Vec<(f32, f32)>,
}

/// The stereo side's feature maps (§2.2).
struct StereoMaps {
    /// `stem_2x` … `stem_16x` of the left image.
    stems: [Tensor<4>; 4],
    /// `cat(f4, stem_4x)`, `f8`, `f16`, `f32` of the left image.
    features_left: [Tensor<4>; 4],
    /// `cat(f4, stem_4y)` of the right image.
    features_right0: Tensor<4>,
    /// The matching descriptors `desc(conv(features[0]))` of both images.
    match_left: Tensor<4>,
    match_right: Tensor<4>,
}

/// Panics unless `left` and `right` are `B×3×H×W` images of one shape with H and W multiples
/// of 32, and `iters` covers the seven dual-branch iterations.
fn check_inputs(left: &Tensor<4>, right: &Tensor<4>, iters: usize) {
    let [b, ch, h, w] = left.dims();
    assert_eq!(
        left.dims(),
        right.dims(),
        "Monster::forward: left and right images differ in shape"
    );
    assert!(
        ch == 3 && b > 0,
        "Monster::forward: expected B×3×H×W images, got {:?}",
        left.dims()
    );
    assert!(
        h > 0 && w > 0 && h % 32 == 0 && w % 32 == 0,
        "Monster::forward: H and W must be positive multiples of 32, got {h}×{w} (pad first)"
    );
    assert!(
        iters >= 7,
        "Monster::forward: iters ({iters}) must be at least 7 (the last 7 are dual-branch)"
    );
}

/// Root-key prefixes of the mono branch, frozen during training.
const MONO_PREFIXES: [&str; 2] = ["mono_encoder.", "mono_decoder."];

impl Monster {
    /// Builds the model with lazily initialised (random) parameters: cheap until weights are
    /// loaded or used. Panics if `config` is invalid (see [`MonsterConfig::validate`]).
    pub fn new(config: &MonsterConfig, device: &Device) -> Self {
        if let Err(e) = config.validate() {
            panic!("{e}");
        }
        let f = config.dpt.features;
        let e = config.vit.embed_dim;
        let c = config.hidden();
        let features = StereoFeatures::new(f, device);
        let cost = CostAggregation::new(device);
        let spx = SpxHead::new(device);
        let cor_planes = config.corr_levels * (2 * config.corr_radius + 1) * (GWC_GROUPS + 1);
        Self {
            mono_encoder: DinoVisionTransformer::new(&config.vit, device),
            mono_decoder: DptHead::new(e, &config.dpt, true, device),
            feat_decoder: DptHead::new(e, &config.dpt, false, device),
            feat_transfer: features.feat_transfer,
            stem_2: features.stem_2,
            stem_4: features.stem_4,
            stem_8: features.stem_8,
            stem_16: features.stem_16,
            conv: features.conv,
            desc: features.desc,
            corr_stem: cost.corr_stem,
            corr_feature_att: cost.corr_feature_att,
            cost_agg: cost.cost_agg,
            classifier: cost.classifier,
            spx_4: spx.spx_4,
            spx_2: spx.spx_2,
            spx: spx.spx,
            feat_transfer_cnet: FeatTransferCnet::new(f, c, device),
            context_zqr_convs: (0..config.n_gru_layers)
                .map(|_| conv2d(c, 3 * c, 3, 1, 1, true, device))
                .collect(),
            update_block: BasicMultiUpdateBlock::new(c, cor_planes, device),
            update_block_mix_stereo: BasicMultiUpdateBlockMix2::new(
                c,
                cor_planes,
                FEATURE0_CHANNELS,
                device,
            ),
            update_block_mix_mono: BasicMultiUpdateBlockMix2::new(
                c,
                cor_planes,
                FEATURE0_CHANNELS,
                device,
            ),
            spx_2_gru: Conv2x::new(32, 32, device),
            spx_gru: spx_gru_init(device),
            REMP: Remp::new(device),
            config: config.clone(),
        }
    }

    /// The configuration the model was built with.
    pub fn config(&self) -> &MonsterConfig {
        &self.config
    }

    /// Upstream `Monster.forward(image1, image2, iters, test_mode)`.
    ///
    /// `left`, `right`: `B×3×H×W`, RGB values 0–255, H and W multiples of 32 (pad with
    /// replicate padding first, as upstream's `InputPadder`). `iters ≥ 7` (upstream uses 32 at
    /// test time, 22 in training). `test_mode = false` also returns every intermediate prediction
    /// and `init_disp_up` (for the training loss). D = `config.max_disp / 4` disparity bins.
    ///
    /// Panics on a shape that violates these rules.
    pub fn forward(
        &self,
        left: Tensor<4>,
        right: Tensor<4>,
        iters: usize,
        test_mode: bool,
    ) -> MonsterOutput {
        check_inputs(&left, &right, iters);
        // The iteration loop runs its layers many times: prepare their weights once.
        on_cpu_pool(&left.device(), || {
            with_prepared_weights(|| self.forward_pass([left, right], iters, test_mode))
        })
    }

    /// The network on checked inputs: the mono branch (§2.1), the stereo features (§2.2), the
    /// cost volume and initial disparity (§2.3), the context (§2.4), the Combined Geo Encoding
    /// Volume (§2.5) and the refinement iterations (§2.6).
    fn forward_pass(
        &self,
        [left, right]: [Tensor<4>; 2],
        iters: usize,
        test_mode: bool,
    ) -> MonsterOutput {
        let [_, _, h, w] = left.dims();
        let image1 = normalize_image(left);
        let image2 = normalize_image(right);
        let mono = infer_mono(
            &self.mono_encoder,
            &self.mono_decoder,
            &self.feat_decoder,
            image1.clone(),
            image2.clone(),
        );
        let depth_mono = mono.depth_mono;
        let disp_mono_4x = resize_bilinear(depth_mono.clone(), [h / 4, w / 4], false);
        let stereo = span(STEMS, || {
            self.stereo_features(&mono.features_left, mono.features_right, [&image1, &image2])
        });
        let [stem_2x, stem_4x, stem_8x, stem_16x] = stereo.stems;
        let (geo_volume, init_disp) = self.initial_disparity(
            &stereo.match_left,
            &stereo.match_right,
            &stereo.features_left,
        );
        let init_disp_up = (!test_mode)
            .then(|| self.superpixel_upsample(&init_disp, &stereo.features_left[0], &stem_2x));
        let (net, inp) = span(STEMS, || {
            self.context(&mono.features_left, [stem_4x, stem_8x, stem_16x])
        });
        let geo = span(GEO, || {
            GeoEncodingVolume::new(
                stereo.match_left,
                stereo.match_right,
                geo_volume,
                self.config.corr_radius,
                self.config.corr_levels,
            )
        });
        let [features_left0, ..] = stereo.features_left;
        let out = iterate(
            &self.iteration_blocks(),
            IterationInputs {
                geo,
                init_disp,
                disp_mono_4x,
                net,
                inp,
                features_left0,
                features_right0: stereo.features_right0,
                stem_2x,
                image1,
                image2,
            },
            iters,
            test_mode,
        );
        MonsterOutput {
            disp: out.disp,
            disp_preds: out.disp_preds,
            init_disp_up,
            depth_mono,
            scale_shift: out.scale_shift,
        }
    }

    /// The stereo features (§2.2) of the normalised `images` from the mono branch's left and
    /// right feature paths: the stems of the left image and the matching descriptors.
    fn stereo_features(
        &self,
        mono_left: &[Tensor<4>; 4],
        mono_right: [Tensor<4>; 4],
        [image1, image2]: [&Tensor<4>; 2],
    ) -> StereoMaps {
        let [fl4, fl8, fl16, fl32] = self.feat_transfer.forward(mono_left.clone());
        let [fr4, _, _, _] = self.feat_transfer.forward(mono_right);
        let stem_2x = conv_in_block_forward(&self.stem_2, image1.clone());
        let stem_4x = conv_in_block_forward(&self.stem_4, stem_2x.clone());
        let stem_8x = conv_in_block_forward(&self.stem_8, stem_4x.clone());
        let stem_16x = conv_in_block_forward(&self.stem_16, stem_8x.clone());
        let stem_2y = conv_in_block_forward(&self.stem_2, image2.clone());
        let stem_4y = conv_in_block_forward(&self.stem_4, stem_2y);
        let features_left = [Tensor::cat(vec![fl4, stem_4x.clone()], 1), fl8, fl16, fl32];
        let features_right0 = Tensor::cat(vec![fr4, stem_4y], 1);
        let match_left = conv2d_forward(&self.desc, self.conv.forward(features_left[0].clone()));
        let match_right = conv2d_forward(&self.desc, self.conv.forward(features_right0.clone()));
        StereoMaps {
            stems: [stem_2x, stem_4x, stem_8x, stem_16x],
            features_left,
            features_right0,
            match_left,
            match_right,
        }
    }

    /// The group-wise correlation volume of the descriptors, aggregated by the 3-D hourglass
    /// (§2.3): the aggregated volume and its soft-argmin disparity.
    fn initial_disparity(
        &self,
        match_left: &Tensor<4>,
        match_right: &Tensor<4>,
        features_left: &[Tensor<4>; 4],
    ) -> (Tensor<5>, Tensor<4>) {
        let gwc = span("gwc volume", || {
            build_gwc_volume(
                match_left.clone(),
                match_right.clone(),
                self.config.disp_bins(),
                GWC_GROUPS,
            )
        });
        span("3-d hourglass + init disparity", || {
            let gwc = self
                .corr_feature_att
                .forward(self.corr_stem.forward(gwc), features_left[0].clone());
            let geo_volume = self.cost_agg.forward(gwc, features_left);
            let logits: Tensor<5> = self.classifier.forward(geo_volume.clone());
            let prob = softmax(logits.squeeze_dim::<4>(1), 1);
            (geo_volume, disparity_regression(prob))
        })
    }

    /// Train mode's `init_disp_up`: the initial disparity upsampled by the superpixel head.
    fn superpixel_upsample(
        &self,
        init_disp: &Tensor<4>,
        features_left0: &Tensor<4>,
        stem_2x: &Tensor<4>,
    ) -> Tensor<4> {
        let x = conv_in_block_forward(&self.spx_4, features_left0.clone());
        let x = self.spx_2.forward(x, stem_2x.clone());
        let spx_pred = softmax(conv_transpose2d_forward(&self.spx[0], x), 1);
        context_upsample(init_disp.clone().mul_scalar(4.0), spx_pred)
    }

    /// The GRU context (§2.4): the initial hidden states `tanh(cnet)` and per level the
    /// `[cz, cr, cq]` thirds of `context_zqr_convs[i](relu(cnet_i))`.
    fn context(
        &self,
        mono_left: &[Tensor<4>; 4],
        stems: [Tensor<4>; 3],
    ) -> ([Tensor<4>; 3], [GruContext; 3]) {
        let cnet = self.feat_transfer_cnet.forward(mono_left, stems);
        let net = cnet.clone().map(tanh);
        let inp: [GruContext; 3] = std::array::from_fn(|i| {
            let conv = &self.context_zqr_convs[i];
            let y = conv2d_forward(conv, relu(cnet[i].clone()));
            let c = y.dims()[1] / 3;
            let mut parts = y.split(c, 1).into_iter();
            [
                parts.next().expect("cz"),
                parts.next().expect("cr"),
                parts.next().expect("cq"),
            ]
        });
        (net, inp)
    }

    /// The modules of the refinement loop, borrowed.
    pub fn iteration_blocks(&self) -> IterationBlocks<'_> {
        IterationBlocks {
            update_block: &self.update_block,
            update_block_mix_stereo: &self.update_block_mix_stereo,
            update_block_mix_mono: &self.update_block_mix_mono,
            spx_2_gru: &self.spx_2_gru,
            spx_gru: &self.spx_gru[0],
            remp: &self.REMP,
        }
    }

    /// Number of parameters (PyTorch `parameters()`: BatchNorm running statistics excluded),
    /// counted from the shapes without initialising lazy parameters.
    pub fn num_params(&self) -> usize {
        count_params(self, |_| true)
    }

    /// Number of parameters that are trained upstream: all but the frozen mono branch
    /// (`mono_encoder`, `mono_decoder`).
    pub fn num_trainable_params(&self) -> usize {
        count_params(self, |k| !MONO_PREFIXES.iter().any(|p| k.starts_with(p)))
    }

    /// Loads an official Depth Anything V2 checkpoint (keys `pretrained.*` for the DINOv2 encoder,
    /// `depth_head.*` for the DPT head, e.g. `depth_anything_v2_vitl.pth`) as upstream does at
    /// construction: strictly into `mono_encoder` and `mono_decoder`, and into the trainable copy
    /// `feat_decoder` (which has no output convolutions: those keys are left unused). The reports
    /// are returned in that order; a missing or mis-shaped key is an error naming it.
    pub fn load_depth_anything(
        &mut self,
        path: impl AsRef<std::path::Path>,
    ) -> Result<[LoadReport; 3], WeightsError> {
        let path = path.as_ref();
        Ok([
            load_submodule(&mut self.mono_encoder, path, "pretrained.")?,
            load_submodule(&mut self.mono_decoder, path, "depth_head.")?,
            load_submodule(&mut self.feat_decoder, path, "depth_head.")?,
        ])
    }

    /// Prepares the model for training as upstream (`requires_grad_(False)` on the mono branch,
    /// then `model.train(); model.freeze_bn()`): `mono_encoder` and `mono_decoder` are frozen
    /// (no gradients; they have no BatchNorm/dropout), and every **BatchNorm2d** (the FeatureAtt
    /// layers of `corr_feature_att`/`cost_agg`, `spx_2_gru`, `REMP`) uses its running statistics,
    /// while the BatchNorm3d of `corr_stem`/`cost_agg` stay in training mode. Call on a model
    /// built or loaded **on the autodiff device** (a moved module has untracked parameters).
    pub fn freeze_for_training(mut self) -> Self {
        self.mono_encoder = self.mono_encoder.freeze();
        self.mono_decoder = self.mono_decoder.freeze();
        self.corr_feature_att = freeze_bn(self.corr_feature_att);
        let agg = &mut self.cost_agg;
        agg.feature_att_8 = freeze_bn(agg.feature_att_8.clone());
        agg.feature_att_16 = freeze_bn(agg.feature_att_16.clone());
        agg.feature_att_32 = freeze_bn(agg.feature_att_32.clone());
        agg.feature_att_up_16 = freeze_bn(agg.feature_att_up_16.clone());
        agg.feature_att_up_8 = freeze_bn(agg.feature_att_up_8.clone());
        self.spx_2_gru = freeze_bn(self.spx_2_gru);
        self.REMP = freeze_bn(self.REMP);
        self
    }
}

fn count_params(model: &Monster, keep: impl Fn(&str) -> bool) -> usize {
    module_keys(model)
        .into_iter()
        .filter(|(k, _)| {
            !k.ends_with("running_mean") && !k.ends_with("running_var") && keep(k.as_str())
        })
        .map(|(_, s)| s.iter().product::<usize>())
        .sum()
}

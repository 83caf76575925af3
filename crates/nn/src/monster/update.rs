//! The multi-level ConvGRU update blocks (upstream `core/update.py`): `BasicMultiUpdateBlock`
//! (the plain stereo block, `update_block`) and `BasicMultiUpdateBlock_mix2` (the dual-branch
//! blocks `update_block_mix_stereo` and `update_block_mix_mono`, separate weights).
//!
//! Hidden states are `[h4, h8, h16]` (`net[0..3]`, 1/4, 1/8, 1/16). The context is, per level,
//! the three pre-computed GRU biases `[cz, cr, cq]` (upstream `inp_list[i]` =
//! `context_zqr_convs[i](relu(cnet_i)).split(C)`). Update order: gru16, gru08, motion encoder,
//! gru04 (quirk: 16→8→4, the coarse levels see the *previous* finer states).

use burn::module::Module;
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::nn::{PaddingConfig2d, Relu};
use burn::tensor::{Device, Tensor, TensorData};
use rayon::prelude::*;

use crate::activation::{sigmoid, tanh};
use crate::conv::{
    conv2d_forward, conv2d_fused, conv2d_nchw, geometry, layer_weights, prepared, Activation,
    Epilogue, Geometry, LayerWeights, Nchw,
};
use crate::fastmath;
use crate::flex_tensor::f32_vec;
use crate::gate::gru_blend;
use crate::pool::avg_pool2d_padded;
use crate::resize::resize_bilinear;

fn conv(c_in: usize, c_out: usize, k: usize, device: &Device) -> Conv2d {
    let p = k / 2;
    Conv2dConfig::new([c_in, c_out], [k, k])
        .with_padding(PaddingConfig2d::Explicit(p, p, p, p))
        .init(device)
}

/// `pool2x` = `avg_pool2d(k3, s2, p1)`, count_include_pad=True.
pub fn pool2x(x: Tensor<4>) -> Tensor<4> {
    avg_pool2d_padded(x, 3, 2, 1)
}

/// `interp(x, dest)` = bilinear resize of `x` to the spatial size of `dest`, align_corners=True.
pub fn interp(x: Tensor<4>, dest: &Tensor<4>) -> Tensor<4> {
    let [_, _, h, w] = dest.dims();
    resize_bilinear(x, [h, w], true)
}

/// Per-level GRU context biases `[cz, cr, cq]`.
pub type GruContext = [Tensor<4>; 3];

/// Upstream `ConvGRU(hidden, input, 3)`: `z = σ(convz([h,x]) + cz)`, `r = σ(convr([h,x]) + cr)`,
/// `q = tanh(convq([r·h, x]) + cq)`, `h' = (1-z)·h + z·q`.
#[derive(Module, Debug)]
pub struct ConvGru {
    pub convz: Conv2d,
    pub convr: Conv2d,
    pub convq: Conv2d,
}

impl ConvGru {
    pub fn new(hidden: usize, input: usize, device: &Device) -> Self {
        Self {
            convz: conv(hidden + input, hidden, 3, device),
            convr: conv(hidden + input, hidden, 3, device),
            convq: conv(hidden + input, hidden, 3, device),
        }
    }

    /// `x_list` is concatenated along channels (upstream `*x_list`).
    pub fn forward(&self, h: Tensor<4>, ctx: &GruContext, x_list: Vec<Tensor<4>>) -> Tensor<4> {
        if let Some(geometry) = self.fused_geometry(&h) {
            return self.forward_fused(h, ctx, x_list, geometry);
        }
        let x = Tensor::cat(x_list, 1);
        let hx = Tensor::cat(vec![h.clone(), x.clone()], 1);
        let z = sigmoid(conv2d_forward(&self.convz, hx.clone()) + ctx[0].clone());
        let r = sigmoid(conv2d_forward(&self.convr, hx) + ctx[1].clone());
        let q = tanh(
            conv2d_forward(&self.convq, Tensor::cat(vec![r * h.clone(), x], 1)) + ctx[2].clone(),
        );
        gru_blend(h, z, q)
    }

    /// The convolutions' shared geometry where [`forward_fused`](Self::forward_fused) applies:
    /// the CPU inference device, and the three convolutions alike (same-size, with biases) as
    /// upstream builds them.
    fn fused_geometry(&self, h: &Tensor<4>) -> Option<Geometry> {
        let shared = geometry(&self.convz, h)?;
        let same = |c: &Conv2d| geometry(c, h) == Some(shared) && c.bias.is_some();
        let [kh, kw] = shared.kernel;
        let [t, l, b, r] = shared.padding;
        let fusable = shared.stride == [1, 1]
            && shared.dilation == [1, 1]
            && [t + b, l + r] == [kh - 1, kw - 1]
            && [&self.convz, &self.convr, &self.convq]
                .into_iter()
                .all(same);
        fusable.then_some(shared)
    }

    /// The same step on the CPU inference device on plain buffers: `[h, x…]` assembled once,
    /// `convz` and `convr` as one convolution (their weights stacked), the gates, `r·h` and the
    /// update computed in place on the convolutions' outputs.
    fn forward_fused(
        &self,
        h: Tensor<4>,
        ctx: &GruContext,
        x_list: Vec<Tensor<4>>,
        geometry: Geometry,
    ) -> Tensor<4> {
        let device = h.device();
        let [b, hidden, height, width] = h.dims();
        let plane = height * width;
        let h = f32_vec(h);
        let xs: Vec<Vec<f32>> = x_list.into_iter().map(f32_vec).collect();
        let x_channels = xs.iter().map(|x| x.len() / (b * plane)).sum::<usize>();
        let channels = hidden + x_channels;
        let mut hx = Vec::with_capacity(b * channels * plane);
        for n in 0..b {
            hx.extend_from_slice(&h[n * hidden * plane..(n + 1) * hidden * plane]);
            for x in &xs {
                let per_image = x.len() / b;
                hx.extend_from_slice(&x[n * per_image..(n + 1) * per_image]);
            }
        }
        drop(xs);
        let biases =
            |c: &Conv2d| f32_vec(c.bias.as_ref().expect("checked by fused_geometry").val());
        let shape = Nchw {
            b,
            c: channels,
            h: height,
            w: width,
        };
        let conv = |input: &[f32], weights: &LayerWeights, bias: &[f32]| {
            let (out, size) =
                conv2d_nchw(input, shape, weights, geometry, Epilogue::bias(Some(bias)));
            debug_assert_eq!(size, [height, width], "a same-size convolution");
            out
        };
        let [cz, cr, cq] = ctx.clone().map(f32_vec);
        // convz and convr stacked into one layer of 2·hidden outputs.
        let zr_weights = prepared(self.convz.weight.id, "convz+convr", || {
            let raw = [&self.convz, &self.convr].map(|c| f32_vec(c.weight.val()));
            LayerWeights::new(
                raw.concat(),
                2 * hidden,
                geometry.kernel[0] * geometry.kernel[1],
            )
        });
        let zr = conv(
            &hx,
            &zr_weights,
            &[biases(&self.convz), biases(&self.convr)].concat(),
        );
        // z stays in the first half of `zr`; `r·h` replaces `h` in the input of convq.
        let mut z = vec![0.0f32; b * hidden * plane];
        let per_image = hidden * plane;
        for n in 0..b {
            let gates = &zr[n * 2 * per_image..(n + 1) * 2 * per_image];
            let (zs, rs) = gates.split_at(per_image);
            let at = n * per_image..(n + 1) * per_image;
            let rh = &mut hx[n * channels * plane..][..per_image];
            z[at.clone()]
                .par_iter_mut()
                .zip(zs)
                .zip(&cz[at.clone()])
                .for_each(|((z, &v), &c)| *z = fastmath::sigmoid(v + c));
            rh.par_iter_mut()
                .zip(rs)
                .zip(&cr[at.clone()])
                .zip(&h[at])
                .for_each(|(((rh, &v), &c), &h)| *rh = fastmath::sigmoid(v + c) * h);
        }
        drop(zr);
        let mut q = conv(&hx, &layer_weights(&self.convq), &biases(&self.convq));
        q.par_iter_mut()
            .zip(&cq)
            .zip(&z)
            .zip(&h)
            .for_each(|(((q, &c), &z), &h)| *q = (1.0 - z) * h + z * fastmath::tanh(*q + c));
        Tensor::from_data(TensorData::new(q, [b, hidden, height, width]), &device)
    }
}

/// Upstream `DispHead(C, 256, 1)`: `conv2(relu(conv1(x)))`, both 3×3.
#[derive(Module, Debug)]
pub struct DispHead {
    pub conv1: Conv2d,
    pub conv2: Conv2d,
}

impl DispHead {
    pub fn new(c_in: usize, device: &Device) -> Self {
        Self {
            conv1: conv(c_in, 256, 3, device),
            conv2: conv(256, 1, 3, device),
        }
    }

    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        conv2d_forward(
            &self.conv2,
            conv2d_fused(&self.conv1, None, Activation::Relu, x),
        )
    }
}

/// Upstream `BasicMotionEncoder`: `cor = relu(convc2(relu(convc1(corr))))`,
/// `d = relu(convd2(relu(convd1(disp))))`, `out = relu(conv(cat(cor, d)))` (127 ch),
/// returns `cat(out, disp)` (128 ch).
#[derive(Module, Debug)]
pub struct BasicMotionEncoder {
    pub convc1: Conv2d,
    pub convc2: Conv2d,
    pub convd1: Conv2d,
    pub convd2: Conv2d,
    pub conv: Conv2d,
}

impl BasicMotionEncoder {
    pub fn new(cor_planes: usize, device: &Device) -> Self {
        Self {
            convc1: conv(cor_planes, 64, 1, device),
            convc2: conv(64, 64, 3, device),
            convd1: conv(1, 64, 7, device),
            convd2: conv(64, 64, 3, device),
            conv: conv(128, 127, 3, device),
        }
    }

    pub fn forward(&self, disp: Tensor<4>, corr: Tensor<4>) -> Tensor<4> {
        let cor = conv2d_fused(
            &self.convc2,
            None,
            Activation::Relu,
            conv2d_fused(&self.convc1, None, Activation::Relu, corr),
        );
        let d = conv2d_fused(
            &self.convd2,
            None,
            Activation::Relu,
            conv2d_fused(&self.convd1, None, Activation::Relu, disp.clone()),
        );
        let out = conv2d_fused(
            &self.conv,
            None,
            Activation::Relu,
            Tensor::cat(vec![cor, d], 1),
        );
        Tensor::cat(vec![out, disp], 1)
    }
}

/// Upstream `BasicMotionEncoder_mix2`: two branches ("own" and `*_mono` = "other") with
/// `convc1(cat(corr, flaw))` (162+96 → 64), `convc2`, `convd1` (7×7), `convd2`, `conv` 128 → 63;
/// returns `cat(out, disp, out_o, disp_o)` (128 ch).
#[derive(Module, Debug)]
pub struct BasicMotionEncoderMix2 {
    pub convc1: Conv2d,
    pub convc2: Conv2d,
    pub convc1_mono: Conv2d,
    pub convc2_mono: Conv2d,
    pub convd1: Conv2d,
    pub convd2: Conv2d,
    pub convd1_mono: Conv2d,
    pub convd2_mono: Conv2d,
    pub conv: Conv2d,
    pub conv_mono: Conv2d,
}

/// The inputs of one branch of the mix encoder.
#[derive(Debug, Clone)]
pub struct Branch {
    /// Disparity `[B,1,h,w]`.
    pub disp: Tensor<4>,
    /// Geo lookup `[B,162,h,w]`.
    pub corr: Tensor<4>,
    /// `disp_warp(features_right[0], disp) - features_left[0]` `[B,96,h,w]`.
    pub flaw: Tensor<4>,
}

impl BasicMotionEncoderMix2 {
    pub fn new(cor_planes: usize, flaw_planes: usize, device: &Device) -> Self {
        let c = cor_planes + flaw_planes;
        Self {
            convc1: conv(c, 64, 1, device),
            convc2: conv(64, 64, 3, device),
            convc1_mono: conv(c, 64, 1, device),
            convc2_mono: conv(64, 64, 3, device),
            convd1: conv(1, 64, 7, device),
            convd2: conv(64, 64, 3, device),
            convd1_mono: conv(1, 64, 7, device),
            convd2_mono: conv(64, 64, 3, device),
            conv: conv(128, 63, 3, device),
            conv_mono: conv(128, 63, 3, device),
        }
    }

    /// `own` goes through the plain weights, `other` through the `*_mono` weights (for the mono
    /// instance upstream passes the mono branch as `own`).
    pub fn forward(&self, own: &Branch, other: &Branch) -> Tensor<4> {
        let cor = conv2d_fused(
            &self.convc2,
            None,
            Activation::Relu,
            conv2d_fused(
                &self.convc1,
                None,
                Activation::Relu,
                Tensor::cat(vec![own.corr.clone(), own.flaw.clone()], 1),
            ),
        );
        let cor_o = conv2d_fused(
            &self.convc2_mono,
            None,
            Activation::Relu,
            conv2d_fused(
                &self.convc1_mono,
                None,
                Activation::Relu,
                Tensor::cat(vec![other.corr.clone(), other.flaw.clone()], 1),
            ),
        );
        let d = conv2d_fused(
            &self.convd2,
            None,
            Activation::Relu,
            conv2d_fused(&self.convd1, None, Activation::Relu, own.disp.clone()),
        );
        let d_o = conv2d_fused(
            &self.convd2_mono,
            None,
            Activation::Relu,
            conv2d_fused(
                &self.convd1_mono,
                None,
                Activation::Relu,
                other.disp.clone(),
            ),
        );
        let out = conv2d_fused(
            &self.conv,
            None,
            Activation::Relu,
            Tensor::cat(vec![cor, d], 1),
        );
        let out_o = conv2d_fused(
            &self.conv_mono,
            None,
            Activation::Relu,
            Tensor::cat(vec![cor_o, d_o], 1),
        );
        Tensor::cat(vec![out, own.disp.clone(), out_o, other.disp.clone()], 1)
    }
}

/// What an update block returns: the new hidden states, `mask_feat_4` `[B,32,h,w]` and the
/// disparity increment `[B,1,h,w]`.
#[derive(Debug, Clone)]
pub struct UpdateOut {
    pub net: [Tensor<4>; 3],
    pub mask_feat: Tensor<4>,
    pub delta: Tensor<4>,
}

/// The GRU stack shared by both block kinds (fields flattened into each block for the keys).
fn gru_steps(
    gru16: &ConvGru,
    gru08: &ConvGru,
    gru04: &ConvGru,
    net: [Tensor<4>; 3],
    inp: &[GruContext; 3],
    motion: impl FnOnce() -> Tensor<4>,
) -> [Tensor<4>; 3] {
    let [h4, h8, h16] = net;
    let h16 = gru16.forward(h16, &inp[2], vec![pool2x(h8.clone())]);
    let h8 = gru08.forward(
        h8.clone(),
        &inp[1],
        vec![pool2x(h4.clone()), interp(h16.clone(), &h8)],
    );
    let m = motion();
    let h4 = gru04.forward(h4.clone(), &inp[0], vec![m, interp(h8.clone(), &h4)]);
    [h4, h8, h16]
}

/// `mask_feat_4 = nn.Sequential(Conv2d(C, 32, 3, p1), ReLU)` → keys `mask_feat_4.0.*`.
fn mask_feat_init(hidden: usize, device: &Device) -> (Conv2d, Relu) {
    (conv(hidden, 32, 3, device), Relu::new())
}

/// Defines an update block around the motion encoder `$encoder` (the one part that differs
/// between the plain and the dual-branch block): three ConvGRU levels, the disparity head and the
/// mask features, with upstream's keys `encoder`, `gru04`, `gru08`, `gru16`, `disp_head`,
/// `mask_feat_4`.
macro_rules! update_block {
    ($(#[$doc:meta])* $name:ident, $encoder:ty) => {
        $(#[$doc])*
        #[derive(Module, Debug)]
        pub struct $name {
            pub encoder: $encoder,
            pub gru04: ConvGru,
            pub gru08: ConvGru,
            pub gru16: ConvGru,
            pub disp_head: DispHead,
            pub mask_feat_4: (Conv2d, Relu),
        }

        impl $name {
            /// The block around `encoder`; every level's hidden state has `hidden` channels.
            fn with_encoder(encoder: $encoder, hidden: usize, device: &Device) -> Self {
                Self {
                    encoder,
                    gru04: ConvGru::new(hidden, 128 + hidden, device),
                    gru08: ConvGru::new(hidden, 2 * hidden, device),
                    gru16: ConvGru::new(hidden, hidden, device),
                    disp_head: DispHead::new(hidden, device),
                    mask_feat_4: mask_feat_init(hidden, device),
                }
            }

            /// The GRU levels coarse to fine (`motion` feeds the finest), then the heads.
            fn update(
                &self,
                net: [Tensor<4>; 3],
                inp: &[GruContext; 3],
                motion: impl FnOnce() -> Tensor<4>,
            ) -> UpdateOut {
                let net = gru_steps(&self.gru16, &self.gru08, &self.gru04, net, inp, motion);
                let delta = self.disp_head.forward(net[0].clone());
                let mask_feat =
                    conv2d_fused(&self.mask_feat_4.0, None, Activation::Relu, net[0].clone());
                UpdateOut {
                    net,
                    mask_feat,
                    delta,
                }
            }
        }
    };
}

update_block!(
    /// Upstream `BasicMultiUpdateBlock` (n_gru_layers = 3, all hidden dims equal to `hidden`).
    BasicMultiUpdateBlock,
    BasicMotionEncoder
);

impl BasicMultiUpdateBlock {
    /// `cor_planes` = levels·(2r+1)·9 (162 for MonSter).
    pub fn new(hidden: usize, cor_planes: usize, device: &Device) -> Self {
        Self::with_encoder(BasicMotionEncoder::new(cor_planes, device), hidden, device)
    }

    /// `net` = `[h4, h8, h16]`, `corr` = geo lookup at `disp`.
    pub fn forward(
        &self,
        net: [Tensor<4>; 3],
        inp: &[GruContext; 3],
        corr: Tensor<4>,
        disp: Tensor<4>,
    ) -> UpdateOut {
        self.update(net, inp, || self.encoder.forward(disp, corr))
    }
}

update_block!(
    /// Upstream `BasicMultiUpdateBlock_mix2` (the dual-branch block; one instance per branch).
    BasicMultiUpdateBlockMix2,
    BasicMotionEncoderMix2
);

impl BasicMultiUpdateBlockMix2 {
    /// `cor_planes` = 162, `flaw_planes` = 96 (channels of `features_left[0]`).
    pub fn new(hidden: usize, cor_planes: usize, flaw_planes: usize, device: &Device) -> Self {
        let encoder = BasicMotionEncoderMix2::new(cor_planes, flaw_planes, device);
        Self::with_encoder(encoder, hidden, device)
    }

    /// `own`: this instance's branch (stereo for `update_block_mix_stereo`, mono for
    /// `update_block_mix_mono`); `other`: the other branch.
    pub fn forward(
        &self,
        net: [Tensor<4>; 3],
        inp: &[GruContext; 3],
        own: &Branch,
        other: &Branch,
    ) -> UpdateOut {
        self.update(net, inp, || self.encoder.forward(own, other))
    }
}

// ---------------------------------------------------------------------------------------------
// The iteration driver (upstream `Monster.forward`, the `for itr in range(iters)` loop).
// ---------------------------------------------------------------------------------------------

use std::collections::HashMap;

use burn::nn::conv::ConvTranspose2d;

use super::geometry::{GeoEncodingVolume, GEO};
use super::remp::Remp;
use super::scale_shift::align_mono;
use super::upsample::{upsample_disp, Conv2x};
use super::warp::disp_warp;
use crate::profile::span;

/// Profile groups of the refinement loop.
const GRU: &str = "convgru updates";
const UPSAMPLING: &str = "upsampling";

/// The modules the loop uses (borrowed from the assembled model; their state-dict prefixes are
/// `update_block`, `update_block_mix_stereo`, `update_block_mix_mono`, `spx_2_gru`,
/// `spx_gru.0`, `REMP`).
#[derive(Debug, Clone, Copy)]
pub struct IterationBlocks<'a> {
    pub update_block: &'a BasicMultiUpdateBlock,
    pub update_block_mix_stereo: &'a BasicMultiUpdateBlockMix2,
    pub update_block_mix_mono: &'a BasicMultiUpdateBlockMix2,
    pub spx_2_gru: &'a Conv2x,
    pub spx_gru: &'a ConvTranspose2d,
    pub remp: &'a Remp,
}

/// The prepared inputs of the loop.
#[derive(Debug, Clone)]
pub struct IterationInputs {
    /// Built from `match_left`, `match_right` (`desc(conv(features[0]))`) and `cost_agg`'s output.
    pub geo: GeoEncodingVolume,
    /// `[B,1,h,w]` soft-argmin of the classifier (1/4-resolution pixels).
    pub init_disp: Tensor<4>,
    /// `[B,1,h,w]` = `interpolate(depth_mono, (h, w), bilinear, align_corners=False)`.
    pub disp_mono_4x: Tensor<4>,
    /// Initial hidden states `[tanh(cnet_4x), tanh(cnet_8x), tanh(cnet_16x)]`; the mono branch
    /// starts from a copy of these (upstream clones them before the loop).
    pub net: [Tensor<4>; 3],
    /// Per level `[cz, cr, cq]` = `context_zqr_convs[i](relu(cnet_i)).split(C)`.
    pub inp: [GruContext; 3],
    /// `features_left[0]`, `features_right[0]` = `cat(f4, stem_4x)` `[B,96,h,w]`.
    pub features_left0: Tensor<4>,
    pub features_right0: Tensor<4>,
    /// `stem_2x` of the left image `[B,32,H/2,W/2]`.
    pub stem_2x: Tensor<4>,
    /// Normalised images `2·(img/255) - 1`, `[B,3,H,W]` (for REMP).
    pub image1: Tensor<4>,
    pub image2: Tensor<4>,
}

/// Result of the loop.
#[derive(Debug, Clone)]
pub struct IterationOutput {
    /// The final full-resolution disparity `disp_up + REMP(mono_up, disp_up, img1, img2)`
    /// `[B,1,H,W]` (upstream's test-mode return value).
    pub disp: Tensor<4>,
    /// Train mode: every prediction in upstream order (`iters-7` stereo predictions, then per
    /// dual-branch iteration `[mono_up, stereo_up]`; the last one equals `disp`). Empty in test
    /// mode.
    pub disp_preds: Vec<Tensor<4>>,
    /// `(scale, shift)` per batch sample of the mono alignment (empty if `iters < 7`).
    pub scale_shift: Vec<(f32, f32)>,
}

/// Runs the `iters` refinement iterations. See [`iterate_traced`].
pub fn iterate(
    blocks: &IterationBlocks<'_>,
    inputs: IterationInputs,
    iters: usize,
    test_mode: bool,
) -> IterationOutput {
    iterate_traced(blocks, inputs, iters, test_mode, &mut |_, _| {})
}

/// [`iterate`] with a trace callback receiving intermediates under the parity fixture's names
/// (`geo_feat.N`, `feat_warp.N`, `update_block.delta.N`, `update_block.{mask_feat,net0,net1,net2}.N`,
/// `update_block_mix_{stereo,mono}.…`, `upsample_disp.N`, `REMP.0`; `N` counts calls). In test
/// mode the skipped upsamplings are not traced.
pub fn iterate_traced(
    blocks: &IterationBlocks<'_>,
    inputs: IterationInputs,
    iters: usize,
    test_mode: bool,
    trace: &mut dyn FnMut(&str, &Tensor<4>),
) -> IterationOutput {
    let run = Loop {
        blocks,
        geo: inputs.geo,
        inp: inputs.inp,
        features_left0: inputs.features_left0,
        features_right0: inputs.features_right0,
        stem_2x: inputs.stem_2x,
        images: [inputs.image1, inputs.image2],
        n: iters as i64,
        test_mode,
    };
    let mut tracer = Tracer {
        trace,
        counts: HashMap::new(),
    };
    let mut net_stereo = inputs.net.clone();
    let mut state = LoopState {
        disp: inputs.init_disp,
        mono: MonoBranch {
            disp_4x: inputs.disp_mono_4x,
            net: inputs.net,
            up: None,
        },
        disp_up: None,
        disp_preds: Vec::new(),
        scale_shift: Vec::new(),
    };
    for itr in 0..run.n {
        (net_stereo, state) = run.iteration(itr, net_stereo, state, &mut tracer);
    }
    IterationOutput {
        disp: state.disp_up.expect("iters >= 1"),
        disp_preds: state.disp_preds,
        scale_shift: state.scale_shift,
    }
}

/// Hands the loop's intermediates to the trace callback as `name.N`, `N` counting the calls
/// of each name.
struct Tracer<'t> {
    trace: &'t mut dyn FnMut(&str, &Tensor<4>),
    counts: HashMap<String, usize>,
}

impl Tracer<'_> {
    fn emit(&mut self, name: &str, t: &Tensor<4>) {
        let n = self.counts.entry(name.to_string()).or_insert(0);
        (self.trace)(&format!("{name}.{n}"), t);
        *n += 1;
    }

    /// An update block's outputs: `prefix.delta`, `prefix.mask_feat`, `prefix.net0..2`.
    fn emit_block(&mut self, prefix: &str, out: &UpdateOut) {
        self.emit(&format!("{prefix}.delta"), &out.delta);
        self.emit(&format!("{prefix}.mask_feat"), &out.mask_feat);
        for (i, n) in out.net.iter().enumerate() {
            self.emit(&format!("{prefix}.net{i}"), n);
        }
    }
}

/// What the loop reads and does not change: the modules, the inputs, `n` iterations.
struct Loop<'a> {
    blocks: &'a IterationBlocks<'a>,
    geo: GeoEncodingVolume,
    inp: [GruContext; 3],
    features_left0: Tensor<4>,
    features_right0: Tensor<4>,
    stem_2x: Tensor<4>,
    /// The normalised left and right images (for REMP).
    images: [Tensor<4>; 2],
    n: i64,
    test_mode: bool,
}

/// The mono branch of the last seven iterations: its 1/4 disparity (the aligned mono depth
/// after iteration `n − 7`), its hidden states and its latest full-resolution prediction.
struct MonoBranch {
    disp_4x: Tensor<4>,
    net: [Tensor<4>; 3],
    up: Option<Tensor<4>>,
}

/// What the loop carries between iterations besides the stereo hidden states.
struct LoopState {
    /// The stereo disparity at 1/4 resolution.
    disp: Tensor<4>,
    mono: MonoBranch,
    /// The latest full-resolution stereo prediction.
    disp_up: Option<Tensor<4>>,
    disp_preds: Vec<Tensor<4>>,
    scale_shift: Vec<(f32, f32)>,
}

impl Loop<'_> {
    /// Iteration `itr`: the geometry lookup at the current disparity, a GRU update (of the
    /// stereo branch alone before the last seven iterations, of both in them), the disparity
    /// step, and its full-resolution prediction where one is kept. Returns the new stereo
    /// hidden states and state.
    fn iteration(
        &self,
        itr: i64,
        net: [Tensor<4>; 3],
        mut state: LoopState,
        tracer: &mut Tracer<'_>,
    ) -> ([Tensor<4>; 3], LoopState) {
        state.disp = state.disp.detach();
        if itr >= 1 {
            state.mono.disp_4x = state.mono.disp_4x.detach();
        }
        let geo_feat = span(GEO, || self.geo.lookup(&state.disp));
        tracer.emit("geo_feat", &geo_feat);
        let out = if itr <= self.n - 8 {
            let out = span(GRU, || {
                self.blocks
                    .update_block
                    .forward(net, &self.inp, geo_feat, state.disp.clone())
            });
            tracer.emit_block("update_block", &out);
            out
        } else {
            let out;
            (out, state) = self.dual_branch_update(itr, net, state, geo_feat, tracer);
            out
        };
        state.disp = state.disp + out.delta;
        if !self.test_mode || itr == self.n - 1 {
            self.predict(itr, &mut state, out.mask_feat, tracer);
        }
        (out.net, state)
    }

    /// The mutual refinement of iterations `n − 7` onwards: the mono disparity aligned to the
    /// stereo one (at the first), both branches' features warped by their disparities, then
    /// each branch's update block fed its own and the other's; the mono branch steps and
    /// upsamples here. Returns the stereo block's output.
    fn dual_branch_update(
        &self,
        itr: i64,
        net: [Tensor<4>; 3],
        mut state: LoopState,
        geo_feat: Tensor<4>,
        tracer: &mut Tracer<'_>,
    ) -> (UpdateOut, LoopState) {
        let (warped_mono, warped_stereo) = span("mutual refinement (warp, scale/shift)", || {
            if itr == self.n - 7 {
                let (aligned, params) = align_mono(state.mono.disp_4x.clone(), &state.disp);
                state.mono.disp_4x = aligned;
                state.scale_shift = params;
            }
            (
                disp_warp(self.features_right0.clone(), state.mono.disp_4x.clone()),
                disp_warp(self.features_right0.clone(), state.disp.clone()),
            )
        });
        tracer.emit("feat_warp", &warped_mono);
        let flaw_mono = warped_mono - self.features_left0.clone();
        tracer.emit("feat_warp", &warped_stereo);
        let flaw_stereo = warped_stereo - self.features_left0.clone();
        let geo_feat_mono = span(GEO, || self.geo.lookup(&state.mono.disp_4x));
        let stereo = Branch {
            disp: state.disp.clone(),
            corr: geo_feat,
            flaw: flaw_stereo,
        };
        let mono = Branch {
            disp: state.mono.disp_4x.clone(),
            corr: geo_feat_mono,
            flaw: flaw_mono,
        };
        let blocks = self.blocks;
        let out = span(GRU, || {
            blocks
                .update_block_mix_stereo
                .forward(net, &self.inp, &stereo, &mono)
        });
        tracer.emit_block("update_block_mix_stereo", &out);
        let out_m = span(GRU, || {
            blocks
                .update_block_mix_mono
                .forward(state.mono.net, &self.inp, &mono, &stereo)
        });
        tracer.emit_block("update_block_mix_mono", &out_m);
        state.mono.disp_4x = state.mono.disp_4x + out_m.delta;
        state.mono.net = out_m.net;
        if !self.test_mode || itr == self.n - 1 {
            let up = self.upsample(state.mono.disp_4x.clone(), out_m.mask_feat, tracer);
            if !self.test_mode {
                state.disp_preds.push(up.clone());
            }
            state.mono.up = Some(up);
        }
        (out, state)
    }

    /// The stereo disparity's full-resolution prediction, at the last iteration refined by
    /// REMP with the mono branch's; kept as the latest and, in training, as a prediction.
    fn predict(
        &self,
        itr: i64,
        state: &mut LoopState,
        mask_feat: Tensor<4>,
        tracer: &mut Tracer<'_>,
    ) {
        let mut up = self.upsample(state.disp.clone(), mask_feat, tracer);
        if itr == self.n - 1 {
            let mono = state
                .mono
                .up
                .clone()
                .expect("the last iteration is a dual-branch one");
            let [image1, image2] = self.images.clone();
            let refined = span("remp", || {
                self.blocks.remp.forward(mono, up.clone(), image1, image2)
            });
            tracer.emit("REMP", &refined);
            up = up + refined; // quirk 4: disp_up + LeakyReLU(disp_up + residual)
        }
        if !self.test_mode {
            state.disp_preds.push(up.clone());
        }
        state.disp_up = Some(up);
    }

    /// A 1/4 disparity upsampled to full resolution by the convex mask from `mask_feat`.
    fn upsample(
        &self,
        disp: Tensor<4>,
        mask_feat: Tensor<4>,
        tracer: &mut Tracer<'_>,
    ) -> Tensor<4> {
        let up = span(UPSAMPLING, || {
            upsample_disp(
                self.blocks.spx_2_gru,
                self.blocks.spx_gru,
                disp,
                mask_feat,
                self.stem_2x.clone(),
            )
        });
        tracer.emit("upsample_disp", &up);
        up
    }
}

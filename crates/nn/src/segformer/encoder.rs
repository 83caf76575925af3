//! The Mix Transformer encoder of SegFormer (HF `SegformerEncoder`), eval mode.
//!
//! Field names mirror the HF keys (`segformer.encoder.block.0.1.attention.self.sr.weight`, …) so
//! weights load by path; the one exception is `attention.self`, a Rust keyword, which is the field
//! `self_attn` here (the loader renames the key, see [`super::model::torch_key`]).
//! Every LayerNorm has eps 1e-5 (HF builds them without an eps argument).

use burn::module::Module;
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::nn::{LayerNorm, LayerNormConfig, Linear, LinearConfig, PaddingConfig2d};
use burn::tensor::activation::softmax;
use burn::tensor::{Device, Tensor};

use crate::attention::gelu_erf;

use super::config::SegformerConfig;
use super::trace::Trace;

/// LayerNorm eps of every HF SegFormer LayerNorm.
pub const LAYER_NORM_EPS: f64 = 1e-5;

fn layer_norm(c: usize, device: &Device) -> LayerNorm {
    LayerNormConfig::new(c)
        .with_epsilon(LAYER_NORM_EPS)
        .init(device)
}

/// B×C×h×w → B×(h·w)×C, tokens row-major.
pub fn to_tokens(x: Tensor<4>) -> Tensor<3> {
    let [b, c, h, w] = x.dims();
    x.reshape([b, c, h * w]).swap_dims(1, 2)
}

/// B×(h·w)×C → B×C×h×w.
pub fn to_map(x: Tensor<3>, h: usize, w: usize) -> Tensor<4> {
    let [b, n, c] = x.dims();
    assert_eq!(n, h * w, "{n} tokens do not form a {h}×{w} map");
    x.swap_dims(1, 2).reshape([b, c, h, w])
}

/// Overlapping patch embedding: Conv2d(k, stride s, padding k/2) then LayerNorm on the tokens.
#[derive(Module, Debug)]
pub struct OverlapPatchEmbeddings {
    /// The strided convolution.
    pub proj: Conv2d,
    /// LayerNorm of the tokens.
    pub layer_norm: LayerNorm,
}

impl OverlapPatchEmbeddings {
    fn new(c_in: usize, c_out: usize, k: usize, s: usize, device: &Device) -> Self {
        Self {
            proj: Conv2dConfig::new([c_in, c_out], [k, k])
                .with_stride([s, s])
                .with_padding(PaddingConfig2d::Explicit(k / 2, k / 2, k / 2, k / 2))
                .init(device),
            layer_norm: layer_norm(c_out, device),
        }
    }

    /// B×C_in×H×W → (B×N×C, h, w).
    pub fn forward(&self, x: Tensor<4>) -> (Tensor<3>, usize, usize) {
        let y = self.proj.forward(x);
        let [_, _, h, w] = y.dims();
        (self.layer_norm.forward(to_tokens(y)), h, w)
    }
}

/// Efficient self-attention: keys and values from a spatially reduced copy of the tokens.
#[derive(Module, Debug)]
pub struct EfficientSelfAttention {
    /// C → C.
    pub query: Linear,
    /// C → C.
    pub key: Linear,
    /// C → C.
    pub value: Linear,
    /// Conv2d(C, C, kernel = stride = sr) when sr > 1: drops the last h mod sr rows and
    /// w mod sr columns.
    pub sr: Option<Conv2d>,
    /// LayerNorm after `sr` (present iff `sr` is).
    pub layer_norm: Option<LayerNorm>,
    num_heads: usize,
}

impl EfficientSelfAttention {
    fn new(c: usize, num_heads: usize, sr: usize, device: &Device) -> Self {
        let (sr_conv, sr_norm) = if sr > 1 {
            (
                Some(
                    Conv2dConfig::new([c, c], [sr, sr])
                        .with_stride([sr, sr])
                        .init(device),
                ),
                Some(layer_norm(c, device)),
            )
        } else {
            (None, None)
        };
        Self {
            query: LinearConfig::new(c, c).init(device),
            key: LinearConfig::new(c, c).init(device),
            value: LinearConfig::new(c, c).init(device),
            sr: sr_conv,
            layer_norm: sr_norm,
            num_heads,
        }
    }

    /// The key/value input: the reduced and normalised tokens (B×N'×C), or `x` itself when sr = 1.
    pub fn reduced(&self, x: Tensor<3>, h: usize, w: usize) -> Tensor<3> {
        match (&self.sr, &self.layer_norm) {
            (Some(sr), Some(ln)) => ln.forward(to_tokens(sr.forward(to_map(x, h, w)))),
            _ => x,
        }
    }

    /// `softmax(Q·Kᵀ/√d)·V` per head, heads concatenated (before `attention.output.dense`).
    fn forward(&self, x: Tensor<3>, h: usize, w: usize, trace: &mut Trace, tag: &str) -> Tensor<3> {
        let [b, n, c] = x.dims();
        let heads = self.num_heads;
        let hd = c / heads;
        let split = |t: Tensor<3>| {
            let m = t.dims()[1];
            t.reshape([b, m, heads, hd]).swap_dims(1, 2)
        };
        let q = split(self.query.forward(x.clone()));
        let kv = self.reduced(x, h, w);
        if self.sr.is_some() {
            trace.record(|| format!("{tag}.sr_kv"), &kv);
        }
        let k = split(self.key.forward(kv.clone()));
        let v = split(self.value.forward(kv));
        let scores = q.matmul(k.swap_dims(2, 3)).div_scalar((hd as f64).sqrt());
        softmax(scores, 3)
            .matmul(v)
            .swap_dims(1, 2)
            .reshape([b, n, c])
    }
}

/// `attention.output` of HF: the output projection.
#[derive(Module, Debug)]
pub struct SelfOutput {
    /// C → C.
    pub dense: Linear,
}

/// `attention` of HF: the self-attention (`self`, here `self_attn`) and its output projection.
#[derive(Module, Debug)]
pub struct Attention {
    /// HF `attention.self`.
    pub self_attn: EfficientSelfAttention,
    /// HF `attention.output`.
    pub output: SelfOutput,
}

/// `mlp.dwconv` of HF (a wrapper holding the conv).
#[derive(Module, Debug)]
pub struct DwConv {
    /// Depth-wise Conv2d(4C, 3×3, padding 1, groups 4C).
    pub dwconv: Conv2d,
}

/// Mix-FFN: Linear(C→4C) → depth-wise 3×3 conv → GELU (erf) → Linear(4C→C).
#[derive(Module, Debug)]
pub struct MixFfn {
    /// C → hidden.
    pub dense1: Linear,
    /// The depth-wise conv.
    pub dwconv: DwConv,
    /// hidden → C.
    pub dense2: Linear,
}

impl MixFfn {
    fn new(c: usize, hidden: usize, device: &Device) -> Self {
        Self {
            dense1: LinearConfig::new(c, hidden).init(device),
            dwconv: DwConv {
                dwconv: Conv2dConfig::new([hidden, hidden], [3, 3])
                    .with_groups(hidden)
                    .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
                    .init(device),
            },
            dense2: LinearConfig::new(hidden, c).init(device),
        }
    }

    /// x: B×N×C on an h×w grid.
    pub fn forward(&self, x: Tensor<3>, h: usize, w: usize) -> Tensor<3> {
        let y = self.dense1.forward(x);
        let y = to_tokens(self.dwconv.dwconv.forward(to_map(y, h, w)));
        self.dense2.forward(gelu_erf(y))
    }
}

/// Pre-norm transformer block (HF `SegformerLayer`).
#[derive(Module, Debug)]
pub struct Layer {
    /// LN before attention.
    pub layer_norm_1: LayerNorm,
    /// Efficient attention.
    pub attention: Attention,
    /// LN before the Mix-FFN.
    pub layer_norm_2: LayerNorm,
    /// Mix-FFN.
    pub mlp: MixFfn,
}

impl Layer {
    /// `x += attn(LN1 x); x += mlp(LN2 x)`; `tag` names the trace entries (`stage1.block0`).
    pub fn forward(
        &self,
        x: Tensor<3>,
        h: usize,
        w: usize,
        trace: &mut Trace,
        tag: &str,
    ) -> Tensor<3> {
        let ln1 = self.layer_norm_1.forward(x.clone());
        trace.record(|| format!("{tag}.ln1"), &ln1);
        let attn = self.attention.self_attn.forward(ln1, h, w, trace, tag);
        let attn = self.attention.output.dense.forward(attn);
        trace.record(|| format!("{tag}.attn"), &attn);
        let x = x + attn;
        let mlp = self.mlp.forward(self.layer_norm_2.forward(x.clone()), h, w);
        trace.record(|| format!("{tag}.mlp"), &mlp);
        let x = x + mlp;
        trace.record(|| format!("{tag}.out"), &x);
        x
    }
}

/// The four-stage encoder (HF `SegformerEncoder`).
#[derive(Module, Debug)]
pub struct Encoder {
    /// One overlapping patch embedding per stage.
    pub patch_embeddings: Vec<OverlapPatchEmbeddings>,
    /// `block[stage][layer]`.
    pub block: Vec<Vec<Layer>>,
    /// The LayerNorm closing each stage.
    pub layer_norm: Vec<LayerNorm>,
}

impl Encoder {
    /// Builds the encoder (lazy parameters).
    pub fn new(cfg: &SegformerConfig, device: &Device) -> Self {
        let mut patch_embeddings = Vec::new();
        let mut block = Vec::new();
        let mut norms = Vec::new();
        let mut c_in = cfg.num_channels;
        for i in 0..4 {
            let c = cfg.hidden_sizes[i];
            patch_embeddings.push(OverlapPatchEmbeddings::new(
                c_in,
                c,
                cfg.patch_sizes[i],
                cfg.strides[i],
                device,
            ));
            block.push(
                (0..cfg.depths[i])
                    .map(|_| Layer {
                        layer_norm_1: layer_norm(c, device),
                        attention: Attention {
                            self_attn: EfficientSelfAttention::new(
                                c,
                                cfg.num_attention_heads[i],
                                cfg.sr_ratios[i],
                                device,
                            ),
                            output: SelfOutput {
                                dense: LinearConfig::new(c, c).init(device),
                            },
                        },
                        layer_norm_2: layer_norm(c, device),
                        mlp: MixFfn::new(c, c * cfg.mlp_ratios[i], device),
                    })
                    .collect(),
            );
            norms.push(layer_norm(c, device));
            c_in = c;
        }
        Self {
            patch_embeddings,
            block,
            layer_norm: norms,
        }
    }

    /// The four stage outputs (B×C_i×h_i×w_i) of the normalised image B×3×H×W.
    pub fn forward(&self, pixel_values: Tensor<4>, trace: &mut Trace) -> Vec<Tensor<4>> {
        let mut x = pixel_values;
        let mut outs = Vec::with_capacity(4);
        for (i, embed) in self.patch_embeddings.iter().enumerate() {
            let stage = format!("stage{}", i + 1);
            let (mut t, h, w) = embed.forward(x);
            trace.record(|| format!("{stage}.patch_embed"), &t);
            for (j, layer) in self.block[i].iter().enumerate() {
                t = layer.forward(t, h, w, trace, &format!("{stage}.block{j}"));
            }
            let map = to_map(self.layer_norm[i].forward(t), h, w);
            trace.record(|| format!("{stage}.out"), &map);
            outs.push(map.clone());
            x = map;
        }
        outs
    }
}

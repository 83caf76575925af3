//! DINOv2 encoder of the mono branch (`mono_encoder`, `monsterpp.md` §2.1 step 2) and the mono
//! input preparation.
//!
//! Field names mirror the PyTorch keys (`mono_encoder.patch_embed.proj.weight`,
//! `blocks.N.attn.qkv`, `ls1.gamma`, `norm1`, …) so that weights load by path with
//! [`crate::weights`].

use burn::module::{Module, Param};
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::nn::{Initializer, LayerNorm, LayerNormConfig, Linear, LinearConfig};
use burn::tensor::{Device, Tensor, TensorData};

use crate::attention::{attention_qkv, gelu_erf};
use crate::config::VitConfig;
use crate::resize::resize_bilinear;

/// `img = 2·(img/255) − 1` (images are float 0–255 RGB, B×3×H×W); used by both branches.
pub fn normalize_image(img: Tensor<4>) -> Tensor<4> {
    img.div_scalar(255.0).mul_scalar(2.0).sub_scalar(1.0)
}

/// The mono-branch input: bilinear resize of the normalised image by 14/16 with
/// align_corners = True → B×3×⌊7H/8⌋×⌊7W/8⌋.
pub fn mono_input(img_normalized: Tensor<4>) -> Tensor<4> {
    let [_, _, h, w] = img_normalized.dims();
    let size = [
        (h as f64 * 14.0 / 16.0).floor() as usize,
        (w as f64 * 14.0 / 16.0).floor() as usize,
    ];
    resize_bilinear(img_normalized, size, true)
}

/// Conv2d 3→E, kernel = stride = patch size.
#[derive(Module, Debug)]
pub struct PatchEmbed {
    /// The patch projection.
    pub proj: Conv2d,
}

/// Multi-head self-attention with a fused qkv projection.
#[derive(Module, Debug)]
pub struct Attention {
    /// E → 3E.
    pub qkv: Linear,
    /// E → E.
    pub proj: Linear,
    num_heads: usize,
}

impl Attention {
    /// x: B×N×E.
    pub fn forward(&self, x: Tensor<3>) -> Tensor<3> {
        let [b, n, e] = x.dims();
        let h = self.num_heads;
        let hd = e / h;
        let qkv = self.qkv.forward(x);
        let out = attention_qkv(qkv, h, (hd as f64).powf(-0.5) as f32);
        debug_assert_eq!(out.dims(), [b, n, e]);
        self.proj.forward(out)
    }
}

/// Per-channel scale (`ls1`, `ls2`).
#[derive(Module, Debug)]
pub struct LayerScale {
    /// E.
    pub gamma: Param<Tensor<1>>,
}

impl LayerScale {
    /// x · gamma over the last dim.
    pub fn forward(&self, x: Tensor<3>) -> Tensor<3> {
        x * self.gamma.val().unsqueeze::<3>()
    }
}

/// fc1 → GELU (erf) → fc2.
#[derive(Module, Debug)]
pub struct Mlp {
    /// E → hidden.
    pub fc1: Linear,
    /// hidden → E.
    pub fc2: Linear,
}

impl Mlp {
    /// x: B×N×E.
    pub fn forward(&self, x: Tensor<3>) -> Tensor<3> {
        self.fc2.forward(gelu_erf(self.fc1.forward(x)))
    }
}

/// Pre-norm transformer block with LayerScale.
#[derive(Module, Debug)]
pub struct Block {
    /// LN before attention (eps 1e-6).
    pub norm1: LayerNorm,
    /// Self-attention.
    pub attn: Attention,
    /// LayerScale after attention.
    pub ls1: LayerScale,
    /// LN before the MLP.
    pub norm2: LayerNorm,
    /// The MLP.
    pub mlp: Mlp,
    /// LayerScale after the MLP.
    pub ls2: LayerScale,
}

impl Block {
    /// `x += ls1·attn(norm1 x); x += ls2·mlp(norm2 x)`.
    pub fn forward(&self, x: Tensor<3>) -> Tensor<3> {
        let x = x.clone() + self.ls1.forward(self.attn.forward(self.norm1.forward(x)));
        x.clone() + self.ls2.forward(self.mlp.forward(self.norm2.forward(x)))
    }
}

/// The four intermediate layers of the ViT (already through the final norm).
#[derive(Debug, Clone)]
pub struct VitFeatures {
    /// Patch tokens per layer, B×N×E with N = gh·gw (row-major).
    pub tokens: Vec<Tensor<3>>,
    /// Class tokens per layer, B×E (unused by MonSter, kept for parity checks).
    pub cls: Vec<Tensor<2>>,
    /// Token grid (gh, gw) = (H'/14, W'/14) of the ViT input.
    pub grid: (usize, usize),
}

/// DINOv2 `DinoVisionTransformer` (`mono_encoder`).
#[derive(Module, Debug)]
pub struct DinoVisionTransformer {
    /// 1×1×E.
    pub cls_token: Param<Tensor<3>>,
    /// 1×(1+G²)×E, G = 37.
    pub pos_embed: Param<Tensor<3>>,
    /// 1×E, present in checkpoints, unused.
    pub mask_token: Param<Tensor<2>>,
    /// Patch embedding.
    pub patch_embed: PatchEmbed,
    /// Transformer blocks.
    pub blocks: Vec<Block>,
    /// Final LN (eps 1e-6).
    pub norm: LayerNorm,
    patch_size: usize,
    pos_grid: usize,
    interpolate_offset: f64,
    intermediate_layers: [usize; 4],
}

impl DinoVisionTransformer {
    /// Builds the encoder (lazy parameters: cheap until weights are loaded or used).
    pub fn new(cfg: &VitConfig, device: &Device) -> Self {
        let e = cfg.embed_dim;
        let g = cfg.pos_grid;
        let ln = || LayerNormConfig::new(e).with_epsilon(1e-6).init(device);
        let blocks = (0..cfg.depth)
            .map(|_| Block {
                norm1: ln(),
                attn: Attention {
                    qkv: LinearConfig::new(e, 3 * e).init(device),
                    proj: LinearConfig::new(e, e).init(device),
                    num_heads: cfg.num_heads,
                },
                ls1: LayerScale {
                    gamma: Initializer::Ones.init([e], device),
                },
                norm2: ln(),
                mlp: Mlp {
                    fc1: LinearConfig::new(e, cfg.mlp_hidden()).init(device),
                    fc2: LinearConfig::new(cfg.mlp_hidden(), e).init(device),
                },
                ls2: LayerScale {
                    gamma: Initializer::Ones.init([e], device),
                },
            })
            .collect();
        let init = Initializer::Normal {
            mean: 0.0,
            std: 0.02,
        };
        Self {
            cls_token: init.init([1, 1, e], device),
            pos_embed: init.init([1, 1 + g * g, e], device),
            mask_token: Initializer::Zeros.init([1, e], device),
            patch_embed: PatchEmbed {
                proj: Conv2dConfig::new([3, e], [cfg.patch_size, cfg.patch_size])
                    .with_stride([cfg.patch_size, cfg.patch_size])
                    .init(device),
            },
            blocks,
            norm: ln(),
            patch_size: cfg.patch_size,
            pos_grid: g,
            interpolate_offset: cfg.interpolate_offset,
            intermediate_layers: cfg.intermediate_layers,
        }
    }

    /// Token width E.
    pub fn embed_dim(&self) -> usize {
        self.norm.gamma.lazy_shape().as_slice()[0]
    }

    /// Pos-embed for a gh×gw token grid: 1×(1+gh·gw)×E (cls first). The grid part is the
    /// PyTorch `F.interpolate(scale_factor=((gh+0.1)/G, (gw+0.1)/G), mode='bicubic',
    /// align_corners=False)`: source coordinate (dst+0.5)·G/(n+0.1) − 0.5, A = −0.75, clamped taps.
    pub fn interpolate_pos_embed(&self, gh: usize, gw: usize) -> Tensor<3> {
        let pos = self.pos_embed.val();
        let [_, n1, e] = pos.dims();
        let g = self.pos_grid;
        let device = pos.device();
        let cls = pos.clone().slice([0..1, 0..1]);
        let grid = pos.slice([0..1, 1..n1]).reshape([g, g * e]);
        let wh = Tensor::<2>::from_data(
            TensorData::new(
                bicubic_matrix(gh, g, (gh as f64 + self.interpolate_offset) / g as f64),
                [gh, g],
            ),
            &device,
        );
        let ww = Tensor::<2>::from_data(
            TensorData::new(
                bicubic_matrix(gw, g, (gw as f64 + self.interpolate_offset) / g as f64),
                [gw, g],
            ),
            &device,
        );
        // rows: [gh, G·E] → [gh, G, E]; then columns with a batched matmul over gh.
        let t1 = wh.matmul(grid).reshape([gh, g, e]);
        let ww3 = ww.unsqueeze::<3>().expand([gh, gw, g]);
        let out = ww3.matmul(t1).reshape([1, gh * gw, e]);
        Tensor::cat(vec![cls, out], 1)
    }

    /// Patch embedding + cls token + interpolated pos-embed: B×(1+N)×E.
    pub fn prepare_tokens(&self, x: Tensor<4>) -> (Tensor<3>, (usize, usize)) {
        let [b, _, h, w] = x.dims();
        let (gh, gw) = (h / self.patch_size, w / self.patch_size);
        let t = self.patch_embed.proj.forward(x); // B×E×gh×gw
        let e = t.dims()[1];
        let t = t.reshape([b, e, gh * gw]).swap_dims(1, 2);
        let cls = self.cls_token.val().expand([b, 1, e]);
        let t = Tensor::cat(vec![cls, t], 1);
        (t + self.interpolate_pos_embed(gh, gw), (gh, gw))
    }

    /// `get_intermediate_layers(x, layers, return_class_token=True, norm=True)` on the (resized,
    /// normalised) ViT input B×3×H'×W'.
    pub fn forward_intermediate(&self, x: Tensor<4>) -> VitFeatures {
        let (mut t, grid) = self.prepare_tokens(x);
        let last = *self.intermediate_layers.iter().max().unwrap_or(&0);
        let mut tokens = Vec::with_capacity(4);
        let mut cls = Vec::with_capacity(4);
        for (i, blk) in self.blocks.iter().enumerate().take(last + 1) {
            t = blk.forward(t);
            if self.intermediate_layers.contains(&i) {
                let normed = self.norm.forward(t.clone());
                let [b, n1, e] = normed.dims();
                cls.push(normed.clone().slice([0..b, 0..1]).reshape([b, e]));
                tokens.push(normed.slice([0..b, 1..n1]));
            }
        }
        VitFeatures { tokens, cls, grid }
    }
}

/// Interpolation matrix (out × inp) of PyTorch's bicubic upsampling with an explicit scale factor,
/// align_corners = False: src = (dst + 0.5)/scale − 0.5, A = −0.75, taps clamped to the border.
pub fn bicubic_matrix(out: usize, inp: usize, scale_factor: f64) -> Vec<f32> {
    const A: f64 = -0.75;
    let cc1 = |x: f64| ((A + 2.0) * x - (A + 3.0)) * x * x + 1.0;
    let cc2 = |x: f64| ((A * x - 5.0 * A) * x + 8.0 * A) * x - 4.0 * A;
    let mut m = vec![0f32; out * inp];
    let scale = 1.0 / scale_factor;
    for d in 0..out {
        let src = (d as f64 + 0.5) * scale - 0.5;
        let i0 = src.floor();
        let t = src - i0;
        let coeffs = [cc2(t + 1.0), cc1(t), cc1(1.0 - t), cc2(2.0 - t)];
        for (k, c) in coeffs.iter().enumerate() {
            let idx = (i0 as i64 - 1 + k as i64).clamp(0, inp as i64 - 1) as usize;
            m[d * inp + idx] += *c as f32;
        }
    }
    m
}

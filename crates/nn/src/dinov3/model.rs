//! The HF `DINOv3ViTModel` network (eval mode) on burn.
//!
//! Field names mirror the HF keys (`embeddings.patch_embeddings.weight`, `layer.N.attention.q_proj`,
//! `layer.N.norm1`, `norm`) so that checkpoints load by path with [`crate::weights`]; the MLP and
//! the layer scales reuse the DINOv2 modules of [`crate::monster::vit`] and are renamed while
//! loading (see [`super::load`]).

use burn::module::{Module, Param};
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::nn::{Initializer, LayerNorm, LayerNormConfig, Linear, LinearConfig};
use burn::tensor::activation::softmax;
use burn::tensor::{Device, Tensor};

use super::config::Dinov3Config;
use super::rope::Rope;
use crate::monster::vit::{LayerScale, Mlp};

/// Patch embedding and the prefix tokens (`embeddings.*`).
#[derive(Module, Debug)]
pub struct Embeddings {
    /// 1×1×D.
    pub cls_token: Param<Tensor<3>>,
    /// 1×1×D; used only for masked-image training, present in every checkpoint.
    pub mask_token: Param<Tensor<3>>,
    /// 1×R×D.
    pub register_tokens: Param<Tensor<3>>,
    /// Conv2d 3→D, kernel = stride = patch; a size that is not a multiple of the patch drops the
    /// remainder, as torch does.
    pub patch_embeddings: Conv2d,
}

impl Embeddings {
    /// `[CLS, registers, patches (row-major)]`: B×(1+R+N)×D. No absolute position embedding.
    pub fn forward(&self, pixel_values: Tensor<4>) -> Tensor<3> {
        let b = pixel_values.dims()[0];
        let p = self.patch_embeddings.forward(pixel_values); // B×D×gh×gw
        let [_, d, gh, gw] = p.dims();
        let patches = p.reshape([b, d, gh * gw]).swap_dims(1, 2);
        let r = self.register_tokens.dims()[1];
        let cls = self.cls_token.val().expand([b, 1, d]);
        let registers = self.register_tokens.val().expand([b, r, d]);
        Tensor::cat(vec![cls, registers, patches], 1)
    }
}

/// Multi-head self-attention with separate projections and RoPE on the patch tokens.
#[derive(Module, Debug)]
pub struct Attention {
    /// D→D, bias.
    pub q_proj: Linear,
    /// D→D, no bias in the released models.
    pub k_proj: Linear,
    /// D→D, bias.
    pub v_proj: Linear,
    /// D→D, bias.
    pub o_proj: Linear,
    num_heads: usize,
}

impl Attention {
    /// x: B×T×D (T = prefix + patches) → B×T×D after `o_proj`.
    pub fn forward(&self, x: Tensor<3>, rope: &Rope, prefix: usize) -> Tensor<3> {
        let [b, t, d] = x.dims();
        let h = self.num_heads;
        let hd = d / h;
        let heads = |y: Tensor<3>| y.reshape([b, t, h, hd]).swap_dims(1, 2);
        let q = rope.apply(heads(self.q_proj.forward(x.clone())), prefix);
        let k = rope.apply(heads(self.k_proj.forward(x.clone())), prefix);
        let v = heads(self.v_proj.forward(x));
        // softmax(q·kᵀ · hd^-½)·v; hd^-½ = 1/8 for head_dim 64, an exact power of two.
        let scores = q
            .matmul(k.swap_dims(2, 3))
            .mul_scalar((hd as f64).powf(-0.5));
        let out = softmax(scores, 3)
            .matmul(v)
            .swap_dims(1, 2)
            .reshape([b, t, d]);
        self.o_proj.forward(out)
    }
}

/// One pre-norm transformer layer (`layer.N`).
#[derive(Module, Debug)]
pub struct Layer {
    /// LN before attention.
    pub norm1: LayerNorm,
    /// Self-attention.
    pub attention: Attention,
    /// λ1 (`layer_scale1.lambda1`).
    pub layer_scale1: LayerScale,
    /// LN before the MLP.
    pub norm2: LayerNorm,
    /// `up_proj` (loaded as `fc1`) → GELU (erf) → `down_proj` (`fc2`).
    pub mlp: Mlp,
    /// λ2 (`layer_scale2.lambda1`).
    pub layer_scale2: LayerScale,
}

impl Layer {
    /// `x += λ1·attn(norm1 x); x += λ2·mlp(norm2 x)`.
    pub fn forward(&self, x: Tensor<3>, rope: &Rope, prefix: usize) -> Tensor<3> {
        let a = self
            .attention
            .forward(self.norm1.forward(x.clone()), rope, prefix);
        let x = x + self.layer_scale1.forward(a);
        let m = self.mlp.forward(self.norm2.forward(x.clone()));
        x + self.layer_scale2.forward(m)
    }
}

/// HF `DINOv3ViTModel`: embeddings, layers, final LayerNorm.
#[derive(Module, Debug)]
pub struct Dinov3Vit {
    /// Patch conv and prefix tokens.
    pub embeddings: Embeddings,
    /// Transformer layers.
    pub layer: Vec<Layer>,
    /// Final LayerNorm.
    pub norm: LayerNorm,
    patch_size: usize,
    head_dim: usize,
    rope_theta: f64,
}

impl Dinov3Vit {
    /// Builds the network (lazy parameters: cheap until weights are loaded or used). Call
    /// [`Dinov3Config::validate`] first.
    pub fn new(cfg: &Dinov3Config, device: &Device) -> Self {
        let d = cfg.hidden_size;
        let ln = || {
            LayerNormConfig::new(d)
                .with_epsilon(cfg.layer_norm_eps)
                .init(device)
        };
        let linear =
            |i: usize, o: usize, bias: bool| LinearConfig::new(i, o).with_bias(bias).init(device);
        let layer = (0..cfg.num_hidden_layers)
            .map(|_| Layer {
                norm1: ln(),
                attention: Attention {
                    q_proj: linear(d, d, cfg.query_bias),
                    k_proj: linear(d, d, cfg.key_bias),
                    v_proj: linear(d, d, cfg.value_bias),
                    o_proj: linear(d, d, cfg.proj_bias),
                    num_heads: cfg.num_attention_heads,
                },
                layer_scale1: LayerScale {
                    gamma: Initializer::Ones.init([d], device),
                },
                norm2: ln(),
                mlp: Mlp {
                    fc1: linear(d, cfg.intermediate_size, cfg.mlp_bias),
                    fc2: linear(cfg.intermediate_size, d, cfg.mlp_bias),
                },
                layer_scale2: LayerScale {
                    gamma: Initializer::Ones.init([d], device),
                },
            })
            .collect();
        let token = Initializer::Normal {
            mean: 0.0,
            std: 0.02,
        };
        Self {
            embeddings: Embeddings {
                cls_token: token.init([1, 1, d], device),
                mask_token: Initializer::Zeros.init([1, 1, d], device),
                register_tokens: token.init([1, cfg.num_register_tokens, d], device),
                patch_embeddings: Conv2dConfig::new([3, d], [cfg.patch_size, cfg.patch_size])
                    .with_stride([cfg.patch_size, cfg.patch_size])
                    .init(device),
            },
            layer,
            norm: ln(),
            patch_size: cfg.patch_size,
            head_dim: cfg.head_dim(),
            rope_theta: cfg.rope_theta,
        }
    }

    /// Number of tokens before the patches (CLS + registers).
    pub fn num_prefix_tokens(&self) -> usize {
        1 + self.embeddings.register_tokens.dims()[1]
    }

    /// The patch grid (n_h, n_w) of a `height × width` input.
    pub fn patch_grid(&self, height: usize, width: usize) -> (usize, usize) {
        (height / self.patch_size, width / self.patch_size)
    }

    /// RoPE tables for the patch grid of a `height × width` input.
    pub fn rope(&self, height: usize, width: usize, device: &Device) -> Rope {
        let (gh, gw) = self.patch_grid(height, width);
        Rope::new(gh, gw, self.head_dim, self.rope_theta, device)
    }

    /// `last_hidden_state` (B×(1+R+N)×D, after the final LayerNorm) of B×3×H×W pixel values,
    /// plus each layer's output (before the final norm) when `keep_layers` is set.
    pub fn forward_layers(
        &self,
        pixel_values: Tensor<4>,
        keep_layers: bool,
    ) -> (Tensor<3>, Vec<Tensor<3>>) {
        let [_, _, h, w] = pixel_values.dims();
        let rope = self.rope(h, w, &pixel_values.device());
        let prefix = self.num_prefix_tokens();
        let mut x = self.embeddings.forward(pixel_values);
        let mut kept = Vec::new();
        for layer in &self.layer {
            x = layer.forward(x, &rope, prefix);
            if keep_layers {
                kept.push(x.clone());
            }
        }
        (self.norm.forward(x), kept)
    }

    /// `last_hidden_state` of B×3×H×W pixel values (H, W ≥ one patch).
    pub fn forward(&self, pixel_values: Tensor<4>) -> Tensor<3> {
        self.forward_layers(pixel_values, false).0
    }

    /// `pooler_output`: the CLS token of `last_hidden_state`, B×D.
    pub fn pooler(last_hidden_state: Tensor<3>) -> Tensor<2> {
        let [b, _, d] = last_hidden_state.dims();
        last_hidden_state.narrow(1, 0, 1).reshape([b, d])
    }
}

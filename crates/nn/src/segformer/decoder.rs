//! The all-MLP decode head of SegFormer (HF `SegformerDecodeHead`), eval mode.

use burn::module::Module;
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::nn::{BatchNorm, BatchNormConfig, Linear, LinearConfig};
use burn::tensor::activation::relu;
use burn::tensor::{Device, Tensor};

use super::config::SegformerConfig;
use super::encoder::{to_map, to_tokens};
use super::trace::Trace;
use crate::resize::resize_bilinear;

/// `decode_head.linear_c.i` of HF: a per-pixel projection C_i → D.
#[derive(Module, Debug)]
pub struct LinearC {
    /// C_i → D.
    pub proj: Linear,
}

/// Projects the four stage maps to D channels, upsamples them to the stage-1 grid, concatenates
/// them (stage 4, 3, 2, 1), fuses (1×1 conv, BatchNorm with running statistics, ReLU) and
/// classifies (1×1 conv). Dropout is an identity at inference.
#[derive(Module, Debug)]
pub struct DecodeHead {
    /// One projection per stage.
    pub linear_c: Vec<LinearC>,
    /// Conv2d 1×1, 4D → D, no bias.
    pub linear_fuse: Conv2d,
    /// BatchNorm2d(D), eps 1e-5.
    pub batch_norm: BatchNorm,
    /// Conv2d 1×1, D → classes, with bias.
    pub classifier: Conv2d,
}

impl DecodeHead {
    /// Builds the head (lazy parameters).
    pub fn new(cfg: &SegformerConfig, device: &Device) -> Self {
        let d = cfg.decoder_hidden_size;
        Self {
            linear_c: cfg
                .hidden_sizes
                .iter()
                .map(|&c| LinearC {
                    proj: LinearConfig::new(c, d).init(device),
                })
                .collect(),
            linear_fuse: Conv2dConfig::new([4 * d, d], [1, 1])
                .with_bias(false)
                .init(device),
            batch_norm: BatchNormConfig::new(d).with_epsilon(1e-5).init(device),
            classifier: Conv2dConfig::new([d, cfg.num_labels], [1, 1]).init(device),
        }
    }

    /// Logits B×classes×h₁×w₁ from the four stage outputs. With tracing on, the literal HF
    /// computation (projections, upsampling, concatenation, 1×1 fuse); otherwise the same
    /// linear algebra folded (see [`DecodeHead::fused_folded`]).
    pub fn forward(&self, stages: &[Tensor<4>], trace: &mut Trace) -> Tensor<4> {
        let pre_bn = if trace.is_enabled() {
            self.fused_literal(stages, trace)
        } else {
            self.fused_folded(stages)
        };
        let fused = relu(self.batch_norm.forward(pre_bn));
        trace.record(|| "decoder.fused".into(), &fused);
        self.classifier.forward(fused)
    }

    /// `linear_fuse(cat(up(proj₄ x₄), up(proj₃ x₃), up(proj₂ x₂), proj₁ x₁))`, as HF does it.
    fn fused_literal(&self, stages: &[Tensor<4>], trace: &mut Trace) -> Tensor<4> {
        let [_, _, h1, w1] = stages[0].dims();
        let mut maps: Vec<Tensor<4>> = stages
            .iter()
            .zip(&self.linear_c)
            .map(|(x, mlp)| {
                upsample_to(
                    to_map(
                        mlp.proj.forward(to_tokens(x.clone())),
                        x.dims()[2],
                        x.dims()[3],
                    ),
                    h1,
                    w1,
                )
            })
            .collect();
        maps.reverse();
        let concat = Tensor::cat(maps, 1);
        trace.record(|| "decoder.concat".into(), &concat);
        self.linear_fuse.forward(concat)
    }

    /// The same value as [`DecodeHead::fused_literal`] up to float rounding, at a fraction of the
    /// cost: the 1×1 fuse is linear and bilinear upsampling is a per-channel linear map whose
    /// weights sum to 1, so `W·cat(up(Pᵢxᵢ))` = `Σᵢ up((Wᵢ∘Pᵢ) xᵢ)` with the fuse block Wᵢ folded
    /// into each projection. Each stage is then projected at its own resolution and the
    /// 4D-channel map at the stage-1 size (768 × 3072 per pixel for mit-b2) is never built.
    pub fn fused_folded(&self, stages: &[Tensor<4>]) -> Tensor<4> {
        let [_, _, h1, w1] = stages[0].dims();
        let fuse = self.linear_fuse.weight.val();
        let [d, d4, _, _] = fuse.dims();
        let fuse = fuse.reshape([d, d4]);
        let n = self.linear_c.len();
        let mut sum: Option<Tensor<4>> = None;
        for (i, (x, mlp)) in stages.iter().zip(&self.linear_c).enumerate() {
            // Concatenation order is stage 4, 3, 2, 1: stage i sits at block n-1-i.
            let block = fuse.clone().narrow(1, (n - 1 - i) * d, d); // [D out, D in]
            let block_t = block.transpose(); // [D in, D out]
            let weight = mlp.proj.weight.val().matmul(block_t.clone()); // [C_i, D]
            let [_, _, h, w] = x.dims();
            let mut y = to_tokens(x.clone()).matmul(weight.unsqueeze::<3>());
            if let Some(b) = &mlp.proj.bias {
                y = y + b.val().unsqueeze::<2>().matmul(block_t).unsqueeze::<3>();
            }
            let y = upsample_to(to_map(y, h, w), h1, w1);
            sum = Some(match sum {
                Some(s) => s + y,
                None => y,
            });
        }
        sum.expect("four stages")
    }
}

/// Bilinear (align_corners = False) to h×w; the identity at the same size.
fn upsample_to(y: Tensor<4>, h: usize, w: usize) -> Tensor<4> {
    let [_, _, hy, wy] = y.dims();
    if (hy, wy) == (h, w) {
        y
    } else {
        resize_bilinear(y, [h, w], false)
    }
}

//! Context network (design §2.4): `feat_transfer_cnet` on the raw DPT paths of the left image and
//! the left stems, then `net = tanh(c)`, `inp = relu(c)` and `context_zqr_convs` (C → 3C, split
//! into cz, cr, cq).
//!
//! Field names mirror the upstream state-dict keys: [`ContextNet`] holds the root-level modules
//! `feat_transfer_cnet` and `context_zqr_convs`; it loads from a full checkpoint with an **empty**
//! key prefix.
//!
//! Shapes (F = DPT `features`, C = hidden dim, 128 upstream, 32 in the tiny fixture): every list
//! is ordered `[1/4 (h×w), 1/8, 1/16]`.

use burn::module::Module;
use burn::nn::conv::Conv2d;
use burn::tensor::{Device, Tensor};

use crate::activation::{relu, tanh};
use crate::conv::conv2d_forward;

use super::features::conv2d;

/// `Feat_transfer_cnet`: Conv3×3 (bias) `(F+192)→C` at 1/16, `(F+96)→C` at 1/8, `(F+48)→C` at 1/4.
#[derive(Module, Debug)]
pub struct FeatTransferCnet {
    pub res_16x: Conv2d,
    pub res_8x: Conv2d,
    pub res_4x: Conv2d,
}

impl FeatTransferCnet {
    /// `f` = DPT `features`, `c` = hidden dim.
    pub fn new(f: usize, c: usize, device: &Device) -> Self {
        Self {
            res_16x: conv2d(f + 192, c, 3, 1, 1, true, device),
            res_8x: conv2d(f + 96, c, 3, 1, 1, true, device),
            res_4x: conv2d(f + 48, c, 3, 1, 1, true, device),
        }
    }

    /// Raw DPT paths of the left image (`feat_decoder` output, `[F×h×w, F×H/8, F×H/16, F×H/32]`; the
    /// last is unused) and the left stems `[stem_4 48×h×w, stem_8 96×H/8, stem_16 192×H/16]` →
    /// context before the activations `[C×h×w, C×H/8, C×H/16]`.
    pub fn forward(
        &self,
        dpt_paths: &[Tensor<4>; 4],
        stems_4_8_16: [Tensor<4>; 3],
    ) -> [Tensor<4>; 3] {
        let [s4, s8, s16] = stems_4_8_16;
        let c16 = conv2d_forward(
            &self.res_16x,
            Tensor::cat(vec![dpt_paths[2].clone(), s16], 1),
        );
        let c8 = conv2d_forward(&self.res_8x, Tensor::cat(vec![dpt_paths[1].clone(), s8], 1));
        let c4 = conv2d_forward(&self.res_4x, Tensor::cat(vec![dpt_paths[0].clone(), s4], 1));
        [c4, c8, c16]
    }
}

/// Output of [`ContextNet::forward`]; every array is ordered `[1/4, 1/8, 1/16]`.
#[derive(Debug, Clone)]
pub struct ContextOutput {
    /// Context before the activations (the upstream `cnet_list`), `[B, C, ·, ·]`.
    pub cnet: [Tensor<4>; 3],
    /// Initial GRU hidden states `tanh(cnet)`. Upstream clones these for the mono branch too.
    pub net: [Tensor<4>; 3],
    /// `relu(cnet)` (upstream `inp_list` before the zqr convs; kept for reference).
    pub inp: [Tensor<4>; 3],
    /// `context_zqr_convs[i](inp[i])` split in three: `[cz, cr, cq]`, each `[B, C, ·, ·]`.
    pub czqr: [[Tensor<4>; 3]; 3],
}

/// The root-level context modules of the upstream `Monster`.
#[derive(Module, Debug)]
pub struct ContextNet {
    pub feat_transfer_cnet: FeatTransferCnet,
    /// Three `Conv2d(C, 3C, 3, padding 1)` with bias, one per GRU level `[1/4, 1/8, 1/16]`.
    pub context_zqr_convs: Vec<Conv2d>,
}

impl ContextNet {
    /// `f` = DPT `features`, `c` = hidden dim (all three `hidden_dims` equal), 3 GRU levels.
    pub fn new(f: usize, c: usize, device: &Device) -> Self {
        Self {
            feat_transfer_cnet: FeatTransferCnet::new(f, c, device),
            context_zqr_convs: (0..3)
                .map(|_| conv2d(c, 3 * c, 3, 1, 1, true, device))
                .collect(),
        }
    }

    /// See [`FeatTransferCnet::forward`] for the inputs.
    pub fn forward(
        &self,
        dpt_paths: &[Tensor<4>; 4],
        stems_4_8_16: [Tensor<4>; 3],
    ) -> ContextOutput {
        let cnet = self.feat_transfer_cnet.forward(dpt_paths, stems_4_8_16);
        let net = cnet.clone().map(tanh);
        let inp = cnet.clone().map(relu);
        let czqr: Vec<[Tensor<4>; 3]> = inp
            .iter()
            .zip(&self.context_zqr_convs)
            .map(|(x, conv)| {
                let y = conv2d_forward(conv, x.clone());
                let c = y.dims()[1] / 3;
                let mut parts = y.split(c, 1).into_iter();
                [
                    parts.next().unwrap(),
                    parts.next().unwrap(),
                    parts.next().unwrap(),
                ]
            })
            .collect();
        let czqr: [[Tensor<4>; 3]; 3] = czqr.try_into().expect("three GRU levels");
        ContextOutput {
            cnet,
            net,
            inp,
            czqr,
        }
    }
}

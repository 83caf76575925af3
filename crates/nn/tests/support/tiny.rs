//! The `monsterpp-tiny` fixture's weights and the refinement loop's parts and inputs, shared by
//! the CPU (`parity_iterations`) and GPU (`parity_gpu`) parity tests.

use burn::module::Module;
use burn::nn::conv::{Conv2d, Conv2dConfig, ConvTranspose2d};
use burn::nn::PaddingConfig2d;
use burn::tensor::activation::{relu, tanh};
use burn::tensor::module::interpolate;
use burn::tensor::ops::{InterpolateMode, InterpolateOptions};
use burn::tensor::{Device, Tensor};

use nn::monster::features::{BasicConvIn, Window};
use nn::monster::geometry::GeoEncodingVolume;
use nn::monster::remp::Remp;
use nn::monster::update::{
    BasicMultiUpdateBlock, BasicMultiUpdateBlockMix2, GruContext, IterationBlocks, IterationInputs,
};
use nn::monster::upsample::{spx_gru_init, Conv2x};
use nn::weights::load_submodule;

use super::Fixture;

/// The fixture set.
pub const FIXTURE: &str = "fixtures/monsterpp-tiny";
/// Hidden width of the tiny configuration.
pub const HIDDEN: usize = 32;

/// The fixture's weights file.
pub fn weights() -> std::path::PathBuf {
    super::fixture_dir(FIXTURE).join("weights.safetensors")
}

/// `m` with the fixture's weights under `prefix`.
pub fn load<M: Module>(mut m: M, prefix: &str) -> M {
    load_submodule(&mut m, weights(), prefix).unwrap_or_else(|e| panic!("{prefix}: {e}"));
    m
}

/// features[0] of one side (`0` left, `1` right): `cat(feat_transfer_0, stem_4)`.
pub fn features0(fx: &Fixture, side: usize) -> Tensor<4> {
    Tensor::cat(
        vec![
            fx.t::<4>(&format!("inter.feat_transfer_0.{side}")),
            fx.t::<4>(&format!("inter.stem_4.{side}")),
        ],
        1,
    )
}

/// The refinement loop's modules, loaded from the fixture's weights.
pub struct Parts {
    pub update_block: BasicMultiUpdateBlock,
    pub mix_stereo: BasicMultiUpdateBlockMix2,
    pub mix_mono: BasicMultiUpdateBlockMix2,
    pub spx_2_gru: Conv2x,
    pub spx_gru: Vec<ConvTranspose2d>,
    pub remp: Remp,
    pub zqr: Vec<Conv2d>,
    pub conv: BasicConvIn,
    pub desc: Conv2d,
}

impl Parts {
    pub fn load(device: &Device) -> Self {
        let zqr = (0..3)
            .map(|_| {
                Conv2dConfig::new([HIDDEN, 3 * HIDDEN], [3, 3])
                    .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
                    .init(device)
            })
            .collect::<Vec<_>>();
        Self {
            update_block: load(
                BasicMultiUpdateBlock::new(HIDDEN, 162, device),
                "update_block.",
            ),
            mix_stereo: load(
                BasicMultiUpdateBlockMix2::new(HIDDEN, 162, 96, device),
                "update_block_mix_stereo.",
            ),
            mix_mono: load(
                BasicMultiUpdateBlockMix2::new(HIDDEN, 162, 96, device),
                "update_block_mix_mono.",
            ),
            spx_2_gru: load(Conv2x::new(32, 32, device), "spx_2_gru."),
            spx_gru: load(spx_gru_init(device), "spx_gru."),
            remp: load(Remp::new(device), "REMP."),
            zqr: load(zqr, "context_zqr_convs."),
            conv: load(
                BasicConvIn::new(96, 96, Window::new(3, 1, 1), device),
                "conv.",
            ),
            desc: load(Conv2dConfig::new([96, 96], [1, 1]).init(device), "desc."),
        }
    }

    pub fn blocks(&self) -> IterationBlocks<'_> {
        IterationBlocks {
            update_block: &self.update_block,
            update_block_mix_stereo: &self.mix_stereo,
            update_block_mix_mono: &self.mix_mono,
            spx_2_gru: &self.spx_2_gru,
            spx_gru: &self.spx_gru[0],
            remp: &self.remp,
        }
    }

    /// The loop's inputs from the fixture intermediates (`inter.cost_agg.0`,
    /// `inter.init_disp_q.0`, `inter.cnet_*`, `inter.feat_transfer_0.*`, `inter.stem_*`,
    /// `output.depth_mono`); matching features go through the `conv`/`desc` weights.
    pub fn inputs(&self, fx: &Fixture) -> IterationInputs {
        let fl = features0(fx, 0);
        let fr = features0(fx, 1);
        let ml = self.desc.forward(self.conv.forward(fl.clone()));
        let mr = self.desc.forward(self.conv.forward(fr.clone()));
        let geo = GeoEncodingVolume::new(ml, mr, fx.t::<5>("inter.cost_agg.0"), 4, 2);
        let cnet: Vec<Tensor<4>> = (0..3)
            .map(|i| fx.t::<4>(&format!("inter.cnet_{i}.0")))
            .collect();
        let net = std::array::from_fn(|i| tanh(cnet[i].clone()));
        let inp: Vec<GruContext> = cnet
            .iter()
            .zip(&self.zqr)
            .map(|(c, conv)| {
                let v = conv.forward(relu(c.clone())).split(HIDDEN, 1);
                [v[0].clone(), v[1].clone(), v[2].clone()]
            })
            .collect();
        let depth_mono = fx.t::<4>("output.depth_mono");
        let [_, _, h, w] = depth_mono.dims();
        let disp_mono_4x = interpolate(
            depth_mono,
            InterpolateOptions::new(InterpolateMode::Bilinear)
                .with_align_corners(false)
                .with_output_size([h / 4, w / 4]),
        );
        IterationInputs {
            geo,
            init_disp: fx.t::<4>("inter.init_disp_q.0"),
            disp_mono_4x,
            net,
            inp: [inp[0].clone(), inp[1].clone(), inp[2].clone()],
            features_left0: fl,
            features_right0: fr,
            stem_2x: fx.t::<4>("inter.stem_2.0"),
            image1: fx.image("left"),
            image2: fx.image("right"),
        }
    }
}

//! SegFormer semantic segmentation (OpenEarthMap classes): the water, tree and building masks of
//! the SeasonStereo release, from one forward pass per image.
//!
//! Port of HF `SegformerForSemanticSegmentation` (`nvidia/mit-b2` layout, 9 OpenEarthMap classes)
//! and of the pre-/post-processing of the release's `infer_{water,tree,building}_openearthmap.py`
//! (`../shared/design/segformer-dinov3.md` Part A). Parity: `tests/parity_segformer.rs` against
//! `../shared/fixtures/segformer-tiny`.
//!
//! ```text
//! let seg = Segmenter::from_file("openearthmap_segformer_mit-b2.pt", SegmenterConfig::release(), &device)?;
//! let out = seg.segment(&image)?;          // 8-bit RGB (or grey) image, any size
//! out.water.png_values()                   // masks/<stem>_mask.png of the water script (0 = water, 255)
//! out.building.probability_u8()            // probs/<stem>_building_prob.png
//! out.tree.percentage_line("a.png")        // a line of tree_percentages.txt
//! ```
//!
//! - [`config::SegformerConfig`]: presets `mit_b2(9)` (the release checkpoint) and `tiny()`.
//! - [`model::Segformer`]: the network; [`model::Segformer::load`] reads the release's `.pt`
//!   (`model_state_dict`, `module.`/`model.` removed) or safetensors in HF naming, strictly.
//! - [`preprocess`]: RGB conversion, PIL bilinear resize to 1000², ImageNet normalisation.
//! - [`postprocess`]: logits → original size, softmax, argmax, masks and their file values.

pub mod config;
pub mod decoder;
pub mod encoder;
mod error;
pub mod model;
pub mod postprocess;
pub mod preprocess;
pub mod trace;

use std::path::Path;

use burn::tensor::Device;
use raster::Image;

pub use config::SegformerConfig;
use dataset::segmentation::{MaskKind, MaskOptions, Segmentation};
pub use model::Segformer;
pub use trace::Trace;

use crate::weights::LoadReport;

pub use error::SegformerError;

/// What a [`Segmenter`] does besides the network: the input size and the per-mask options.
#[derive(Debug, Clone, PartialEq)]
pub struct SegmenterConfig {
    /// The network layout.
    pub model: SegformerConfig,
    /// Network input (width, height); the image is resized to it whatever its aspect ratio.
    pub input_size: (usize, usize),
    /// Options of the water, tree and building masks, in that order.
    pub masks: [MaskOptions; 3],
}

impl SegmenterConfig {
    /// The release: mit-b2 with 9 OpenEarthMap classes, 1000×1000 input, the scripts' defaults.
    pub fn release() -> Self {
        Self::with_model(SegformerConfig::mit_b2(9))
    }

    /// The release's processing around another network layout (e.g. the tiny fixture).
    pub fn with_model(model: SegformerConfig) -> Self {
        Self {
            model,
            input_size: (1000, 1000),
            masks: MaskKind::ALL.map(MaskOptions::defaults),
        }
    }

    /// The options of one mask.
    pub fn mask_mut(&mut self, kind: MaskKind) -> &mut MaskOptions {
        &mut self.masks[MaskKind::ALL.iter().position(|&k| k == kind).unwrap_or(0)]
    }

    fn validate(&self) -> Result<(), SegformerError> {
        self.model.validate().map_err(SegformerError::Input)?;
        let (w, h) = self.input_size;
        if self.model.stage_sizes(h, w).is_none() {
            return Err(SegformerError::Input(format!(
                "input size {w}x{h} is too small for the network"
            )));
        }
        for (kind, m) in MaskKind::ALL.iter().zip(&self.masks) {
            if m.class_id >= self.model.num_labels {
                return Err(SegformerError::Input(format!(
                    "{} class id {} is out of range (the model has {} classes)",
                    kind.name(),
                    m.class_id,
                    self.model.num_labels
                )));
            }
            let finite = m.min_component_pct.is_finite()
                && m.fill_hole_pct.is_finite()
                && m.threshold.is_none_or(f32::is_finite);
            if !finite {
                return Err(SegformerError::Input(format!(
                    "{} mask options must be finite numbers",
                    kind.name()
                )));
            }
        }
        Ok(())
    }
}

/// The network plus the release's pre- and post-processing.
#[derive(Debug)]
pub struct Segmenter {
    model: Segformer,
    config: SegmenterConfig,
    device: Device,
}

impl Segmenter {
    /// Builds the network of `config` and loads `path` strictly (see [`Segformer::load`]).
    pub fn from_file(
        path: impl AsRef<Path>,
        config: SegmenterConfig,
        device: &Device,
    ) -> Result<Self, SegformerError> {
        Self::from_file_with_report(path, config, device).map(|(segmenter, _)| segmenter)
    }

    /// Wraps an already loaded network.
    pub fn new(
        model: Segformer,
        config: SegmenterConfig,
        device: &Device,
    ) -> Result<Self, SegformerError> {
        config.validate()?;
        Ok(Self {
            model,
            config,
            device: device.clone(),
        })
    }

    /// Like [`Segmenter::from_file`], also returning the load report.
    pub fn from_file_with_report(
        path: impl AsRef<Path>,
        config: SegmenterConfig,
        device: &Device,
    ) -> Result<(Self, LoadReport), SegformerError> {
        config.validate()?;
        let mut model = Segformer::new(&config.model, device);
        let report = model.load(path)?;
        Ok((
            Self {
                model,
                config,
                device: device.clone(),
            },
            report,
        ))
    }

    /// The network.
    pub fn model(&self) -> &Segformer {
        &self.model
    }

    /// The configuration.
    pub fn config(&self) -> &SegmenterConfig {
        &self.config
    }

    /// Water, tree and building masks of an 8-bit image (1–4 channels, values 0..=255) at its
    /// own size, from one forward pass.
    pub fn segment(&self, image: &Image) -> Result<Segmentation, SegformerError> {
        let (w_in, h_in) = self.config.input_size;
        let x = preprocess::preprocess(image, w_in, h_in, &self.device)?;
        let logits = self.model.forward(x);
        postprocess::postprocess(logits, image.width(), image.height(), &self.config.masks)
    }
}

//! `SegformerForSemanticSegmentation` (HF transformers) and its checkpoint loading.

use std::path::Path;

use burn::module::Module;
use burn::tensor::{Device, Tensor};

use super::config::SegformerConfig;
use super::decoder::DecodeHead;
use super::encoder::Encoder;
use super::trace::Trace;
use crate::device::on_cpu_pool;
use crate::weights::{load_weights_mapped, module_keys, LoadReport, WeightsError};

/// HF `SegformerModel` (only the encoder matters for segmentation).
#[derive(Module, Debug)]
pub struct SegformerModel {
    /// The Mix Transformer.
    pub encoder: Encoder,
}

/// HF `SegformerForSemanticSegmentation` in eval mode; keys `segformer.encoder.*`, `decode_head.*`.
#[derive(Module, Debug)]
pub struct Segformer {
    /// Backbone.
    pub segformer: SegformerModel,
    /// All-MLP head.
    pub decode_head: DecodeHead,
}

/// Wrapper of the release's `.pt` checkpoint (`torch.save({'model_state_dict': ...})`).
const STATE_DICT_WRAPPER: &str = "model_state_dict.";

impl Segformer {
    /// Builds the network with lazy (untouched until used or loaded) parameters.
    pub fn new(cfg: &SegformerConfig, device: &Device) -> Self {
        Self {
            segformer: SegformerModel {
                encoder: Encoder::new(cfg, device),
            },
            decode_head: DecodeHead::new(cfg, device),
        }
    }

    /// Logits B×classes×h₁×w₁ (h₁ ≈ H/4) of the normalised image B×3×H×W.
    pub fn forward(&self, pixel_values: Tensor<4>) -> Tensor<4> {
        self.forward_traced(pixel_values, &mut Trace::off())
    }

    /// [`Segformer::forward`], recording the intermediates in `trace`.
    pub fn forward_traced(&self, pixel_values: Tensor<4>, trace: &mut Trace) -> Tensor<4> {
        on_cpu_pool(&pixel_values.device(), || {
            let stages = self.segformer.encoder.forward(pixel_values, trace);
            self.decode_head.forward(&stages, trace)
        })
    }

    /// Loads a checkpoint strictly: the safetensors of HF naming, or the release's `.pt`
    /// (`model_state_dict` wrapper; every `module.` then every `model.` substring deleted from the
    /// keys, as the reference scripts do). Missing, mis-shaped **and unexpected** keys are errors
    /// (the reference loads with `strict=False`, but a correct checkpoint has none);
    /// `num_batches_tracked` is ignored.
    pub fn load(&mut self, path: impl AsRef<Path>) -> Result<LoadReport, WeightsError> {
        let report = load_weights_mapped(self, path, checkpoint_keys)?;
        if report.unexpected.is_empty() {
            Ok(report)
        } else {
            Err(WeightsError::Mismatch {
                report: Box::new(report),
            })
        }
    }

    /// The parameters and buffers as (HF key, PyTorch shape), sorted; `num_batches_tracked`
    /// excluded. Equals the key list of the real checkpoint for [`SegformerConfig::mit_b2`]`(9)`.
    pub fn torch_keys(&self) -> Vec<(String, Vec<usize>)> {
        let mut keys: Vec<_> = module_keys(self)
            .into_iter()
            .map(|(k, s)| (torch_key(&k), s))
            .collect();
        keys.sort();
        keys
    }
}

/// burn path → HF key (`attention.self_attn.` → `attention.self.`: `self` is a Rust keyword).
pub fn torch_key(burn_path: &str) -> String {
    burn_path.replace(".attention.self_attn.", ".attention.self.")
}

/// HF key → burn path.
pub fn burn_key(torch_key: &str) -> String {
    torch_key.replace(".attention.self.", ".attention.self_attn.")
}

/// Maps a checkpoint's keys to the model's: keeps only the `model_state_dict` entry when the file
/// has one (optimizer state and the like are dropped), deletes every `module.` then every `model.`
/// substring (the reference `clean_state_dict`), and renames `attention.self` for burn.
pub fn checkpoint_keys(names: &[String]) -> Vec<Option<String>> {
    let wrapped = names.iter().any(|n| n.starts_with(STATE_DICT_WRAPPER));
    names
        .iter()
        .map(|n| {
            let inner = if wrapped {
                n.strip_prefix(STATE_DICT_WRAPPER)?
            } else {
                n.as_str()
            };
            Some(burn_key(
                &inner.replace("module.", "").replace("model.", ""),
            ))
        })
        .collect()
}

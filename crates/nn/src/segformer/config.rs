//! SegFormer layout (HF `SegformerConfig`) with the presets this project needs.

use serde::{Deserialize, Serialize};

pub use dataset::segmentation::OPENEARTHMAP_LABELS;

/// Layout of a `SegformerForSemanticSegmentation` (4 stages).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SegformerConfig {
    /// Channels per stage.
    pub hidden_sizes: [usize; 4],
    /// Transformer blocks per stage.
    pub depths: [usize; 4],
    /// Attention heads per stage (each hidden size must be divisible by it).
    pub num_attention_heads: [usize; 4],
    /// Spatial reduction of keys/values per stage (1 = none).
    pub sr_ratios: [usize; 4],
    /// Kernel of the overlapping patch embeddings (padding = kernel / 2).
    pub patch_sizes: [usize; 4],
    /// Stride of the overlapping patch embeddings.
    pub strides: [usize; 4],
    /// Mix-FFN hidden width = hidden size · ratio.
    pub mlp_ratios: [usize; 4],
    /// Width of the all-MLP decode head.
    pub decoder_hidden_size: usize,
    /// Number of classes (logit channels).
    pub num_labels: usize,
    /// Input channels (RGB).
    pub num_channels: usize,
}

impl SegformerConfig {
    /// `nvidia/mit-b2` with `num_labels` classes: the OpenEarthMap checkpoint of the release
    /// (`num_labels = 9`), 27,355,081 parameters.
    pub fn mit_b2(num_labels: usize) -> Self {
        Self {
            hidden_sizes: [64, 128, 320, 512],
            depths: [3, 4, 6, 3],
            num_attention_heads: [1, 2, 5, 8],
            sr_ratios: [8, 4, 2, 1],
            patch_sizes: [7, 3, 3, 3],
            strides: [4, 2, 2, 2],
            mlp_ratios: [4, 4, 4, 4],
            decoder_hidden_size: 768,
            num_labels,
            num_channels: 3,
        }
    }

    /// The random-weight parity fixture `../shared/fixtures/segformer-tiny` (mit-b2 layout with
    /// hidden sizes [16, 32, 40, 64], two blocks per stage, decoder 64; 331,761 parameters).
    pub fn tiny() -> Self {
        Self {
            hidden_sizes: [16, 32, 40, 64],
            depths: [2, 2, 2, 2],
            decoder_hidden_size: 64,
            ..Self::mit_b2(9)
        }
    }

    /// Checks the numbers a model could not be built from.
    pub fn validate(&self) -> Result<(), String> {
        for i in 0..4 {
            let (c, h) = (self.hidden_sizes[i], self.num_attention_heads[i]);
            if c == 0 || h == 0 || c % h != 0 {
                return Err(format!(
                    "stage {}: hidden size {c} is not a positive multiple of {h} heads",
                    i + 1
                ));
            }
            if self.sr_ratios[i] == 0 || self.strides[i] == 0 || self.patch_sizes[i] == 0 {
                return Err(format!(
                    "stage {}: sr ratio, stride and patch size must be ≥ 1",
                    i + 1
                ));
            }
            if self.mlp_ratios[i] == 0 {
                return Err(format!("stage {}: mlp ratio must be ≥ 1", i + 1));
            }
        }
        if self.decoder_hidden_size == 0 || self.num_labels == 0 || self.num_channels == 0 {
            return Err("decoder width, number of labels and channels must be ≥ 1".into());
        }
        Ok(())
    }

    /// Spatial size (h, w) of each stage's output for an input of `height`×`width`
    /// (`floor((n + 2·(k/2) − k) / s) + 1` per stage). `None` when a stage would be empty.
    pub fn stage_sizes(&self, height: usize, width: usize) -> Option<[(usize, usize); 4]> {
        let mut out = [(0, 0); 4];
        let (mut h, mut w) = (height, width);
        for (i, size) in out.iter_mut().enumerate() {
            let (k, s) = (self.patch_sizes[i], self.strides[i]);
            let step = |n: usize| (n + 2 * (k / 2)).checked_sub(k).map(|m| m / s + 1);
            h = step(h)?;
            w = step(w)?;
            *size = (h, w);
        }
        Some(out)
    }

    /// Number of trainable parameters (PyTorch `parameters()`; BatchNorm running statistics
    /// excluded): 27,353,545 for [`SegformerConfig::mit_b2`]`(9)` (its state dict holds
    /// 27,355,081 float values with the 2 × 768 running statistics), 331,761 for the tiny fixture.
    pub fn num_params(&self) -> usize {
        let mut n = 0;
        let mut c_in = self.num_channels;
        let ln = |c: usize| 2 * c;
        let lin = |i: usize, o: usize| i * o + o;
        for i in 0..4 {
            let (c, k, sr) = (self.hidden_sizes[i], self.patch_sizes[i], self.sr_ratios[i]);
            n += c_in * c * k * k + c + ln(c);
            let hidden = c * self.mlp_ratios[i];
            let mut block = ln(c) + 4 * lin(c, c) + ln(c);
            if sr > 1 {
                block += c * c * sr * sr + c + ln(c);
            }
            block += lin(c, hidden) + hidden * 9 + hidden + lin(hidden, c);
            n += self.depths[i] * block + ln(c);
            c_in = c;
        }
        let d = self.decoder_hidden_size;
        n += self.hidden_sizes.iter().map(|&c| lin(c, d)).sum::<usize>();
        n += 4 * d * d + 2 * d + d * self.num_labels + self.num_labels;
        n
    }
}

//! Configuration of the HF `DINOv3ViTModel` (`DINOv3ViTConfig`), with the presets of the released
//! ViT checkpoints and the tiny parity fixture.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::weights::{file_keys, WeightsError};

/// Architecture of a DINOv3 ViT. Settings every released ViT shares (head_dim 64, plain GELU
/// MLP, no key bias, LayerNorm eps 1e-5, RoPE base 100, 4 registers, patch 16) are fields too,
/// so that a checkpoint that differs fails to load instead of running wrong.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Dinov3Config {
    /// Token width D.
    pub hidden_size: usize,
    /// Number of transformer layers.
    pub num_hidden_layers: usize,
    /// Attention heads (`hidden_size / num_attention_heads` is the RoPE head dim).
    pub num_attention_heads: usize,
    /// MLP hidden width.
    pub intermediate_size: usize,
    /// Patch side, pixels.
    pub patch_size: usize,
    /// Register tokens between CLS and the patches.
    pub num_register_tokens: usize,
    /// RoPE base θ.
    pub rope_theta: f64,
    /// LayerNorm epsilon (all norms).
    pub layer_norm_eps: f64,
    /// Bias of the query projection.
    pub query_bias: bool,
    /// Bias of the key projection (false in every released model).
    pub key_bias: bool,
    /// Bias of the value projection.
    pub value_bias: bool,
    /// Bias of the attention output projection.
    pub proj_bias: bool,
    /// Biases of the MLP projections.
    pub mlp_bias: bool,
}

/// A configuration that cannot build a model.
#[derive(Debug, thiserror::Error)]
pub enum Dinov3ConfigError {
    /// Inconsistent sizes.
    #[error("invalid DINOv3 configuration: {0}")]
    Invalid(String),
    /// The checkpoint could not be read.
    #[error(transparent)]
    Weights(#[from] WeightsError),
    /// The checkpoint's keys do not describe a DINOv3 ViT.
    #[error("{file}: not a DINOv3ViTModel checkpoint: {message}")]
    NotDinov3 {
        /// The file.
        file: String,
        /// What is missing.
        message: String,
    },
}

impl Dinov3Config {
    fn released(hidden: usize, layers: usize, heads: usize, mlp: usize) -> Self {
        Self {
            hidden_size: hidden,
            num_hidden_layers: layers,
            num_attention_heads: heads,
            intermediate_size: mlp,
            patch_size: 16,
            num_register_tokens: 4,
            rope_theta: 100.0,
            layer_norm_eps: 1e-5,
            query_bias: true,
            key_bias: false,
            value_bias: true,
            proj_bias: true,
            mlp_bias: true,
        }
    }

    /// ViT-S/16 (`facebook/dinov3-vits16-pretrain-lvd1689m`): 21,596,544 values.
    pub fn vits16() -> Self {
        Self::released(384, 12, 6, 1536)
    }

    /// ViT-B/16: 85,660,416 values.
    pub fn vitb16() -> Self {
        Self::released(768, 12, 12, 3072)
    }

    /// ViT-L/16, the upstream default `facebook/dinov3-vitl16-pretrain-sat493m`: 303,129,600 values.
    pub fn vitl16() -> Self {
        Self::released(1024, 24, 16, 4096)
    }

    /// The parity fixture `../shared/fixtures/dinov3-tiny` (hidden 128, 4 layers, 2 heads).
    pub fn tiny() -> Self {
        Self::released(128, 4, 2, 512)
    }

    /// A preset by name: `vits16`, `vitb16`, `vitl16` or `tiny`.
    pub fn preset(name: &str) -> Option<Self> {
        match name {
            "vits16" => Some(Self::vits16()),
            "vitb16" => Some(Self::vitb16()),
            "vitl16" => Some(Self::vitl16()),
            "tiny" => Some(Self::tiny()),
            _ => None,
        }
    }

    /// Width of one attention head.
    pub fn head_dim(&self) -> usize {
        self.hidden_size / self.num_attention_heads.max(1)
    }

    /// Checks the sizes the model relies on.
    pub fn validate(&self) -> Result<(), Dinov3ConfigError> {
        let bad = |m: String| Err(Dinov3ConfigError::Invalid(m));
        if self.hidden_size == 0 || self.num_attention_heads == 0 || self.patch_size == 0 {
            return bad("hidden_size, num_attention_heads and patch_size must be positive".into());
        }
        if !self.hidden_size.is_multiple_of(self.num_attention_heads) {
            return bad(format!(
                "hidden_size {} is not divisible by num_attention_heads {}",
                self.hidden_size, self.num_attention_heads
            ));
        }
        if !self.head_dim().is_multiple_of(4) {
            return bad(format!(
                "head dim {} must be a multiple of 4 (RoPE uses head_dim/4 frequencies per axis)",
                self.head_dim()
            ));
        }
        if !(self.rope_theta > 0.0 && self.layer_norm_eps > 0.0) {
            return bad("rope_theta and layer_norm_eps must be positive".into());
        }
        Ok(())
    }

    /// Reads a Hugging Face `config.json` (`model_type: dinov3_vit`). Fields that are absent
    /// keep the released models' values; a gated MLP is rejected (not implemented).
    pub fn from_hf_json(path: &Path) -> Result<Self, Dinov3ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|e| {
            Dinov3ConfigError::Invalid(format!("{}: cannot read: {e}", path.display()))
        })?;
        let v: serde_json::Value = serde_json::from_str(&text).map_err(|e| {
            Dinov3ConfigError::Invalid(format!("{}: not JSON: {e}", path.display()))
        })?;
        let num = |k: &str| {
            v.get(k)
                .and_then(serde_json::Value::as_u64)
                .map(|n| n as usize)
        };
        let flag = |k: &str| v.get(k).and_then(serde_json::Value::as_bool);
        if flag("use_gated_mlp") == Some(true) {
            return Err(Dinov3ConfigError::Invalid(format!(
                "{}: use_gated_mlp = true (the ViT-7B/H+ SwiGLU MLP) is not supported",
                path.display()
            )));
        }
        let mut c = Self::vitl16();
        let field = |k: &str| {
            num(k).ok_or_else(|| {
                Dinov3ConfigError::Invalid(format!("{}: `{k}` missing", path.display()))
            })
        };
        c.hidden_size = field("hidden_size")?;
        c.num_hidden_layers = field("num_hidden_layers")?;
        c.num_attention_heads = field("num_attention_heads")?;
        c.intermediate_size = field("intermediate_size")?;
        c.patch_size = num("patch_size").unwrap_or(c.patch_size);
        c.num_register_tokens = num("num_register_tokens").unwrap_or(c.num_register_tokens);
        let float = |k: &str| v.get(k).and_then(serde_json::Value::as_f64);
        c.rope_theta = float("rope_theta").unwrap_or(c.rope_theta);
        c.layer_norm_eps = float("layer_norm_eps").unwrap_or(c.layer_norm_eps);
        c.query_bias = flag("query_bias").unwrap_or(c.query_bias);
        c.key_bias = flag("key_bias").unwrap_or(c.key_bias);
        c.value_bias = flag("value_bias").unwrap_or(c.value_bias);
        c.proj_bias = flag("proj_bias").unwrap_or(c.proj_bias);
        c.mlp_bias = flag("mlp_bias").unwrap_or(c.mlp_bias);
        c.validate()?;
        Ok(c)
    }

    /// Infers the configuration from the key shapes of an HF checkpoint (safetensors or `.pth`):
    /// width from `embeddings.cls_token`, layers from `layer.N.*`, MLP width from `up_proj`,
    /// registers from `register_tokens`, patch from the patch conv, biases from which bias keys
    /// exist. Heads are not stored in a checkpoint: every released DINOv3 ViT uses head_dim 64,
    /// so heads = width / 64 (use a preset or `config.json` for anything else).
    pub fn from_checkpoint(path: &Path) -> Result<Self, Dinov3ConfigError> {
        let keys = file_keys(path)?;
        let not = |message: String| Dinov3ConfigError::NotDinov3 {
            file: path.display().to_string(),
            message,
        };
        let shape = |k: &str| keys.iter().find(|(n, _)| n == k).map(|(_, s)| s.clone());
        let has = |k: &str| keys.iter().any(|(n, _)| n == k);
        let cls = shape("embeddings.cls_token")
            .ok_or_else(|| not("no `embeddings.cls_token` (HF DINOv3ViTModel layout expected; the original facebookresearch layout is not supported)".into()))?;
        let hidden = *cls.last().unwrap_or(&0);
        let layers = keys
            .iter()
            .filter_map(|(n, _)| {
                n.strip_prefix("layer.")?
                    .split('.')
                    .next()?
                    .parse::<usize>()
                    .ok()
            })
            .max()
            .map_or(0, |m| m + 1);
        let up = shape("layer.0.mlp.up_proj.weight").ok_or_else(|| {
            not("no `layer.0.mlp.up_proj.weight` (gated MLPs are not supported)".into())
        })?;
        let patch = shape("embeddings.patch_embeddings.weight")
            .ok_or_else(|| not("no `embeddings.patch_embeddings.weight`".into()))?;
        let registers = shape("embeddings.register_tokens").map_or(0, |s| s[1]);
        let mut c = Self::released(hidden, layers, (hidden / 64).max(1), up[0]);
        c.patch_size = *patch.last().unwrap_or(&16);
        c.num_register_tokens = registers;
        c.query_bias = has("layer.0.attention.q_proj.bias");
        c.key_bias = has("layer.0.attention.k_proj.bias");
        c.value_bias = has("layer.0.attention.v_proj.bias");
        c.proj_bias = has("layer.0.attention.o_proj.bias");
        c.mlp_bias = has("layer.0.mlp.up_proj.bias");
        c.validate()?;
        Ok(c)
    }
}

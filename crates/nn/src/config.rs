//! Configuration of MonSter++ with the upstream defaults (`../shared/design/monsterpp.md` §1).
//!
//! Presets: [`MonsterConfig::vitl`] (the released `*_large.pth` / `mix_all.pth` checkpoints),
//! [`MonsterConfig::vitb`], [`MonsterConfig::vits`], and [`MonsterConfig::tiny`] (exactly the
//! parity fixture `../shared/fixtures/monsterpp-tiny/meta.json`). Call [`MonsterConfig::validate`]
//! before building a model.

use serde::{Deserialize, Serialize};

/// Which DINOv2 encoder the mono branch uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum EncoderKind {
    /// ViT-S/14: 384 wide, 12 blocks, 6 heads.
    Vits,
    /// ViT-B/14: 768 wide, 12 blocks, 12 heads.
    Vitb,
    /// ViT-L/14: 1024 wide, 24 blocks, 16 heads (all released MonSter++ accuracy checkpoints).
    Vitl,
    /// A custom ViT (the tiny parity fixture).
    Custom,
}

/// The DINOv2 ViT of the mono branch.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VitConfig {
    /// Token width E.
    pub embed_dim: usize,
    /// Number of transformer blocks.
    pub depth: usize,
    /// Attention heads (embed_dim must be divisible by it).
    pub num_heads: usize,
    /// MLP hidden width = embed_dim · mlp_ratio.
    pub mlp_ratio: f64,
    /// Patch size (14).
    pub patch_size: usize,
    /// Side of the pos-embed grid (518/14 = 37).
    pub pos_grid: usize,
    /// Blocks whose (normed) outputs feed the DPT heads.
    pub intermediate_layers: [usize; 4],
    /// Offset added to the grid size in the pos-embed interpolation (0.1).
    pub interpolate_offset: f64,
}

impl VitConfig {
    /// MLP hidden width (`int(embed_dim * mlp_ratio)`, as in PyTorch).
    pub fn mlp_hidden(&self) -> usize {
        (self.embed_dim as f64 * self.mlp_ratio) as usize
    }
}

/// The DPT heads (`mono_decoder`, `feat_decoder`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DptConfig {
    /// Fusion width F.
    pub features: usize,
    /// Per-level projection widths (the last one equals the ViT width in every upstream config).
    pub out_channels: [usize; 4],
}

/// Full MonSter++ accuracy-model configuration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MonsterConfig {
    /// Encoder preset name.
    pub encoder: EncoderKind,
    /// DINOv2 layout.
    pub vit: VitConfig,
    /// DPT layout.
    pub dpt: DptConfig,
    /// GRU hidden widths (all equal upstream).
    pub hidden_dims: [usize; 3],
    /// Number of GRU levels (3).
    pub n_gru_layers: usize,
    /// Levels of the combined geo encoding volume pyramid (2).
    pub corr_levels: usize,
    /// Lookup radius (4 → 9 taps).
    pub corr_radius: usize,
    /// Maximum disparity at full resolution; a multiple of 32 (runtime knob, no parameters).
    pub max_disp: usize,
    /// Refinement iterations at inference (≥ 7: the last 7 are the dual-branch ones).
    pub iters: usize,
}

/// A configuration that cannot build a model.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("invalid MonSter++ configuration: {0}")]
pub struct ConfigError(pub String);

impl MonsterConfig {
    fn with_encoder(encoder: EncoderKind, vit: VitConfig, dpt: DptConfig) -> Self {
        Self {
            encoder,
            vit,
            dpt,
            hidden_dims: [128; 3],
            n_gru_layers: 3,
            corr_levels: 2,
            corr_radius: 4,
            max_disp: 416,
            iters: 32,
        }
    }

    fn vit(embed_dim: usize, depth: usize, num_heads: usize, layers: [usize; 4]) -> VitConfig {
        VitConfig {
            embed_dim,
            depth,
            num_heads,
            mlp_ratio: 4.0,
            patch_size: 14,
            pos_grid: 37,
            intermediate_layers: layers,
            interpolate_offset: 0.1,
        }
    }

    /// ViT-S encoder, DPT features 64, out [48, 96, 192, 384].
    pub fn vits() -> Self {
        Self::with_encoder(
            EncoderKind::Vits,
            Self::vit(384, 12, 6, [2, 5, 8, 11]),
            DptConfig {
                features: 64,
                out_channels: [48, 96, 192, 384],
            },
        )
    }

    /// ViT-B encoder, DPT features 128, out [96, 192, 384, 768].
    pub fn vitb() -> Self {
        Self::with_encoder(
            EncoderKind::Vitb,
            Self::vit(768, 12, 12, [2, 5, 8, 11]),
            DptConfig {
                features: 128,
                out_channels: [96, 192, 384, 768],
            },
        )
    }

    /// ViT-L encoder, DPT features 256, out [256, 512, 1024, 1024] (the released checkpoints).
    pub fn vitl() -> Self {
        Self::with_encoder(
            EncoderKind::Vitl,
            Self::vit(1024, 24, 16, [4, 11, 17, 23]),
            DptConfig {
                features: 256,
                out_channels: [256, 512, 1024, 1024],
            },
        )
    }

    /// The parity fixture `monsterpp-tiny`: ViT 64 wide, 12 blocks, 2 heads, mlp_ratio 2;
    /// DPT features 64, out [32, 48, 64, 64]; hidden 32; max_disp 64; iters 8.
    pub fn tiny() -> Self {
        Self {
            encoder: EncoderKind::Custom,
            vit: VitConfig {
                mlp_ratio: 2.0,
                ..Self::vit(64, 12, 2, [2, 5, 8, 11])
            },
            dpt: DptConfig {
                features: 64,
                out_channels: [32, 48, 64, 64],
            },
            hidden_dims: [32; 3],
            n_gru_layers: 3,
            corr_levels: 2,
            corr_radius: 4,
            max_disp: 64,
            iters: 8,
        }
    }

    /// Preset by name: `vits`, `vitb`, `vitl` or `tiny`.
    pub fn preset(name: &str) -> Result<Self, ConfigError> {
        match name {
            "vits" => Ok(Self::vits()),
            "vitb" => Ok(Self::vitb()),
            "vitl" => Ok(Self::vitl()),
            "tiny" => Ok(Self::tiny()),
            other => Err(ConfigError(format!(
                "unknown preset {other:?} (expected vits, vitb, vitl or tiny; vitg is not supported)"
            ))),
        }
    }

    /// GRU hidden width C.
    pub fn hidden(&self) -> usize {
        self.hidden_dims[0]
    }

    /// Disparity bins at 1/4 resolution, D = max_disp / 4.
    pub fn disp_bins(&self) -> usize {
        self.max_disp / 4
    }

    /// Checks every constraint the network relies on; the message says which field and why.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let err = |m: String| Err(ConfigError(m));
        let v = &self.vit;
        if v.embed_dim == 0 || v.num_heads == 0 || v.depth == 0 {
            return err(format!(
                "vit.embed_dim ({}), vit.num_heads ({}) and vit.depth ({}) must be positive",
                v.embed_dim, v.num_heads, v.depth
            ));
        }
        if !v.embed_dim.is_multiple_of(v.num_heads) {
            return err(format!(
                "vit.embed_dim ({}) must be divisible by vit.num_heads ({})",
                v.embed_dim, v.num_heads
            ));
        }
        if v.mlp_ratio.is_nan() || v.mlp_ratio <= 0.0 || v.mlp_hidden() == 0 {
            return err(format!("vit.mlp_ratio ({}) must be positive", v.mlp_ratio));
        }
        if v.patch_size == 0 || v.pos_grid == 0 {
            return err("vit.patch_size and vit.pos_grid must be positive".into());
        }
        if let Some(&l) = v.intermediate_layers.iter().find(|&&l| l >= v.depth) {
            return err(format!(
                "vit.intermediate_layers contains {l}, but the ViT has only {} blocks",
                v.depth
            ));
        }
        if v.intermediate_layers.windows(2).any(|w| w[0] >= w[1]) {
            return err(format!(
                "vit.intermediate_layers {:?} must be strictly increasing",
                v.intermediate_layers
            ));
        }
        if self.dpt.features == 0 || !self.dpt.features.is_multiple_of(2) {
            return err(format!(
                "dpt.features ({}) must be positive and even",
                self.dpt.features
            ));
        }
        if self.dpt.out_channels.contains(&0) {
            return err(format!(
                "dpt.out_channels {:?} must be positive",
                self.dpt.out_channels
            ));
        }
        let c = self.hidden_dims[0];
        if c == 0 || self.hidden_dims.iter().any(|&h| h != c) {
            return err(format!(
                "hidden_dims {:?} must be positive and all equal (upstream requirement)",
                self.hidden_dims
            ));
        }
        if self.n_gru_layers != 3 {
            return err(format!("n_gru_layers ({}) must be 3", self.n_gru_layers));
        }
        if self.corr_levels != 2 {
            return err(format!(
                "corr_levels ({}) must be 2 (the update blocks' input width is fixed to 2 levels)",
                self.corr_levels
            ));
        }
        if self.corr_radius != 4 {
            return err(format!(
                "corr_radius ({}) must be 4 (the update blocks' input width is fixed to 9 taps)",
                self.corr_radius
            ));
        }
        if self.max_disp == 0 || !self.max_disp.is_multiple_of(32) {
            return err(format!(
                "max_disp ({}) must be a positive multiple of 32 (D = max_disp/4 must be divisible by 8)",
                self.max_disp
            ));
        }
        if self.iters < 7 {
            return err(format!(
                "iters ({}) must be at least 7 (the last 7 iterations are the dual-branch refinement)",
                self.iters
            ));
        }
        Ok(())
    }
}

impl Default for MonsterConfig {
    /// The upstream default: `vitl`.
    fn default() -> Self {
        Self::vitl()
    }
}

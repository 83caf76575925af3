//! One TOML file per training run with every hyper-parameter, shipped presets, and
//! `key=value` overrides.
//!
//! A run file has seven tables: `[model]`, `[data]`, `[loss]` (the losses' [`LossConfig`]),
//! `[optim]`, `[schedule]`, `[augment]` and `[run]`; a missing key takes its default, an unknown
//! key is an error. Relative paths are relative to the working directory. Presets
//! ([`PRESETS`], files in `crates/train/presets/`, compiled in): `tiny` (CPU, minutes, on a
//! procedural-world set), the paper's Table 1 runs `a-lidar`, `b-disp`, `c-photo`, `d-full` and
//! the data ablations `s1`, `s2`, `s3`. Each preset says in comments where the released YAML
//! files differ from the paper.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use dataset::augment::AugmentConfig;

use crate::loss::LossConfig;
use crate::optim::OptimConfig;
use crate::schedule::OneCycleConfig;

/// Every hyper-parameter of a training run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrainConfig {
    /// Name of the run (reported, and the default output folder name).
    #[serde(default = "default_name")]
    pub name: String,
    pub model: ModelConfig,
    pub data: DataConfig,
    #[serde(default)]
    pub loss: LossConfig,
    #[serde(default)]
    pub optim: OptimConfig,
    #[serde(default)]
    pub schedule: OneCycleConfig,
    /// RAFT-Stereo-style augmentation as the release configures it, including the training crop
    /// (`crop_height`, `crop_width`: multiples of 32). Defaults: the release's YAML values.
    #[serde(default)]
    pub augment: AugmentConfig,
    pub run: RunConfig,
}

fn default_name() -> String {
    "run".into()
}

/// The network and its initialisation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelConfig {
    /// `nn::config::MonsterConfig` preset: `tiny`, `vits`, `vitb` or `vitl` (paper: vitl).
    pub preset: String,
    /// Maximum disparity of the cost volume (multiple of 32); default: the preset's.
    #[serde(default)]
    pub max_disp: Option<usize>,
    /// Initial weights: a MonSter++ checkpoint (`.pth`, e.g. `Mix_all_large.pth`) or one of our
    /// safetensors checkpoints. Empty: random initialisation (tests and smoke runs only).
    #[serde(default)]
    pub init: Option<PathBuf>,
    /// Depth Anything V2 checkpoint loaded into the mono branch and the DPT copy before `init`
    /// (upstream does this at construction; a full MonSter++ checkpoint overrides it).
    #[serde(default)]
    pub depth_anything: Option<PathBuf>,
}

/// Where the training and validation samples come from (the release's dataset layout, see the
/// `dataset` crate).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DataConfig {
    /// The dataset folder (`train/`, `val/`, `disparity_maps/`, `experiments/`).
    pub root: PathBuf,
    /// Teacher folder name under `disparity_maps/` (release: `monster++`).
    #[serde(default = "default_teacher")]
    pub teacher: String,
    /// Training list `experiments/<name>.csv` (S1 `sub1_synchronic`, S2 `sub2_synchronic`,
    /// S3 `sub5_syndiach`, all combinations `sub3_diachronic`); empty: every `train/L/` image.
    #[serde(default)]
    pub experiment: Option<String>,
    /// Restrict training to the AOIs of `train_aois.csv` (release: yes, when the file exists).
    #[serde(default = "yes")]
    pub use_aoi_lists: bool,
    /// Validation list `experiments/<name>.csv` of the `val/` split (release: `sub_val`);
    /// when that file is absent every `val/L/` image is used.
    #[serde(default = "default_valid_experiment")]
    pub valid_experiment: String,
    /// At most this many validation pairs (0: all).
    #[serde(default)]
    pub valid_limit: usize,
}

fn default_teacher() -> String {
    "monster++".into()
}
fn default_valid_experiment() -> String {
    "sub_val".into()
}
fn yes() -> bool {
    true
}

/// Length, batches, iterations, seeds, logging and output of a run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunConfig {
    /// Samples per optimiser step (paper 4; release YAML 2).
    pub batch_size: usize,
    /// Optimiser steps (paper and release 50,000).
    pub steps: usize,
    /// Refinement iterations of the forward pass in training (release 22).
    pub train_iters: usize,
    /// Refinement iterations at validation (release 32).
    pub valid_iters: usize,
    /// Validation centre crop (release: the training crop size); a multiple of 32.
    pub valid_crop: usize,
    /// Seed of the data order and the augmentation (release 0).
    pub seed: u64,
    /// Write a checkpoint every this many steps (release 2000); one is always written at the end.
    pub checkpoint_every: usize,
    /// Validate every this many steps (release 2000; 0: never).
    pub validate_every: usize,
    /// Also validate before the first step (gives the starting EPE).
    #[serde(default)]
    pub validate_at_start: bool,
    /// Checkpoints kept besides the newest (older ones are deleted; 0 keeps all).
    #[serde(default = "default_keep")]
    pub keep_checkpoints: usize,
    /// Output folder: `config.toml`, `metrics.csv`, `validation.csv`, `checkpoints/`.
    pub output: PathBuf,
}

fn default_keep() -> usize {
    3
}

/// Names of the shipped presets.
pub const PRESETS: [&str; 8] = [
    "tiny", "a-lidar", "b-disp", "c-photo", "d-full", "s1", "s2", "s3",
];

/// The TOML text of a shipped preset.
pub fn preset_text(name: &str) -> Option<&'static str> {
    Some(match name {
        "tiny" => include_str!("../presets/tiny.toml"),
        "a-lidar" => include_str!("../presets/a-lidar.toml"),
        "b-disp" => include_str!("../presets/b-disp.toml"),
        "c-photo" => include_str!("../presets/c-photo.toml"),
        "d-full" => include_str!("../presets/d-full.toml"),
        "s1" => include_str!("../presets/s1.toml"),
        "s2" => include_str!("../presets/s2.toml"),
        "s3" => include_str!("../presets/s3.toml"),
        _ => return None,
    })
}

/// A configuration that cannot be read or used; the message names the file or key and the fix.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct ConfigError(pub String);

impl TrainConfig {
    /// A preset name or a TOML file, then the `key=value` overrides in order
    /// (e.g. `run.steps=100`, `model.init="w.safetensors"`, `loss.lambda_photo=0`).
    pub fn load(preset_or_path: &str, overrides: &[String]) -> Result<Self, ConfigError> {
        let (text, origin) = match preset_text(preset_or_path) {
            Some(t) => (t.to_string(), format!("preset {preset_or_path:?}")),
            None => {
                let path = Path::new(preset_or_path);
                let text = std::fs::read_to_string(path).map_err(|e| {
                    ConfigError(format!(
                        "{}: cannot read the training configuration ({e}); give a TOML file or a preset: {}",
                        path.display(),
                        PRESETS.join(", ")
                    ))
                })?;
                (text, path.display().to_string())
            }
        };
        Self::from_toml(&text, overrides, &origin)
    }

    /// Parses TOML text (`origin` names it in errors) and applies the overrides.
    pub fn from_toml(text: &str, overrides: &[String], origin: &str) -> Result<Self, ConfigError> {
        let mut table: toml::Table = toml::from_str(text)
            .map_err(|e| ConfigError(format!("{origin}: not valid TOML: {e}")))?;
        for o in overrides {
            apply_override(&mut table, o)?;
        }
        let config: TrainConfig = toml::Value::Table(table)
            .try_into()
            .map_err(|e| ConfigError(format!("{origin}: {e}")))?;
        config
            .validate()
            .map_err(|e| ConfigError(format!("{origin}: {}", e.0)))?;
        Ok(config)
    }

    /// The configuration as TOML (written to the run folder so a run can be repeated).
    pub fn to_toml(&self) -> String {
        toml::to_string(self).expect("a TrainConfig always serialises")
    }

    /// The network configuration: the preset with `max_disp` applied, validated.
    pub fn monster_config(&self) -> Result<nn::config::MonsterConfig, ConfigError> {
        let mut m = nn::config::MonsterConfig::preset(&self.model.preset)
            .map_err(|e| ConfigError(format!("model.preset: {e}")))?;
        if let Some(d) = self.model.max_disp {
            m.max_disp = d;
        }
        m.validate()
            .map_err(|e| ConfigError(format!("model: {e}")))?;
        Ok(m)
    }

    /// Checks the values no single table can check alone.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let r = &self.run;
        let bad = |m: String| Err(ConfigError(m));
        self.monster_config()?;
        self.loss
            .validate()
            .map_err(|e| ConfigError(e.to_string()))?;
        if r.batch_size == 0 {
            return bad("run.batch_size must be at least 1".into());
        }
        if r.steps == 0 {
            return bad("run.steps must be at least 1".into());
        }
        if r.train_iters < 7 || r.valid_iters < 7 {
            return bad(format!(
                "run.train_iters ({}) and run.valid_iters ({}) must be at least 7 (MonSter++'s last 7 iterations are the dual-branch ones)",
                r.train_iters, r.valid_iters
            ));
        }
        let a = &self.augment;
        if [a.crop_height, a.crop_width]
            .iter()
            .any(|&c| c == 0 || !c.is_multiple_of(32))
        {
            return bad(format!(
                "augment.crop_height ({}) and augment.crop_width ({}) must be positive multiples of 32 (the network's downsampling)",
                a.crop_height, a.crop_width
            ));
        }
        a.validate()
            .map_err(|e| ConfigError(format!("augment: {e}")))?;
        if r.valid_crop == 0 || !r.valid_crop.is_multiple_of(32) {
            return bad(format!(
                "run.valid_crop ({}) must be a positive multiple of 32",
                r.valid_crop
            ));
        }
        if r.checkpoint_every == 0 {
            return bad("run.checkpoint_every must be at least 1".into());
        }
        let o = &self.optim;
        if !(o.lr.is_finite() && o.lr > 0.0) {
            return bad(format!("optim.lr ({}) must be positive", o.lr));
        }
        if !(o.feat_decoder_lr_factor.is_finite() && o.feat_decoder_lr_factor >= 0.0) {
            return bad(format!(
                "optim.feat_decoder_lr_factor ({}) must be ≥ 0",
                o.feat_decoder_lr_factor
            ));
        }
        if let Some(c) = o.grad_clip_norm {
            if !(c.is_finite() && c > 0.0) {
                return bad(format!("optim.grad_clip_norm ({c}) must be positive"));
            }
        }
        crate::schedule::OneCycle::new(o.lr, r.steps, &self.schedule)
            .map_err(|e| ConfigError(format!("schedule: {e}")))?;
        Ok(())
    }
}

/// Sets `dotted.key = value` in `table`; `value` is read as TOML (`3`, `1e-4`, `true`,
/// `[64, 128]`, `"text"`), and as a plain string when it is not valid TOML.
fn apply_override(table: &mut toml::Table, assignment: &str) -> Result<(), ConfigError> {
    let (key, raw) = assignment.split_once('=').ok_or_else(|| {
        ConfigError(format!(
            "override {assignment:?}: expected key=value, e.g. run.steps=100"
        ))
    })?;
    let key = key.trim();
    let raw = raw.trim();
    let value = toml::from_str::<toml::Table>(&format!("v = {raw}"))
        .ok()
        .and_then(|mut t| t.remove("v"))
        .unwrap_or_else(|| toml::Value::String(raw.to_string()));
    let parts: Vec<&str> = key.split('.').collect();
    if parts.iter().any(|p| p.is_empty()) {
        return Err(ConfigError(format!(
            "override {assignment:?}: empty key part"
        )));
    }
    let mut node = table;
    for p in &parts[..parts.len() - 1] {
        let entry = node
            .entry(p.to_string())
            .or_insert_with(|| toml::Value::Table(toml::Table::new()));
        node = entry.as_table_mut().ok_or_else(|| {
            ConfigError(format!(
                "override {assignment:?}: {p} is a value, not a table"
            ))
        })?;
    }
    node.insert(parts[parts.len() - 1].to_string(), value);
    Ok(())
}

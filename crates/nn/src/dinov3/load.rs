//! Loading HF `DINOv3ViTModel` checkpoints (safetensors or `.pth`, F16/BF16/F32 upcast to f32)
//! strictly: every parameter present with its shape, and no key left over.
//!
//! The MLP and layer scales reuse the DINOv2 modules (`fc1`/`fc2`, `gamma`), so three HF names
//! are renamed on the way in and back in every report: `mlp.up_proj` ↔ `mlp.fc1`,
//! `mlp.down_proj` ↔ `mlp.fc2`, `layer_scaleK.lambda1` ↔ `layer_scaleK.gamma`. Reports and
//! [`hf_keys`] always speak HF names.

use std::path::Path;

use super::model::Dinov3Vit;
use crate::weights::{load_submodule_with, module_keys, LoadReport, WeightsError};

/// HF key → module path (regex, applied to the file's keys).
const HF_TO_MODULE: [(&str, &str); 3] = [
    (r"^(layer\.\d+\.mlp\.)up_proj\.", "${1}fc1."),
    (r"^(layer\.\d+\.mlp\.)down_proj\.", "${1}fc2."),
    (r"^(layer\.\d+\.layer_scale[12]\.)lambda1$", "${1}gamma"),
];

/// Module path → HF key (plain substring renames; no HF key contains the module names).
fn to_hf_name(name: &str) -> String {
    name.replace(".mlp.fc1.", ".mlp.up_proj.")
        .replace(".mlp.fc2.", ".mlp.down_proj.")
        .replace(".layer_scale1.gamma", ".layer_scale1.lambda1")
        .replace(".layer_scale2.gamma", ".layer_scale2.lambda1")
}

fn report_in_hf_names(mut report: LoadReport) -> LoadReport {
    for list in [
        &mut report.missing,
        &mut report.mismatched,
        &mut report.unexpected,
    ] {
        for k in list.iter_mut() {
            *k = to_hf_name(k);
        }
    }
    report
}

/// Loads an HF checkpoint into `model`. Errors (with a report in HF names) when a parameter is
/// missing or mis-shaped, or when the file has keys the model does not use (the wrong layout,
/// e.g. the original facebookresearch `blocks.N.attn.qkv` checkpoints, or a wrong size preset).
pub fn load_dinov3(model: &mut Dinov3Vit, path: &Path) -> Result<LoadReport, WeightsError> {
    match load_submodule_with(model, path, "", &HF_TO_MODULE) {
        Ok(report) => {
            let report = report_in_hf_names(report);
            if report.unexpected.is_empty() {
                Ok(report)
            } else {
                Err(WeightsError::Mismatch {
                    report: Box::new(report),
                })
            }
        }
        Err(WeightsError::Mismatch { report }) => Err(WeightsError::Mismatch {
            report: Box::new(report_in_hf_names(*report)),
        }),
        Err(e) => Err(e),
    }
}

/// The model's parameters as (HF key, PyTorch shape), sorted; cheap (lazy shapes).
pub fn hf_keys(model: &Dinov3Vit) -> Vec<(String, Vec<usize>)> {
    let mut keys: Vec<_> = module_keys(model)
        .into_iter()
        .map(|(k, s)| (to_hf_name(&k), s))
        .collect();
    keys.sort();
    keys
}

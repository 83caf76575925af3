//! Building the network for training: configuration, initial weights (a MonSter++ `.pth` or one
//! of our safetensors checkpoints, optionally a Depth Anything V2 checkpoint first), the
//! upstream freeze (mono branch frozen, 2-D BatchNorm on running statistics), on the autodiff
//! device.

use std::path::Path;

use burn::tensor::Device;
use nn::monster::Monster;
use nn::weights::load_weights;

use crate::config::TrainConfig;
use crate::TrainError;

/// What was loaded into the model (for the run's log).
#[derive(Debug, Clone, Default)]
pub struct InitReport {
    /// Lines such as `init: path (1002 tensors)`.
    pub lines: Vec<String>,
    /// Parameters in the model / trained (the mono branch excluded).
    pub params: usize,
    pub trainable_params: usize,
}

fn non_empty(p: &Option<std::path::PathBuf>) -> Option<&Path> {
    p.as_deref().filter(|p| !p.as_os_str().is_empty())
}

/// The model of `config` on `device` (an autodiff device, e.g. `Device::flex().autodiff()`),
/// loaded from `weights` when given (a resumed checkpoint), else from the configured
/// Depth Anything and `init` checkpoints, then frozen as upstream.
pub fn build_model(
    config: &TrainConfig,
    device: &Device,
    weights: Option<&Path>,
) -> Result<(Monster, InitReport), TrainError> {
    let mc = config
        .monster_config()
        .map_err(|e| TrainError::Config(e.0))?;
    // Parameters without loaded weights are initialised (lazily, on first use) from the
    // device's random generator: seed it so a run is reproducible.
    device.seed(config.run.seed);
    let mut model = Monster::new(&mc, device);
    let mut report = InitReport::default();
    let load_err = |e: nn::weights::WeightsError| TrainError::Weights(e.to_string());
    match weights {
        Some(w) => {
            let r = load_weights(&mut model, w).map_err(load_err)?;
            report.lines.push(format!(
                "resumed weights: {} ({} tensors)",
                w.display(),
                r.applied
            ));
        }
        None => {
            if let Some(da) = non_empty(&config.model.depth_anything) {
                let r = model.load_depth_anything(da).map_err(load_err)?;
                let applied: usize = r.iter().map(|x| x.applied).sum();
                report.lines.push(format!(
                    "Depth Anything V2: {} ({applied} tensors into mono_encoder, mono_decoder, feat_decoder)",
                    da.display()
                ));
            }
            match non_empty(&config.model.init) {
                Some(init) => {
                    let r = load_weights(&mut model, init).map_err(load_err)?;
                    let unexpected = if r.unexpected.is_empty() {
                        String::new()
                    } else {
                        format!(", {} unexpected keys ignored", r.unexpected.len())
                    };
                    report.lines.push(format!(
                        "initial weights: {} ({} tensors{unexpected})",
                        init.display(),
                        r.applied
                    ));
                }
                None => report.lines.push(
                    "initial weights: none (random initialisation; set model.init to a MonSter++ checkpoint for real runs)"
                        .into(),
                ),
            }
        }
    }
    report.params = model.num_params();
    report.trainable_params = model.num_trainable_params();
    Ok((model.freeze_for_training(), report))
}

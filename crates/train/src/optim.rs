//! AdamW as upstream MonSter++ / SeasonStereo use it: two parameter groups (the DPT copy
//! `feat_decoder` at a fraction of the learning rate, everything else trainable at the full rate),
//! global gradient-norm clipping as `torch.nn.utils.clip_grad_norm_`, and a state that can be
//! saved and restored bit-exactly across processes.
//!
//! Why not burn's own clipping: `GradientClippingConfig::Norm` clips every tensor by its own norm;
//! PyTorch clips all gradients together by their global norm. Why two learning rates instead of
//! scaled gradients: Adam normalises the gradient, so scaling it does not change the step; the
//! half rate must be applied to the update itself (burn's `ModuleLearningRate` groups do that).
//!
//! burn keys the optimiser state by [`ParamId`], and a model rebuilt in a new process gets new
//! ids. [`param_ids`] and [`assign_param_ids`] save and restore the ids by parameter path so a
//! resumed run finds its AdamW moments again.

use std::collections::BTreeMap;
use std::path::Path;

use burn::module::{Module, ModuleMapper, ModuleVisitor, Param, ParamGroup, ParamId};
use burn::optim::lr_scheduler::module_lr_scheduler::{ModuleLearningRate, ModuleLrScheduler};
use burn::optim::{AdamWConfig, GradientsParams, ModuleOptimizer};
use burn::tensor::Tensor;
use serde::{Deserialize, Serialize};

/// Optimiser hyper-parameters (defaults: the paper's AdamW, lr 5e-4, weight decay 1e-5,
/// eps 1e-8, PyTorch betas, clipping at norm 1.0, `feat_decoder` at half the rate).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OptimConfig {
    /// Peak learning rate of the one-cycle schedule.
    pub lr: f64,
    /// Decoupled weight decay (AdamW).
    pub weight_decay: f32,
    /// Adam epsilon.
    pub eps: f32,
    /// Adam beta 1.
    pub beta1: f32,
    /// Adam beta 2.
    pub beta2: f32,
    /// Global gradient-norm clipping threshold (`None`: no clipping).
    pub grad_clip_norm: Option<f64>,
    /// Learning-rate factor of the DPT copy `feat_decoder` (upstream 0.5).
    pub feat_decoder_lr_factor: f64,
}

impl Default for OptimConfig {
    fn default() -> Self {
        Self {
            lr: 5e-4,
            weight_decay: 1e-5,
            eps: 1e-8,
            beta1: 0.9,
            beta2: 0.999,
            grad_clip_norm: Some(1.0),
            feat_decoder_lr_factor: 0.5,
        }
    }
}

/// Root module of the reduced-rate group.
pub const FEAT_DECODER: &str = "feat_decoder";

/// What one optimiser step did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepReport {
    /// Global L2 norm of the gradients before clipping.
    pub grad_norm: f64,
    /// Factor the gradients were multiplied by (1 when not clipped).
    pub clip_factor: f64,
    /// Number of parameter tensors that received a gradient.
    pub params_with_grad: usize,
}

/// AdamW with the upstream parameter groups and global clipping.
#[derive(Clone)]
pub struct Optimizer {
    inner: ModuleOptimizer,
    config: OptimConfig,
}

/// A failure to save or load the optimiser state (the message names the file).
#[derive(Debug, thiserror::Error)]
#[error("{file}: {message}")]
pub struct OptimStateError {
    /// The file.
    pub file: std::path::PathBuf,
    /// What went wrong.
    pub message: String,
}

impl Optimizer {
    /// A fresh optimiser (no moments yet).
    pub fn new(config: &OptimConfig) -> Self {
        let adamw = AdamWConfig::new()
            .with_beta_1(config.beta1)
            .with_beta_2(config.beta2)
            .with_epsilon(config.eps)
            .with_weight_decay(config.weight_decay)
            .init();
        Self {
            inner: adamw,
            config: config.clone(),
        }
    }

    /// The learning rate of every parameter for a step at base rate `lr`.
    pub fn learning_rates(&self, lr: f64) -> ModuleLearningRate {
        ModuleLrScheduler::new(lr)
            .with_group(
                ParamGroup::from_predicate(FEAT_DECODER),
                lr * self.config.feat_decoder_lr_factor,
            )
            .step()
    }

    /// One update of `model` at base learning rate `lr`: clip the gradients by their global
    /// norm, then AdamW with the group rates. Parameters without a gradient (frozen ones) are
    /// not touched. Returns `None` in the report's place when the gradients are not finite: the
    /// step is skipped (the model is returned unchanged) so one bad batch cannot poison the
    /// weights.
    pub fn step<M: Module>(
        &mut self,
        lr: f64,
        model: M,
        mut grads: GradientsParams,
    ) -> (M, Option<StepReport>) {
        let (sum_sq, count) = {
            let mut norm = GradNorm {
                grads: &grads,
                sum: None,
                count: 0,
            };
            model.visit(&mut norm);
            let sum = norm
                .sum
                .map(|s| s.into_scalar::<f32>() as f64)
                .unwrap_or(0.0);
            (sum, norm.count)
        };
        let grad_norm = sum_sq.sqrt();
        if !grad_norm.is_finite() {
            return (model, None);
        }
        let mut clip_factor = 1.0;
        if let Some(max_norm) = self.config.grad_clip_norm {
            // torch.nn.utils.clip_grad_norm_: coef = max_norm / (norm + 1e-6), clamped to 1.
            let coef = max_norm / (grad_norm + 1e-6);
            if coef < 1.0 {
                clip_factor = coef;
                model.visit(&mut GradScale {
                    grads: &mut grads,
                    factor: coef,
                });
            }
        }
        let rates = self.learning_rates(lr);
        let model = self.inner.step(rates, model, grads);
        (
            model,
            Some(StepReport {
                grad_norm,
                clip_factor,
                params_with_grad: count,
            }),
        )
    }

    /// Writes the AdamW moments and step counts (burnpack format) to `path` (not atomic: the
    /// checkpoint writer renames the whole folder).
    pub fn save(&self, path: &Path) -> Result<(), OptimStateError> {
        self.inner.save(path).map_err(|e| OptimStateError {
            file: path.to_path_buf(),
            message: format!("cannot write the optimiser state: {e}"),
        })
    }

    /// Restores the state written by [`save`](Self::save). The model's parameter ids must be the
    /// saved ones (see [`assign_param_ids`]).
    pub fn load(self, path: &Path) -> Result<Self, OptimStateError> {
        let config = self.config.clone();
        let inner = self.inner.load(path).map_err(|e| OptimStateError {
            file: path.to_path_buf(),
            message: format!("cannot read the optimiser state (corrupt or not a burnpack file: delete the checkpoint or resume from another): {e}"),
        })?;
        Ok(Self { inner, config })
    }
}

/// Sums the squares of every float parameter's gradient (one lazy tensor, read once).
struct GradNorm<'a> {
    grads: &'a GradientsParams,
    sum: Option<Tensor<1>>,
    count: usize,
}

impl ModuleVisitor for GradNorm<'_> {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        if let Some(g) = self.grads.get::<D>(param.id) {
            let s = g.square().sum();
            self.sum = Some(match self.sum.take() {
                Some(acc) => acc + s,
                None => s,
            });
            self.count += 1;
        }
    }
}

/// Multiplies every float parameter's gradient by `factor`.
struct GradScale<'a> {
    grads: &'a mut GradientsParams,
    factor: f64,
}

impl ModuleVisitor for GradScale<'_> {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        if let Some(g) = self.grads.remove::<D>(param.id) {
            self.grads.register(param.id, g.mul_scalar(self.factor));
        }
    }
}

/// The id of every float parameter by its path (`feat_decoder.scratch.layer1_rn.weight`).
pub fn param_ids<M: Module>(model: &M) -> BTreeMap<String, u64> {
    struct Ids {
        path: Vec<String>,
        out: BTreeMap<String, u64>,
    }
    impl ModuleVisitor for Ids {
        fn enter_module(&mut self, name: &str, _: &str) {
            self.path.push(name.to_string());
        }
        fn exit_module(&mut self, _: &str, _: &str) {
            self.path.pop();
        }
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            self.out.insert(self.path.join("."), param.id.val());
        }
    }
    let mut ids = Ids {
        path: Vec::new(),
        out: BTreeMap::new(),
    };
    model.visit(&mut ids);
    ids.out
}

/// Gives the float parameters the ids in `ids` (by path), so a saved optimiser state applies to
/// a model rebuilt in another process. Errors name the first path missing on either side.
pub fn assign_param_ids<M: Module>(model: M, ids: &BTreeMap<String, u64>) -> Result<M, String> {
    let current = param_ids(&model);
    if let Some(p) = current.keys().find(|p| !ids.contains_key(*p)) {
        return Err(format!(
            "the model parameter {p} has no saved id (checkpoint from another model configuration?)"
        ));
    }
    if let Some(p) = ids.keys().find(|p| !current.contains_key(*p)) {
        return Err(format!(
            "the checkpoint has a parameter {p} the model does not (checkpoint from another model configuration?)"
        ));
    }
    struct Assign<'a> {
        path: Vec<String>,
        ids: &'a BTreeMap<String, u64>,
    }
    impl ModuleMapper for Assign<'_> {
        fn enter_module(&mut self, name: &str, _: &str) {
            self.path.push(name.to_string());
        }
        fn exit_module(&mut self, _: &str, _: &str) {
            self.path.pop();
        }
        fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
            let (id, tensor, mapper) = param.consume();
            let id = self
                .ids
                .get(&self.path.join("."))
                .map(|&v| ParamId::from(v))
                .unwrap_or(id);
            Param::from_mapped_value(id, tensor, mapper)
        }
    }
    Ok(model.map(&mut Assign {
        path: Vec::new(),
        ids,
    }))
}

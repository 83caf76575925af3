//! The training loop: batches → forward in train mode → SeasonStereo sequence loss → backward →
//! global clipping → AdamW (two learning-rate groups) → one-cycle schedule; periodic validation,
//! atomic checkpoints, exact resume, clean stop on request (Ctrl-C).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

use burn::module::Module;
use burn::optim::GradientsParams;
use burn::tensor::Device;
use nn::monster::Monster;

use crate::checkpoint::{self, Checkpoint, CheckpointState};
use crate::config::TrainConfig;
use crate::data::{network_inputs, PreparedSample, TrainData, ValidData};
use crate::loss::{sequence_loss, LossBatch, LossTerms};
use crate::metrics::{
    pair_scores, peak_rss_bytes, RunLogs, ValidationAccumulator, ValidationScores,
};
use crate::optim::{assign_param_ids, param_ids, Optimizer};
use crate::schedule::OneCycle;
use crate::setup::build_model;
use crate::TrainError;

/// One finished optimiser step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepRecord {
    /// Steps done after this one (1-based).
    pub step: usize,
    /// Total steps of the run.
    pub total_steps: usize,
    /// Base learning rate of this step (`feat_decoder` used `lr × feat_decoder_lr_factor`).
    pub lr: f64,
    /// The loss terms (λ- and sequence-weighted, summed as the release logs them).
    pub terms: LossTerms,
    /// Global gradient norm before clipping (`NaN` when the step was skipped).
    pub grad_norm: f64,
    /// Factor applied by the clipping (1 = not clipped).
    pub clip_factor: f64,
    /// True when the gradients were not finite and the update was skipped.
    pub skipped: bool,
    /// Wall time of this step, seconds.
    pub seconds: f64,
    /// Steps per second averaged over this session.
    pub its_per_s: f64,
}

/// One validation pass.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ValidationRecord {
    /// Steps done when it ran.
    pub step: usize,
    pub scores: ValidationScores,
    pub seconds: f64,
}

/// Receives the progress of a run (the CLI draws a bar; tests collect the records).
pub trait Observer {
    /// The run starts at `start_step` of `total_steps` (non-zero when resumed); `lines` describe
    /// the setup (weights loaded, data, parameters).
    fn started(&mut self, _start_step: usize, _total_steps: usize, _lines: &[String]) {}
    /// A step finished.
    fn step(&mut self, _record: &StepRecord) {}
    /// Validation is starting over `pairs` pairs.
    fn validation_started(&mut self, _pairs: usize) {}
    /// A validation pair was scored.
    fn validation_pair(&mut self, _done: usize) {}
    /// A validation pass finished.
    fn validated(&mut self, _record: &ValidationRecord) {}
    /// A checkpoint was written.
    fn checkpointed(&mut self, _dir: &Path) {}
}

/// Shows nothing.
pub struct Quiet;
impl Observer for Quiet {}

/// Run options that are not hyper-parameters.
#[derive(Debug, Clone, Default)]
pub struct TrainOptions {
    /// Continue from this checkpoint (or run folder's newest checkpoint).
    pub resume: Option<PathBuf>,
    /// Set by a signal handler (see [`interrupt_flag`]): the loop saves a checkpoint after the
    /// current step and returns.
    pub stop: Option<Arc<AtomicBool>>,
    /// Stop (with a checkpoint) once this many steps are done: what an interruption after a
    /// checkpoint looks like, for tests and time-boxed sessions.
    pub stop_after: Option<usize>,
    /// Compute device (default: `Device::flex()`); the model trains on its autodiff version.
    pub device: Option<Device>,
}

/// How a run ended.
#[derive(Debug, Clone, PartialEq)]
pub struct TrainSummary {
    /// Steps done (of the configured total).
    pub steps_done: usize,
    pub total_steps: usize,
    /// True when it stopped early (interrupt or `stop_after`) with a checkpoint.
    pub interrupted: bool,
    /// Loss of the first and the last step of this session.
    pub first_loss: Option<f32>,
    pub last_loss: Option<f32>,
    /// Validation scores before the first step of this session (when `validate_at_start`) and at
    /// the end.
    pub first_validation: Option<ValidationScores>,
    pub last_validation: Option<ValidationScores>,
    /// Every step's loss terms of this session (in order).
    pub losses: Vec<LossTerms>,
    /// Steps per second over this session (excluding validation and checkpoints).
    pub its_per_s: f64,
    /// Peak resident memory of the process, bytes (Linux).
    pub peak_rss_bytes: Option<u64>,
    /// The last checkpoint written.
    pub checkpoint: Option<PathBuf>,
}

/// A stop flag set by Ctrl-C (a second Ctrl-C exits at once with status 130).
pub fn interrupt_flag() -> Result<Arc<AtomicBool>, TrainError> {
    let flag = Arc::new(AtomicBool::new(false));
    let f = flag.clone();
    ctrlc::set_handler(move || {
        if f.swap(true, Ordering::SeqCst) {
            eprintln!("interrupted twice: exiting without a checkpoint");
            std::process::exit(130);
        }
        eprintln!(
            "interrupt: saving a checkpoint after the current step (Ctrl-C again to exit now)"
        );
    })
    .map_err(|e| TrainError::Io(format!("cannot install the Ctrl-C handler: {e}")))?;
    Ok(flag)
}

/// The configuration to resume `path` with: the checkpoint's own, then `overrides`.
pub fn resume_config(path: &Path, overrides: &[String]) -> Result<TrainConfig, TrainError> {
    let ck = Checkpoint::open(path)?;
    TrainConfig::from_toml(
        &ck.state.config,
        overrides,
        &ck.dir.join(checkpoint::STATE_FILE).display().to_string(),
    )
    .map_err(|e| TrainError::Config(e.0))
}

/// The optimisation state of a run: what one step needs besides the model and the batch.
pub struct Session {
    config: TrainConfig,
    device: Device,
    optimizer: Optimizer,
    schedule: OneCycle,
    best_epe: Option<f64>,
}

impl Session {
    /// A fresh session (new optimiser) for `config` on the autodiff `device`.
    pub fn new(config: &TrainConfig, device: &Device) -> Result<Self, TrainError> {
        Ok(Self {
            config: config.clone(),
            device: device.clone(),
            optimizer: Optimizer::new(&config.optim),
            schedule: OneCycle::new(config.optim.lr, config.run.steps, &config.schedule)
                .map_err(|e| TrainError::Config(e.to_string()))?,
            best_epe: None,
        })
    }

    /// The learning rate of 0-based step `step`.
    pub fn lr(&self, step: usize) -> f64 {
        self.schedule.lr(step)
    }

    /// One optimiser step on `batch` at base learning rate `lr` (forward in train mode,
    /// sequence loss, backward, clipping, AdamW). Returns the updated model, the loss terms and
    /// the optimiser's report (`None`: non-finite gradients, update skipped).
    pub fn step(
        &mut self,
        model: Monster,
        batch: &[PreparedSample],
        lr: f64,
    ) -> Result<(Monster, LossTerms, Option<crate::optim::StepReport>), TrainError> {
        let device = self.device.clone();
        nn::device::on_cpu_pool(&device, || train_step(self, model, batch, lr))
    }
}

/// Trains as `config` says (see the module docs).
pub fn train(
    config: &TrainConfig,
    options: &TrainOptions,
    observer: &mut dyn Observer,
) -> Result<TrainSummary, TrainError> {
    config.validate().map_err(|e| TrainError::Config(e.0))?;
    let base = options.device.clone().unwrap_or_else(Device::flex);
    let device = base.clone().autodiff();
    let output = &config.run.output;
    std::fs::create_dir_all(output).map_err(|e| TrainError::io(output, e))?;

    let data = TrainData::open(config)?;
    let valid = ValidData::open(config)?;
    let resume = options
        .resume
        .as_deref()
        .map(Checkpoint::open)
        .transpose()?;

    let (model, init) = build_model(
        config,
        &device,
        resume.as_ref().map(|c| c.model_path()).as_deref(),
    )?;
    let mut optimizer = Optimizer::new(&config.optim);
    let (mut model, start_step, best_epe) = match &resume {
        Some(ck) => {
            let model = assign_param_ids(model, &ck.state.param_ids)
                .map_err(|e| TrainError::Checkpoint(format!("{}: {e}", ck.dir.display())))?;
            optimizer = optimizer
                .load(&ck.optimizer_path())
                .map_err(|e| TrainError::Checkpoint(e.to_string()))?;
            if ck.state.seed != config.run.seed {
                return Err(TrainError::Checkpoint(format!(
                    "{}: the checkpoint was trained with run.seed = {}, the configuration says {}; an exact resume needs the same seed",
                    ck.dir.display(),
                    ck.state.seed,
                    config.run.seed
                )));
            }
            (model, ck.state.step, ck.state.best_epe)
        }
        None => (model, 0, None),
    };
    if start_step >= config.run.steps {
        return Err(TrainError::Config(format!(
            "the checkpoint is at step {start_step}, the run has {} steps; raise run.steps to continue",
            config.run.steps
        )));
    }

    let config_path = output.join("config.toml");
    raster::formats::write_atomically(&config_path, |f| {
        use std::io::Write;
        f.write_all(config.to_toml().as_bytes())
    })
    .map_err(|e| TrainError::Io(e.to_string()))?;
    let resumed = resume.as_ref().map(|_| start_step);
    let mut logs = RunLogs::open(output, resumed)?;

    let mut lines = init.lines.clone();
    lines.push(format!("device: {base:?}"));
    lines.push(format!(
        "parameters: {:.2} M, trained {:.2} M (mono branch frozen)",
        init.params as f64 / 1e6,
        init.trainable_params as f64 / 1e6
    ));
    lines.push(format!(
        "training samples: {} ({} batches of {} per epoch); validation pairs: {}",
        data.len(),
        data.batches_per_epoch(),
        config.run.batch_size,
        valid.as_ref().map_or(0, |v| v.len())
    ));
    if let Some(ck) = &resume {
        lines.push(format!(
            "resumed from {} at step {start_step}",
            ck.dir.display()
        ));
    }
    observer.started(start_step, config.run.steps, &lines);

    let schedule = OneCycle::new(config.optim.lr, config.run.steps, &config.schedule)
        .map_err(|e| TrainError::Config(e.to_string()))?;
    let mut session = Session {
        config: config.clone(),
        device,
        optimizer,
        schedule,
        best_epe,
    };
    let mut summary = TrainSummary {
        steps_done: start_step,
        total_steps: config.run.steps,
        interrupted: false,
        first_loss: None,
        last_loss: None,
        first_validation: None,
        last_validation: None,
        losses: Vec::new(),
        its_per_s: 0.0,
        peak_rss_bytes: None,
        checkpoint: None,
    };

    if config.run.validate_at_start && resume.is_none() {
        if let Some(v) = &valid {
            let r = validate(&model, v, &base, config, start_step, observer)?;
            logs.validation(&r)?;
            summary.first_validation = r.as_ref().map(|r| r.scores);
        }
    }

    let mut train_seconds = 0.0;
    for step in start_step..config.run.steps {
        let t0 = Instant::now();
        let batch = data.batch(step)?;
        let lr = session.schedule.lr(step);
        let (next, terms, report) = train_step(&mut session, model, &batch, lr)?;
        model = next;
        let seconds = t0.elapsed().as_secs_f64();
        train_seconds += seconds;
        let done = step + 1;
        let steps_here = done - start_step;
        let record = StepRecord {
            step: done,
            total_steps: config.run.steps,
            lr,
            terms,
            grad_norm: report.map_or(f64::NAN, |r| r.grad_norm),
            clip_factor: report.map_or(f64::NAN, |r| r.clip_factor),
            skipped: report.is_none(),
            seconds,
            its_per_s: steps_here as f64 / train_seconds.max(1e-9),
        };
        logs.step(&record)?;
        observer.step(&record);
        summary.first_loss.get_or_insert(terms.total);
        summary.last_loss = Some(terms.total);
        summary.losses.push(terms);
        summary.steps_done = done;
        summary.its_per_s = record.its_per_s;

        let stop_requested = options
            .stop
            .as_ref()
            .is_some_and(|s| s.load(Ordering::SeqCst))
            || options.stop_after.is_some_and(|n| done >= n);
        let last = done == config.run.steps;
        if config.run.validate_every > 0 && done % config.run.validate_every == 0 || last {
            if let Some(v) = &valid {
                let r = validate(&model, v, &base, config, done, observer)?;
                logs.validation(&r)?;
                if let Some(r) = r {
                    summary.last_validation = Some(r.scores);
                    if r.scores.epe.is_finite() && session.best_epe.is_none_or(|b| r.scores.epe < b)
                    {
                        session.best_epe = Some(r.scores.epe);
                        let best = output.join("best.safetensors");
                        save_model_atomically(&model, &best)?;
                    }
                }
            }
        }
        if done % config.run.checkpoint_every == 0 || last || stop_requested {
            let dir = save_checkpoint(&session, &model, done, lr)?;
            checkpoint::prune(output, config.run.keep_checkpoints)?;
            observer.checkpointed(&dir);
            summary.checkpoint = Some(dir);
        }
        if stop_requested && !last {
            summary.interrupted = true;
            break;
        }
    }
    if summary.steps_done == config.run.steps {
        let final_path = output.join("final.safetensors");
        save_model_atomically(&model, &final_path)?;
    }
    summary.peak_rss_bytes = peak_rss_bytes();
    Ok(summary)
}

/// One optimiser step on `batch` at learning rate `lr`.
fn train_step(
    session: &mut Session,
    model: Monster,
    batch: &[PreparedSample],
    lr: f64,
) -> Result<(Monster, LossTerms, Option<crate::optim::StepReport>), TrainError> {
    let cfg = &session.config;
    let items: Vec<_> = batch.iter().map(PreparedSample::loss_item).collect();
    let loss_batch = LossBatch::new(&items, &cfg.loss, &session.device)
        .map_err(|e| TrainError::Loss(e.to_string()))?;
    let (left, right) = network_inputs(batch, &session.device);
    // One scope for the forward and the backward: the convolutions prepare each weight tensor
    // once (the ConvGRU runs its layers every iteration, the input gradients read them again).
    let (grads, terms) = nn::conv::with_prepared_weights(|| -> Result<_, TrainError> {
        let out = model.forward(left, right, cfg.run.train_iters, false);
        let init = out.init_disp_up.ok_or_else(|| {
            TrainError::Loss("the train-mode forward returned no init_disp_up".into())
        })?;
        let loss = sequence_loss(&cfg.loss, &loss_batch, init, &out.disp_preds)
            .map_err(|e| TrainError::Loss(e.to_string()))?;
        Ok((loss.total.backward(), loss.terms))
    })?;
    let grads = GradientsParams::from_grads(grads, &model);
    let (model, report) = session.optimizer.step(lr, model, grads);
    Ok((model, terms, report))
}

/// Scores the model (test mode, `valid_iters`, no autodiff, BatchNorm3d on running statistics
/// as `model.eval()` upstream) on the validation pairs.
fn validate(
    model: &Monster,
    valid: &ValidData,
    base: &Device,
    config: &TrainConfig,
    step: usize,
    observer: &mut dyn Observer,
) -> Result<Option<ValidationRecord>, TrainError> {
    let t0 = Instant::now();
    let eval = model.valid();
    let mut acc = ValidationAccumulator::default();
    observer.validation_started(valid.len());
    for i in 0..valid.len() {
        let s = valid.get(i)?;
        let prepared = PreparedSample {
            input_left: s.left.clone(),
            input_right: s.right.clone(),
            real_left: s.left,
            real_right: s.right,
            target: s.truth.clone(),
            valid_left: s.valid.clone(),
            building_left: s.valid.clone(),
            stem: s.stem,
            diachronic: s.diachronic,
        };
        let (left, right) = network_inputs(std::slice::from_ref(&prepared), base);
        let out = eval.forward(left, right, config.run.valid_iters, true);
        let pred: Vec<f32> = out
            .disp
            .into_data()
            .convert::<f32>()
            .try_into_vec::<f32>()
            .map_err(|e| {
                TrainError::Loss(format!("cannot read the validation prediction: {e:?}"))
            })?;
        if let Some(scores) = pair_scores(&pred, s.truth.data(), s.valid.data()) {
            acc.add(scores, prepared.diachronic);
        }
        observer.validation_pair(i + 1);
    }
    let record = acc.finish().map(|scores| ValidationRecord {
        step,
        scores,
        seconds: t0.elapsed().as_secs_f64(),
    });
    if let Some(r) = &record {
        observer.validated(r);
    }
    Ok(record)
}

fn save_model_atomically(model: &Monster, path: &Path) -> Result<(), TrainError> {
    let tmp = path.with_extension(format!("partial-{}.safetensors", std::process::id()));
    nn::weights::save_checkpoint(model, &tmp).map_err(|e| TrainError::Weights(e.to_string()))?;
    std::fs::rename(&tmp, path).map_err(|e| TrainError::io(path, e))
}

fn save_checkpoint(
    session: &Session,
    model: &Monster,
    step: usize,
    last_lr: f64,
) -> Result<PathBuf, TrainError> {
    let state = CheckpointState {
        format: checkpoint::FORMAT,
        step,
        seed: session.config.run.seed,
        last_lr,
        best_epe: session.best_epe,
        param_ids: param_ids(model),
        config: session.config.to_toml(),
    };
    checkpoint::write(
        &session.config.run.output,
        &state,
        |p| nn::weights::save_checkpoint(model, p).map_err(|e| TrainError::Weights(e.to_string())),
        |p| {
            session
                .optimizer
                .save(p)
                .map_err(|e| TrainError::Checkpoint(e.to_string()))
        },
    )
}

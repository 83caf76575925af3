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
use crate::metrics::{pair_scores, peak_rss_bytes, RunLogs, ValidationAccumulator};
pub use crate::metrics::{StepRecord, ValidationRecord, ValidationScores};
use crate::optim::{assign_param_ids, param_ids, Optimizer};
use crate::schedule::OneCycle;
use crate::setup::{build_model, InitReport};
use crate::TrainError;

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
        Self::with_state(config, device, Optimizer::new(&config.optim), None)
    }

    /// A session that continues with `optimizer` and the best validation EPE so far.
    fn with_state(
        config: &TrainConfig,
        device: &Device,
        optimizer: Optimizer,
        best_epe: Option<f64>,
    ) -> Result<Self, TrainError> {
        Ok(Self {
            config: config.clone(),
            device: device.clone(),
            optimizer,
            schedule: OneCycle::new(config.optim.lr, config.run.steps, &config.schedule)
                .map_err(|e| TrainError::Config(e.to_string()))?,
            best_epe,
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
    let (mut model, optimizer, start_step, best_epe) =
        restore_state(model, config, resume.as_ref())?;
    write_run_config(config)?;
    let logs = RunLogs::open(output, resume.as_ref().map(|_| start_step))?;
    let mut lines = setup_lines(&init, &base, &data, valid.as_ref(), config);
    lines.extend(resume_line(resume.as_ref(), start_step));
    observer.started(start_step, config.run.steps, &lines);

    let mut run = Run {
        config,
        options,
        base,
        data,
        valid,
        logs,
        session: Session::with_state(config, &device, optimizer, best_epe)?,
        summary: TrainSummary::starting_at(start_step, config.run.steps),
        start_step,
        train_seconds: 0.0,
    };
    if config.run.validate_at_start && resume.is_none() {
        run.summary.first_validation = run.validate(&model, start_step, observer)?;
    }
    for step in start_step..config.run.steps {
        let (next, record) = run.step(model, step)?;
        model = next;
        observer.step(&record);
        let done = record.step;
        let stop_requested = run.stop_requested(done);
        let last = done == config.run.steps;
        if run.validation_due(done) || last {
            run.validate_and_keep_best(&model, done, observer)?;
        }
        if done % config.run.checkpoint_every == 0 || last || stop_requested {
            run.checkpoint(&model, done, record.lr, observer)?;
        }
        if stop_requested && !last {
            run.summary.interrupted = true;
            break;
        }
    }
    run.finish(&model)
}

/// The model, optimiser, next step and best EPE to start from: the checkpoint's when resuming
/// (which must match the configured seed and leave steps to do), otherwise fresh ones.
fn restore_state(
    model: Monster,
    config: &TrainConfig,
    resume: Option<&Checkpoint>,
) -> Result<(Monster, Optimizer, usize, Option<f64>), TrainError> {
    let optimizer = Optimizer::new(&config.optim);
    let (model, optimizer, start_step, best_epe) = match resume {
        Some(ck) => {
            let model = assign_param_ids(model, &ck.state.param_ids)
                .map_err(|e| TrainError::Checkpoint(format!("{}: {e}", ck.dir.display())))?;
            let optimizer = optimizer
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
            (model, optimizer, ck.state.step, ck.state.best_epe)
        }
        None => (model, optimizer, 0, None),
    };
    if start_step >= config.run.steps {
        return Err(TrainError::Config(format!(
            "the checkpoint is at step {start_step}, the run has {} steps; raise run.steps to continue",
            config.run.steps
        )));
    }
    Ok((model, optimizer, start_step, best_epe))
}

/// Writes the effective configuration into the run folder, so a run can be read (and resumed)
/// without the files and overrides it was started with.
fn write_run_config(config: &TrainConfig) -> Result<(), TrainError> {
    let config_path = config.run.output.join("config.toml");
    raster::formats::write_atomically(&config_path, |f| {
        use std::io::Write;
        f.write_all(config.to_toml().as_bytes())
    })
    .map_err(|e| TrainError::Io(e.to_string()))
}

/// What the run starts with, in words: the weights loaded, device, parameters and data sizes.
fn setup_lines(
    init: &InitReport,
    base: &Device,
    data: &TrainData,
    valid: Option<&ValidData>,
    config: &TrainConfig,
) -> Vec<String> {
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
        valid.map_or(0, |v| v.len())
    ));
    lines
}

/// The line saying which checkpoint the run resumes from, when it does.
fn resume_line(resume: Option<&Checkpoint>, start_step: usize) -> Option<String> {
    resume.map(|ck| format!("resumed from {} at step {start_step}", ck.dir.display()))
}

impl TrainSummary {
    /// The summary of a session that has not stepped yet, `start_step` of `total_steps` done.
    fn starting_at(start_step: usize, total_steps: usize) -> Self {
        Self {
            steps_done: start_step,
            total_steps,
            interrupted: false,
            first_loss: None,
            last_loss: None,
            first_validation: None,
            last_validation: None,
            losses: Vec::new(),
            its_per_s: 0.0,
            peak_rss_bytes: None,
            checkpoint: None,
        }
    }
}

/// A run in progress: what the loop carries from one step to the next.
struct Run<'a> {
    config: &'a TrainConfig,
    options: &'a TrainOptions,
    /// The device validation runs on (without autodiff).
    base: Device,
    data: TrainData,
    valid: Option<ValidData>,
    logs: RunLogs,
    session: Session,
    summary: TrainSummary,
    start_step: usize,
    /// Seconds spent in steps this session (validation and checkpoints excluded).
    train_seconds: f64,
}

impl Run<'_> {
    /// Trains 0-based step `step` and logs it; returns the updated model and the step's record.
    fn step(&mut self, model: Monster, step: usize) -> Result<(Monster, StepRecord), TrainError> {
        let t0 = Instant::now();
        let batch = self.data.batch(step)?;
        let lr = self.session.schedule.lr(step);
        let (model, terms, report) = train_step(&mut self.session, model, &batch, lr)?;
        let seconds = t0.elapsed().as_secs_f64();
        self.train_seconds += seconds;
        let done = step + 1;
        let record = StepRecord {
            step: done,
            total_steps: self.config.run.steps,
            lr,
            terms,
            grad_norm: report.map_or(f64::NAN, |r| r.grad_norm),
            clip_factor: report.map_or(f64::NAN, |r| r.clip_factor),
            skipped: report.is_none(),
            seconds,
            its_per_s: (done - self.start_step) as f64 / self.train_seconds.max(1e-9),
        };
        self.logs.step(&record)?;
        let summary = &mut self.summary;
        summary.first_loss.get_or_insert(terms.total);
        summary.last_loss = Some(terms.total);
        summary.losses.push(terms);
        summary.steps_done = done;
        summary.its_per_s = record.its_per_s;
        Ok((model, record))
    }

    /// True when an interrupt was signalled or the `stop_after` step count is reached.
    fn stop_requested(&self, done: usize) -> bool {
        self.options
            .stop
            .as_ref()
            .is_some_and(|s| s.load(Ordering::SeqCst))
            || self.options.stop_after.is_some_and(|n| done >= n)
    }

    /// True when the configured validation period ends at `done` steps.
    fn validation_due(&self, done: usize) -> bool {
        let every = self.config.run.validate_every;
        every > 0 && done.is_multiple_of(every)
    }

    /// Validates (when there is validation data) and logs the pass; returns its scores.
    fn validate(
        &mut self,
        model: &Monster,
        done: usize,
        observer: &mut dyn Observer,
    ) -> Result<Option<ValidationScores>, TrainError> {
        let Some(valid) = &self.valid else {
            return Ok(None);
        };
        let record = validate(model, valid, &self.base, self.config, done, observer)?;
        self.logs.validation(&record)?;
        Ok(record.map(|r| r.scores))
    }

    /// Validates and saves `best.safetensors` when the EPE is the best of the run so far.
    fn validate_and_keep_best(
        &mut self,
        model: &Monster,
        done: usize,
        observer: &mut dyn Observer,
    ) -> Result<(), TrainError> {
        let Some(scores) = self.validate(model, done, observer)? else {
            return Ok(());
        };
        self.summary.last_validation = Some(scores);
        if scores.epe.is_finite() && self.session.best_epe.is_none_or(|b| scores.epe < b) {
            self.session.best_epe = Some(scores.epe);
            save_model_atomically(model, &self.config.run.output.join("best.safetensors"))?;
        }
        Ok(())
    }

    /// Writes a checkpoint after `done` steps and prunes the old ones.
    fn checkpoint(
        &mut self,
        model: &Monster,
        done: usize,
        lr: f64,
        observer: &mut dyn Observer,
    ) -> Result<(), TrainError> {
        let dir = save_checkpoint(&self.session, model, done, lr)?;
        checkpoint::prune(&self.config.run.output, self.config.run.keep_checkpoints)?;
        observer.checkpointed(&dir);
        self.summary.checkpoint = Some(dir);
        Ok(())
    }

    /// Saves `final.safetensors` when every step is done and closes the summary.
    fn finish(mut self, model: &Monster) -> Result<TrainSummary, TrainError> {
        if self.summary.steps_done == self.config.run.steps {
            save_model_atomically(model, &self.config.run.output.join("final.safetensors"))?;
        }
        self.summary.peak_rss_bytes = peak_rss_bytes();
        Ok(self.summary)
    }
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

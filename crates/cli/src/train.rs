//! `seasonstereo train`: fine-tune MonSter++ with the SeasonStereo loss (the work is in the
//! library's `seasonstereo::train`; this file parses arguments and draws the progress bar).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use seasonstereo::train::{
    interrupt_flag, resume_config, train, Observer, StepRecord, TrainConfig, TrainOptions,
    TrainSummary, ValidationRecord, PRESETS,
};

#[derive(Args)]
pub struct TrainArgs {
    /// Training configuration: a preset (tiny, a-lidar, b-disp, c-photo, d-full, s1, s2, s3) or a
    /// TOML file with every hyper-parameter. Not needed with --resume (the checkpoint has it).
    #[arg(short, long)]
    config: Option<String>,
    /// Override a configuration value, e.g. --set run.steps=1000 --set loss.lambda_photo=0
    /// (repeatable; applied after the file, before the flags below).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// Continue a run exactly: its output folder (newest checkpoint) or a checkpoints/step-*
    /// folder.
    #[arg(long)]
    resume: Option<PathBuf>,
    /// Dataset folder (= --set data.root=DIR).
    #[arg(long)]
    data: Option<PathBuf>,
    /// Initial weights, MonSter++ .pth or safetensors (= --set model.init=FILE).
    #[arg(long)]
    init: Option<PathBuf>,
    /// Output folder (= --set run.output=DIR).
    #[arg(short, long)]
    output: Option<PathBuf>,
    /// Optimiser steps (= --set run.steps=N).
    #[arg(long)]
    steps: Option<usize>,
    /// Stop with a checkpoint after this many steps (resume later with --resume).
    #[arg(long)]
    stop_after: Option<usize>,
    // Where training runs (a run may resume on another device: the checkpoint is device-free).
    #[command(flatten)]
    device: crate::args::DeviceArg,
    /// Print the resolved configuration as TOML and exit.
    #[arg(long)]
    print_config: bool,
}

fn path_value(p: &Path) -> String {
    // TOML string, escaped.
    toml_string(&p.display().to_string())
}

fn toml_string(s: &str) -> String {
    format!("\"{}\"", s.replace('\\', "\\\\").replace('"', "\\\""))
}

pub fn run(a: TrainArgs) -> Result<()> {
    let config = a.config()?;
    if a.print_config {
        print!("{}", config.to_toml());
        return Ok(());
    }
    let options = TrainOptions {
        resume: a.resume.clone(),
        stop: Some(interrupt_flag()?),
        stop_after: a.stop_after,
        device: Some(a.device.device.device().map_err(anyhow::Error::msg)?),
    };
    let mut bar = TrainBar::default();
    let summary = train(&config, &options, &mut bar)
        .with_context(|| format!("training run {:?}", config.name))?;
    bar.finish();
    print_summary(&summary);
    println!(
        "logs: {}, {}",
        config.run.output.join("metrics.csv").display(),
        config.run.output.join("validation.csv").display()
    );
    Ok(())
}

impl TrainArgs {
    /// The `key=value` overrides the flags stand for, after the `--set` ones.
    fn overrides(&self) -> Vec<String> {
        let mut overrides = self.set.clone();
        if let Some(d) = &self.data {
            overrides.push(format!("data.root={}", path_value(d)));
        }
        if let Some(i) = &self.init {
            overrides.push(format!("model.init={}", path_value(i)));
        }
        if let Some(o) = &self.output {
            overrides.push(format!("run.output={}", path_value(o)));
        }
        if let Some(s) = self.steps {
            overrides.push(format!("run.steps={s}"));
        }
        overrides
    }

    /// The run's configuration: a resumed run's own, or the preset/file with the overrides.
    fn config(&self) -> Result<TrainConfig> {
        let overrides = self.overrides();
        match (&self.resume, &self.config) {
            (Some(r), None) => Ok(resume_config(r, &overrides)?),
            (_, Some(c)) => Ok(TrainConfig::load(c, &overrides)?),
            (None, None) => anyhow::bail!(
                "give --config PRESET|FILE (presets: {}) or --resume RUN_DIR",
                PRESETS.join(", ")
            ),
        }
    }
}

/// The closing lines: steps and loss, validation, checkpoint.
fn print_summary(summary: &TrainSummary) {
    let loss = |v: Option<f32>| v.map_or("-".into(), |v| format!("{v:.4}"));
    let done = if summary.interrupted {
        "stopped after"
    } else {
        "done:"
    };
    let memory = summary.peak_rss_bytes.map_or(String::new(), |b| {
        format!(", peak memory {:.0} MiB", b as f64 / 1048576.0)
    });
    println!(
        "{done} {} of {} steps: loss {} → {}, {:.3} it/s{memory}",
        summary.steps_done,
        summary.total_steps,
        loss(summary.first_loss),
        loss(summary.last_loss),
        summary.its_per_s,
    );
    if let (Some(f), Some(l)) = (summary.first_validation, summary.last_validation) {
        println!(
            "validation EPE {:.3} → {:.3} px (bad-1 {:.1} % → {:.1} %, {} pairs)",
            f.epe,
            l.epe,
            100.0 * f.bad_1px,
            100.0 * l.bad_1px,
            l.pairs
        );
    } else if let Some(l) = summary.last_validation {
        println!(
            "validation EPE {:.3} px, bad-1 {:.1} %, bad-3 {:.1} % ({} pairs)",
            l.epe,
            100.0 * l.bad_1px,
            100.0 * l.bad_3px,
            l.pairs
        );
    }
    if let Some(c) = &summary.checkpoint {
        println!("checkpoint: {}", c.display());
    }
}

/// The progress bar: step, loss terms, learning rate and it/s.
#[derive(Default)]
struct TrainBar {
    bar: Option<ProgressBar>,
}

impl TrainBar {
    fn finish(&mut self) {
        if let Some(b) = self.bar.take() {
            b.finish();
        }
    }
}

impl Observer for TrainBar {
    fn started(&mut self, start: usize, total: usize, lines: &[String]) {
        for l in lines {
            eprintln!("{l}");
        }
        let bar = ProgressBar::new(total as u64);
        bar.set_style(
            ProgressStyle::with_template(
                "train [{bar:30}] {pos}/{len} {msg} {elapsed_precise} eta {eta}",
            )
            .expect("valid template")
            .progress_chars("=> "),
        );
        bar.set_position(start as u64);
        self.bar = Some(bar);
    }

    fn step(&mut self, r: &StepRecord) {
        if let Some(b) = &self.bar {
            b.set_position(r.step as u64);
            let t = &r.terms;
            b.set_message(format!(
                "loss {:.4} (disp {:.4} photo {:.4} smooth {:.4}) epe {:.2} lr {:.2e} {:.2} it/s{}",
                t.total,
                t.disp,
                t.photo,
                t.smooth,
                t.epe,
                r.lr,
                r.its_per_s,
                if r.skipped {
                    " [skipped: non-finite gradients]"
                } else {
                    ""
                }
            ));
        }
    }

    fn validation_started(&mut self, pairs: usize) {
        if let Some(b) = &self.bar {
            b.set_message(format!("validating {pairs} pairs…"));
        }
    }

    fn validated(&mut self, r: &ValidationRecord) {
        let s = &r.scores;
        let line = format!(
            "validation @ step {}: EPE {:.3} px, bad-1 {:.1} %, bad-3 {:.1} % ({} pairs, {:.1} s)",
            r.step,
            s.epe,
            100.0 * s.bad_1px,
            100.0 * s.bad_3px,
            s.pairs,
            r.seconds
        );
        match &self.bar {
            Some(b) => b.println(line),
            None => eprintln!("{line}"),
        }
    }

    fn checkpointed(&mut self, dir: &Path) {
        if let Some(b) = &self.bar {
            b.println(format!("checkpoint {}", dir.display()));
        }
    }
}

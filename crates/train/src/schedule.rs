//! The one-cycle learning-rate schedule, exactly as PyTorch's `OneCycleLR` with
//! `anneal_strategy='linear'`, `three_phase=False`, `cycle_momentum=False` (what upstream
//! MonSter++ and the SeasonStereo release use).
//!
//! PyTorch's definition, which this reproduces value for value (in f64, as Python floats):
//! with `T` total steps, `initial = max_lr / div_factor`, `min = initial / final_div_factor`,
//! phase 1 ends at `pct_start·T − 1` (from `initial` to `max_lr`), phase 2 ends at `T − 1`
//! (from `max_lr` to `min`); the learning rate of step `s` (0-based, the step whose optimiser
//! update uses it) is the linear interpolation inside the phase that contains `s`.
//! Upstream builds the scheduler with `total_steps = max_step + 100`, so the schedule never
//! reaches its minimum during training; [`OneCycleConfig::extra_steps`] keeps that.

use serde::{Deserialize, Serialize};

/// Parameters of the one-cycle schedule (PyTorch defaults except `pct_start`, which upstream
/// sets to 0.01).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OneCycleConfig {
    /// Fraction of the total steps spent warming up (upstream 0.01).
    pub pct_start: f64,
    /// `initial_lr = max_lr / div_factor` (PyTorch default 25).
    pub div_factor: f64,
    /// `min_lr = initial_lr / final_div_factor` (PyTorch default 1e4).
    pub final_div_factor: f64,
    /// Steps added to the training length to get the schedule length (upstream: 100).
    pub extra_steps: usize,
}

impl Default for OneCycleConfig {
    fn default() -> Self {
        Self {
            pct_start: 0.01,
            div_factor: 25.0,
            final_div_factor: 1e4,
            extra_steps: 100,
        }
    }
}

/// A one-cycle schedule of a known length. Pure: the learning rate is a function of the step,
/// so resuming needs only the step number.
#[derive(Debug, Clone, PartialEq)]
pub struct OneCycle {
    max_lr: f64,
    total_steps: usize,
    config: OneCycleConfig,
}

/// A schedule that cannot be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("invalid one-cycle schedule: {0}")]
pub struct ScheduleError(pub String);

impl OneCycle {
    /// The schedule for a run of `train_steps` optimiser steps peaking at `max_lr`
    /// (`total_steps = train_steps + config.extra_steps`).
    pub fn new(
        max_lr: f64,
        train_steps: usize,
        config: &OneCycleConfig,
    ) -> Result<Self, ScheduleError> {
        let total_steps = train_steps + config.extra_steps;
        if total_steps == 0 {
            return Err(ScheduleError(
                "the schedule has 0 steps (steps + extra_steps must be positive)".into(),
            ));
        }
        if !(max_lr.is_finite() && max_lr > 0.0) {
            return Err(ScheduleError(format!("max_lr ({max_lr}) must be positive")));
        }
        if !(config.pct_start > 0.0 && config.pct_start < 1.0) {
            return Err(ScheduleError(format!(
                "pct_start ({}) must lie in (0, 1)",
                config.pct_start
            )));
        }
        if !(config.div_factor > 0.0 && config.final_div_factor > 0.0) {
            return Err(ScheduleError(format!(
                "div_factor ({}) and final_div_factor ({}) must be positive",
                config.div_factor, config.final_div_factor
            )));
        }
        Ok(Self {
            max_lr,
            total_steps,
            config: config.clone(),
        })
    }

    /// Length of the schedule (PyTorch `total_steps`).
    pub fn total_steps(&self) -> usize {
        self.total_steps
    }

    /// The learning rate at the start (`max_lr / div_factor`).
    pub fn initial_lr(&self) -> f64 {
        self.max_lr / self.config.div_factor
    }

    /// The learning rate at the end (`initial_lr / final_div_factor`).
    pub fn min_lr(&self) -> f64 {
        self.initial_lr() / self.config.final_div_factor
    }

    /// The peak learning rate.
    pub fn max_lr(&self) -> f64 {
        self.max_lr
    }

    /// Learning rate of 0-based step `step`. Past the end PyTorch raises an error; this holds
    /// the final value instead.
    pub fn lr(&self, step: usize) -> f64 {
        let t = self.total_steps as f64;
        let phases = [
            (
                self.config.pct_start * t - 1.0,
                self.initial_lr(),
                self.max_lr,
            ),
            (t - 1.0, self.max_lr, self.min_lr()),
        ];
        let s = step.min(self.total_steps - 1) as f64;
        let mut start_step = 0.0;
        for (i, &(end_step, start_lr, end_lr)) in phases.iter().enumerate() {
            if s <= end_step || i == phases.len() - 1 {
                let span = end_step - start_step;
                // PyTorch divides by zero here (a 1-step phase); the phase's end value is the
                // only meaningful answer.
                let pct = if span == 0.0 {
                    1.0
                } else {
                    (s - start_step) / span
                };
                return (end_lr - start_lr) * pct + start_lr;
            }
            start_step = end_step;
        }
        unreachable!("the last phase always matches")
    }
}

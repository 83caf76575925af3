//! Training throughput: optimiser steps per second and peak memory of one training step
//! (forward in train mode, SeasonStereo loss, backward, clipping, AdamW) on a synthetic batch.
//!
//! `cargo bench -p train --bench train_step -- [tiny|vits] [steps] [height] [width] [batch] [iters]`
//! Defaults: tiny, 5 steps, 64×128, batch 2, 8 iterations. A one-shot timer rather than
//! criterion: a vits step takes tens of seconds on a CPU. Peak memory is the process's VmHWM
//! (Linux), so run one configuration per process.

use std::time::Instant;

use burn::tensor::Device;
use train::bench::{step_config, train_step};

fn main() {
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with("--"))
        .collect();
    let preset = args.first().map(String::as_str).unwrap_or("tiny");
    let num = |i: usize, d: usize| args.get(i).and_then(|s| s.parse().ok()).unwrap_or(d);
    let (steps, h, w, batch, iters) = (num(1, 5), num(2, 64), num(3, 128), num(4, 2), num(5, 8));
    let config = step_config(preset, h, w, batch, iters, None).expect("bench configuration");
    let max_disp = config.model.max_disp.unwrap_or_default();
    let mut step = train_step(&config, &Device::flex()).expect("model");
    // One warm-up step (lazy initialisation, allocator).
    let t0 = Instant::now();
    step().expect("step");
    let warm = t0.elapsed().as_secs_f64();
    let t = Instant::now();
    for _ in 1..=steps {
        step().expect("step");
    }
    let secs = t.elapsed().as_secs_f64();
    let peak = train::metrics::peak_rss_bytes()
        .map_or("n/a".into(), |b| format!("{:.0} MiB", b as f64 / 1048576.0));
    println!(
        "train_step {preset} {h}x{w} batch {batch} iters {iters} max_disp {max_disp}: {:.3} it/s ({:.2} s/step over {steps} steps; warm-up {:.2} s), peak RSS {peak}",
        steps as f64 / secs,
        secs / steps as f64,
        warm
    );
}

//! Training throughput: optimiser steps per second and peak memory of one training step
//! (forward in train mode, SeasonStereo loss, backward, clipping, AdamW) on a synthetic batch.
//!
//! `cargo bench -p train --bench train_step -- [tiny|vits] [steps] [height] [width] [batch] [iters]`
//! Defaults: tiny, 5 steps, 64×128, batch 2, 8 iterations. A one-shot timer rather than
//! criterion: a vits step takes tens of seconds on a CPU. Peak memory is the process's VmHWM
//! (Linux), so run one configuration per process.

use std::time::Instant;

use burn::tensor::Device;
use raster::{Image, Mask};
use train::data::PreparedSample;
use train::setup::build_model;
use train::trainer::Session;
use train::TrainConfig;

/// A textured pair with a constant 4-px shift, its disparity and full masks.
fn synthetic(w: usize, h: usize) -> PreparedSample {
    let tex = |x: f32, y: f32| {
        0.5 + 0.25 * (0.31 * x).sin() * (0.17 * y).cos() + 0.2 * (0.05 * x * y).sin()
    };
    let left = Image::from_fn(w, h, |x, y| tex(x as f32, y as f32));
    let right = Image::from_fn(w, h, |x, y| tex(x as f32 + 4.0, y as f32));
    let rgb = |g: &Image| {
        let data: Vec<f32> = g.data().iter().flat_map(|&v| [v, v, v]).collect();
        Image::new(w, h, 3, data).unwrap()
    };
    PreparedSample {
        input_left: rgb(&left),
        input_right: rgb(&right),
        real_left: rgb(&left),
        real_right: rgb(&right),
        target: Image::filled(w, h, 1, 4.0),
        valid_left: Mask::filled(w, h, true),
        building_left: Mask::filled(w, h, true),
        stem: "synthetic".into(),
        diachronic: false,
    }
}

fn main() {
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with("--"))
        .collect();
    let preset = args.first().map(String::as_str).unwrap_or("tiny");
    let num = |i: usize, d: usize| args.get(i).and_then(|s| s.parse().ok()).unwrap_or(d);
    let (steps, h, w, batch, iters) = (num(1, 5), num(2, 64), num(3, 128), num(4, 2), num(5, 8));
    let max_disp = if preset == "tiny" { 64 } else { 192 };
    let config = TrainConfig::load(
        "tiny",
        &[
            format!("model.preset={preset:?}"),
            format!("model.max_disp={max_disp}"),
            format!("run.batch_size={batch}"),
            format!("run.train_iters={iters}"),
            format!("augment.crop_height={h}"),
            format!("augment.crop_width={w}"),
            format!("run.steps={}", steps + 1),
            "loss.ignore_border=4".into(),
        ],
    )
    .expect("bench configuration");
    let device = Device::flex().autodiff();
    let (mut model, _) = build_model(&config, &device, None).expect("model");
    let mut session = Session::new(&config, &device).expect("session");
    let samples: Vec<PreparedSample> = (0..batch).map(|_| synthetic(w, h)).collect();
    // One warm-up step (lazy initialisation, allocator).
    let t0 = Instant::now();
    model = session
        .step(model, &samples, session.lr(0))
        .expect("step")
        .0;
    let warm = t0.elapsed().as_secs_f64();
    let t = Instant::now();
    let mut last = 0.0;
    for s in 1..=steps {
        let (m, terms, _) = session.step(model, &samples, session.lr(s)).expect("step");
        model = m;
        last = terms.total;
    }
    let secs = t.elapsed().as_secs_f64();
    let peak = train::metrics::peak_rss_bytes()
        .map_or("n/a".into(), |b| format!("{:.0} MiB", b as f64 / 1048576.0));
    println!(
        "train_step {preset} {h}x{w} batch {batch} iters {iters} max_disp {max_disp}: {:.3} it/s ({:.2} s/step over {steps} steps; warm-up {:.2} s), peak RSS {peak}, last loss {last:.4}",
        steps as f64 / secs,
        secs / steps as f64,
        warm
    );
}

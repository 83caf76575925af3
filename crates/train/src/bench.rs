//! The training-step workload of `seasonstereo bench train-step` (and of
//! `cargo bench -p train --bench train_step`): forward in train mode, the full SeasonStereo loss
//! over every prediction, backward, clipping and AdamW, on a synthetic textured pair.

use burn::tensor::Device;
use raster::{Image, Mask};

use crate::data::PreparedSample;
use crate::setup::build_model;
use crate::trainer::Session;
use crate::TrainConfig;

/// A textured `w × h` pair with a constant 4-px shift, its disparity and full masks.
pub fn synthetic_sample(w: usize, h: usize) -> PreparedSample {
    let tex = |x: f32, y: f32| {
        0.5 + 0.25 * (0.31 * x).sin() * (0.17 * y).cos() + 0.2 * (0.05 * x * y).sin()
    };
    let left = Image::from_fn(w, h, |x, y| tex(x as f32, y as f32));
    let right = Image::from_fn(w, h, |x, y| tex(x as f32 + 4.0, y as f32));
    let rgb = |g: &Image| g.to_rgb();
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

/// The configuration of a training step: `preset` on `h × w` crops, `batch` samples, `iters`
/// refinement iterations, `max_disp` (default 64 for tiny, 192 otherwise).
pub fn step_config(
    preset: &str,
    h: usize,
    w: usize,
    batch: usize,
    iters: usize,
    max_disp: Option<usize>,
) -> Result<TrainConfig, String> {
    let max_disp = max_disp.unwrap_or(if preset == "tiny" { 64 } else { 192 });
    TrainConfig::load(
        "tiny",
        &[
            format!("model.preset={preset:?}"),
            format!("model.max_disp={max_disp}"),
            format!("run.batch_size={batch}"),
            format!("run.train_iters={iters}"),
            format!("augment.crop_height={h}"),
            format!("augment.crop_width={w}"),
            "run.steps=1000000".into(),
            "loss.ignore_border=4".into(),
        ],
    )
    .map_err(|e| e.to_string())
}

/// One optimiser step per call, on `device` (made autodiff here).
pub fn train_step(
    config: &TrainConfig,
    device: &Device,
) -> Result<Box<dyn FnMut() -> Result<(), String>>, String> {
    let device = device.clone().autodiff();
    let (model, _) = build_model(config, &device, None).map_err(|e| e.to_string())?;
    let mut session = Session::new(config, &device).map_err(|e| e.to_string())?;
    let (h, w) = (config.augment.crop_height, config.augment.crop_width);
    let samples: Vec<PreparedSample> = (0..config.run.batch_size)
        .map(|_| synthetic_sample(w, h))
        .collect();
    let mut model = Some(model);
    let mut step = 0;
    Ok(Box::new(move || {
        let m = model.take().ok_or("a previous step failed")?;
        let (m, _, _) = session
            .step(m, &samples, session.lr(step))
            .map_err(|e| e.to_string())?;
        model = Some(m);
        step += 1;
        Ok(())
    }))
}

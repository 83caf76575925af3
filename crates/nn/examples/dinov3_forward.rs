//! CPU time of one DINOv3 forward pass (flex backend, random weights: timing only).
//!
//! ```sh
//! cargo run --release -p nn --example dinov3_forward -- [vits16|vitb16|vitl16|tiny] [size] [batch] [runs]
//! ```
//!
//! Defaults: ViT-S/16 at 224×224, batch 2 (the score's [left, left_hat] batch), 3 timed runs after
//! one warm-up.

use std::time::Instant;

use burn::tensor::{Device, Distribution, Tensor};
use nn::dinov3::{Dinov3Config, Dinov3Vit};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let preset = args.first().map_or("vits16", String::as_str);
    let arg = |i: usize, default: usize| {
        args.get(i)
            .map(|s| s.parse().expect("sizes and counts are integers"))
            .unwrap_or(default)
    };
    let (size, batch, runs) = (arg(1, 224), arg(2, 2), arg(3, 3));
    let config = Dinov3Config::preset(preset)
        .unwrap_or_else(|| panic!("unknown preset {preset} (vits16, vitb16, vitl16, tiny)"));
    config.validate().expect("valid preset");
    let device = Device::flex();
    let model = Dinov3Vit::new(&config, &device);
    let x = Tensor::<4>::random(
        [batch, 3, size, size],
        Distribution::Normal(0.0, 1.0),
        &device,
    );
    let run = || {
        let out = Dinov3Vit::pooler(model.forward(x.clone()));
        // Reading the values forces the computation.
        out.into_data().try_into_vec_as::<f32>().expect("f32").len()
    };
    run();
    let mut times = Vec::with_capacity(runs);
    for _ in 0..runs {
        let t = Instant::now();
        run();
        times.push(t.elapsed().as_secs_f64());
    }
    times.sort_by(f64::total_cmp);
    println!(
        "DINOv3 {preset} forward, batch {batch} at {size}x{size}, {} cores: median {:.3} s, min {:.3} s over {runs} runs",
        std::thread::available_parallelism().map_or(1, |n| n.get()),
        times[times.len() / 2],
        times[0]
    );
}

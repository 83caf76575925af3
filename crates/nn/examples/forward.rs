//! One MonSter++ forward pass with random weights on the CPU, for peak-memory measurements:
//!
//! ```sh
//! cargo build --release -p nn --example forward
//! /usr/bin/time -v target/release/examples/forward vits 256 512 32   # "Maximum resident set size"
//! ```
//!
//! Arguments: PRESET (tiny, vits, vitb, vitl) HEIGHT WIDTH ITERS [MAX_DISP]. Prints the time of
//! the pass and the estimate of `nn::infer::estimate_memory_bytes` for comparison.

use std::time::Instant;

use burn::tensor::{Device, Distribution, Tensor};
use nn::config::MonsterConfig;
use nn::infer::estimate_memory_bytes;
use nn::monster::Monster;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let arg = |i: usize, default: &str| args.get(i).cloned().unwrap_or_else(|| default.to_string());
    let mut config = MonsterConfig::preset(&arg(0, "tiny")).expect("preset");
    let h: usize = arg(1, "64").parse().expect("HEIGHT");
    let w: usize = arg(2, "128").parse().expect("WIDTH");
    let iters: usize = arg(3, "8").parse().expect("ITERS");
    if let Some(d) = args.get(4) {
        config.max_disp = d.parse().expect("MAX_DISP");
    }
    config.validate().expect("configuration");
    let device = Device::flex();
    let model = Monster::new(&config, &device);
    let l = Tensor::<4>::random([1, 3, h, w], Distribution::Uniform(0.0, 255.0), &device);
    let r = Tensor::<4>::random([1, 3, h, w], Distribution::Uniform(0.0, 255.0), &device);
    let t = Instant::now();
    let out = model.forward(l, r, iters, true);
    let d: Vec<f32> = out.disp.into_data().try_into_vec_as::<f32>().expect("f32");
    let secs = t.elapsed().as_secs_f64();
    let est = estimate_memory_bytes(&config, h, w, 4 * model.num_params() as u64);
    println!(
        "{} {h}x{w} iters {iters} max_disp {}: {secs:.2} s, {} params, estimate {:.0} MiB, mean disparity {:.3}",
        arg(0, "tiny"),
        config.max_disp,
        model.num_params(),
        est as f64 / (1u64 << 20) as f64,
        d.iter().sum::<f32>() / d.len() as f32
    );
}

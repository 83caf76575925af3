//! One census + SGM match of a 1024² synthetic pair over 128 disparities, for measuring time and
//! peak memory: `cargo run --release -p matching --example sgm_1024` under `/usr/bin/time -v`.

#[path = "../tests/synthetic/mod.rs"]
mod synthetic;

use matching::{match_pair, memory_bytes, SgmParams};
use std::time::Instant;

fn main() {
    let size: usize = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(1024);
    let n_disp: i32 = std::env::args()
        .nth(2)
        .and_then(|s| s.parse().ok())
        .unwrap_or(128);
    let pair = synthetic::standard_pair(size, size);
    let params = SgmParams::default();
    let t = Instant::now();
    let disp = match_pair(&pair.left, &pair.right, (-8, n_disp - 9), &params).unwrap();
    let secs = t.elapsed().as_secs_f64();
    let s = synthetic::stats(disp.data(), &pair.disp, |i| !pair.occluded[i]);
    println!(
        "{size}x{size} x {n_disp}: {secs:.3} s, memory_bytes {:.1} MiB, coverage {:.3}, mae {:.3}, bad1 {:.4}",
        memory_bytes(size, size, n_disp as usize) as f64 / (1 << 20) as f64,
        s.coverage,
        s.mae,
        s.bad1
    );
}

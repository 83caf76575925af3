//! Census + SGM throughput on textured synthetic pairs: 512² and 1024², 64 and 128 disparities.
//! The acceptance target is 1024² × 128 disparities in under 3 s on 2 cores.

#[path = "../tests/synthetic/mod.rs"]
mod synthetic;

use criterion::{criterion_group, criterion_main, Criterion};
use matching::{match_pair, memory_bytes, SgmParams};
use std::time::Duration;

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("sgm");
    group.sample_size(10);
    group.warm_up_time(Duration::from_millis(500));
    group.measurement_time(Duration::from_secs(10));
    for size in [512usize, 1024] {
        let pair = synthetic::standard_pair(size, size);
        for n_disp in [64i32, 128] {
            let params = SgmParams::with_range(-8, n_disp - 9);
            println!(
                "sgm {size}x{size} x {n_disp} disparities: {:.1} MiB ({} bytes)",
                memory_bytes(size, size, n_disp as usize) as f64 / (1 << 20) as f64,
                memory_bytes(size, size, n_disp as usize)
            );
            group.bench_function(format!("{size}x{size}x{n_disp}"), |b| {
                b.iter(|| match_pair(&pair.left, &pair.right, &params).unwrap())
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);

//! Census + SGM and census + MGM throughput on textured synthetic pairs: 512² and 1024², 64 and
//! 128 disparities, the default filters (left-right check, uniqueness, median, speckle). The
//! acceptance target is SGM at 1024² × 128 disparities in under 1 s on 2 cores.

#[path = "../tests/synthetic/mod.rs"]
mod synthetic;

use criterion::{criterion_group, criterion_main, Criterion};
use matching::{match_pair, memory_bytes, Aggregation, SgmParams};
use std::time::Duration;

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("matching");
    group.sample_size(10);
    group.warm_up_time(Duration::from_millis(500));
    group.measurement_time(Duration::from_secs(10));
    for size in [512usize, 1024] {
        let pair = synthetic::standard_pair(size, size);
        for n_disp in [64i32, 128] {
            println!(
                "{size}x{size} x {n_disp} disparities: {:.1} MiB ({} bytes)",
                memory_bytes(size, size, n_disp as usize) as f64 / (1 << 20) as f64,
                memory_bytes(size, size, n_disp as usize)
            );
            for (name, aggregation) in [("sgm", Aggregation::Sgm), ("mgm", Aggregation::Mgm)] {
                let params = SgmParams {
                    aggregation,
                    ..SgmParams::default()
                };
                group.bench_function(format!("{name}/{size}x{size}x{n_disp}"), |b| {
                    b.iter(|| {
                        match_pair(&pair.left, &pair.right, (-8, n_disp - 9), &params).unwrap()
                    })
                });
            }
        }
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);

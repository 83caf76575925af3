//! Forward time of MonSter++ on the CPU (flex backend), random weights (timing only):
//! the tiny parity configuration at 64×128 with 8 iterations, and ViT-S at 256×512 with 12 and
//! 32 iterations.
//!
//! ```sh
//! cargo bench -p nn --bench monster
//! ```
//!
//! Peak memory: `crates/nn/examples/forward.rs` (see its documentation).

use std::time::Duration;

use burn::tensor::{Device, Distribution, Tensor};
use criterion::{criterion_group, criterion_main, Criterion};
use nn::config::MonsterConfig;
use nn::monster::Monster;

fn inputs(h: usize, w: usize, device: &Device) -> (Tensor<4>, Tensor<4>) {
    let l = Tensor::<4>::random([1, 3, h, w], Distribution::Uniform(0.0, 255.0), device);
    // The right view: the left one shifted by 4 px, as in the fixture.
    let r = l
        .clone()
        .slice([0..1, 0..3, 0..h, 4..w])
        .pad((0, 4, 0, 0), burn::tensor::ops::PadMode::Edge);
    (l, r)
}

fn bench_case(
    c: &mut Criterion,
    name: &str,
    config: MonsterConfig,
    h: usize,
    w: usize,
    iters: usize,
) {
    let device = Device::flex();
    let model = Monster::new(&config, &device);
    let (l, r) = inputs(h, w, &device);
    // Warm-up outside the measurement (lazy parameters, allocator).
    let _ = model
        .forward(l.clone(), r.clone(), iters, true)
        .disp
        .into_data();
    c.bench_function(name, |b| {
        b.iter(|| {
            model
                .forward(l.clone(), r.clone(), iters, true)
                .disp
                .into_data()
        })
    });
}

fn monster(c: &mut Criterion) {
    bench_case(
        c,
        "monster tiny 64x128 8 iters",
        MonsterConfig::tiny(),
        64,
        128,
        8,
    );
    bench_case(
        c,
        "monster vits 256x512 12 iters",
        MonsterConfig::vits(),
        256,
        512,
        12,
    );
    bench_case(
        c,
        "monster vits 256x512 32 iters",
        MonsterConfig::vits(),
        256,
        512,
        32,
    );
}

criterion_group! {
    name = benches;
    config = Criterion::default()
        .sample_size(10)
        .warm_up_time(Duration::from_millis(1))
        .measurement_time(Duration::from_secs(5));
    targets = monster
}
criterion_main!(benches);

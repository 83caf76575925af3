//! Time of the built-in seasonal model and of the fidelity check on a 1024² image (the paper's
//! crop size), on the procedural world.

use criterion::{criterion_group, criterion_main, Criterion};
use synth::fidelity::{check, FidelityParams};
use synth::{BuiltinSeasons, Season, SeasonGenerator, SourceImage};

fn bench(c: &mut Criterion) {
    let world = world::generate(
        &world::WorldParams::new(1024, 1),
        &world::Neutral,
        &|_, _| {},
    )
    .expect("world");
    let model = BuiltinSeasons::new(1);
    let mut group = c.benchmark_group("synth_1024");
    group.sample_size(10);
    for (name, classes) in [
        ("with_classes", Some(&world.left.classes)),
        ("colour_only", None),
    ] {
        let source = SourceImage {
            id: "bench",
            image: &world.left.image,
            classes,
        };
        group.bench_function(format!("builtin_winter_{name}"), |b| {
            b.iter(|| model.generate(&source, Season::Winter).unwrap())
        });
    }
    let source = SourceImage::new("bench", &world.left.image);
    let variant = model.generate(&source, Season::Autumn).unwrap();
    group.bench_function("fidelity_check", |b| {
        b.iter(|| check(&world.left.image, &variant, &FidelityParams::default()).unwrap())
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);

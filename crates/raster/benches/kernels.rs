//! Throughput of the resampling and SSIM kernels on 1024² rasters (the size of a rectified
//! training crop pair). `cargo bench -p raster --bench kernels`.

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use raster::geometry::{warp_by_disparity, warp_homography};
use raster::ssim::{ssim_box3, ssim_gaussian};
use raster::{Homography, Image};

const N: usize = 1024;

/// A smooth, non-constant RGB test pattern in [0, 1].
fn rgb(seed: f32) -> Image {
    let mut data = Vec::with_capacity(N * N * 3);
    for y in 0..N {
        for x in 0..N {
            let (xf, yf) = (x as f32, y as f32);
            data.push(0.5 + 0.5 * (0.05 * xf + seed).sin());
            data.push(0.5 + 0.5 * (0.03 * yf - seed).cos());
            data.push(0.5 + 0.5 * (0.02 * (xf + yf) + seed).sin());
        }
    }
    Image::new(N, N, 3, data).unwrap()
}

fn kernels(c: &mut Criterion) {
    let a = rgb(0.0);
    let b = rgb(0.7);
    let (ga, gb) = (a.to_gray(), b.to_gray());
    let h = Homography([[1.01, 0.02, -3.5], [-0.015, 0.99, 2.25], [1e-6, -2e-6, 1.0]]);
    let disp = Image::from_fn(N, N, |x, y| 8.0 + 4.0 * ((x + y) as f32 * 0.01).sin());

    let mut g = c.benchmark_group("kernels_1024");
    g.sample_size(10);
    g.bench_function("warp_homography_rgb", |bch| {
        bch.iter(|| warp_homography(black_box(&a), black_box(&h), N, N).unwrap())
    });
    g.bench_function("warp_by_disparity_rgb", |bch| {
        bch.iter(|| warp_by_disparity(black_box(&b), black_box(&disp)).unwrap())
    });
    g.bench_function("ssim_gaussian_gray", |bch| {
        bch.iter(|| ssim_gaussian(black_box(&ga), black_box(&gb), 1.0).unwrap())
    });
    g.bench_function("ssim_box3_rgb", |bch| {
        bch.iter(|| ssim_box3(black_box(&a), black_box(&b)).unwrap())
    });
    g.finish();
}

criterion_group!(benches, kernels);
criterion_main!(benches);

//! Triangulation + DSM rasterisation of a 1024² disparity with real (degree-3 Pléiades) RPCs:
//! the s2p anchor pair's cameras and rectifying homographies, a smooth synthetic disparity around
//! the anchor tile's mean, every pixel valid. Target: under 1 s on 2 cores.

use std::path::PathBuf;

use camera::{rasterize_max, triangulate_disparity, DsmGrid, RpcModel, UtmZone};
use criterion::{criterion_group, criterion_main, Criterion};
use raster::formats::read_tiff;
use raster::{Homography, Image, Mask};

fn matrix(path: PathBuf) -> Homography {
    let v: Vec<f64> = std::fs::read_to_string(path)
        .unwrap()
        .split_whitespace()
        .map(|t| t.parse().unwrap())
        .collect();
    Homography([[v[0], v[1], v[2]], [v[3], v[4], v[5]], [v[6], v[7], v[8]]])
}

fn bench(c: &mut Criterion) {
    let data = testdata::require!("anchors/data/s2p").join("tests/data");
    let dir = data.join("input_triangulation");
    let rpc_l = RpcModel::read_geotiff_rpc(data.join("input_pair/img_01.tif")).unwrap();
    let rpc_r = RpcModel::read_geotiff_rpc(data.join("input_pair/img_02.tif")).unwrap();
    let a = matrix(dir.join("global_pointing_pair_1.txt"));
    let h_l = matrix(dir.join("pair_1/H_ref.txt"));
    let h_r = matrix(dir.join("pair_1/H_sec.txt")).compose(&a.inverse().unwrap());
    // s2p's disparity is x_sec − x_ref; ours is x_ref − x_sec.
    let s2p = read_tiff(dir.join("pair_1/rectified_disp.tif"))
        .unwrap()
        .image;
    let finite: Vec<f64> = s2p
        .data()
        .iter()
        .filter(|v| v.is_finite())
        .map(|&v| -v as f64)
        .collect();
    let d0 = finite.iter().sum::<f64>() / finite.len() as f64;

    let n = 1024;
    let disparity = Image::from_fn(n, n, |x, y| {
        (d0 + 3.0 * (x as f64 / 50.0).sin() * (y as f64 / 70.0).cos()) as f32
    });
    let mask = Mask::filled(n, n, true);

    // The DSM grid: the points' UTM bounding box at 0.5 m.
    let points = triangulate_disparity(&disparity, &h_l, &h_r, &rpc_l, &rpc_r, &mask).unwrap();
    let zone = UtmZone::from_epsg(32740).unwrap();
    let (mut x_min, mut y_min, mut x_max, mut y_max) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
    for p in points.lonlatalt.iter().filter(|p| p[2].is_finite()) {
        let (e, nn) = zone.forward(p[0], p[1]);
        (x_min, x_max, y_min, y_max) = (x_min.min(e), x_max.max(e), y_min.min(nn), y_max.max(nn));
    }
    let grid = DsmGrid::from_bounds(x_min, y_min, x_max + 0.5, y_max + 0.5, 0.5, 32740).unwrap();
    eprintln!(
        "{} of {} pixels triangulated; DSM grid {}x{}",
        points.valid_count(),
        n * n,
        grid.width,
        grid.height
    );

    let mut group = c.benchmark_group("camera");
    group.sample_size(10);
    group.bench_function("triangulate+rasterize 1024²", |b| {
        b.iter(|| {
            let points =
                triangulate_disparity(&disparity, &h_l, &h_r, &rpc_l, &rpc_r, &mask).unwrap();
            rasterize_max(&points, &grid)
        })
    });
    group.bench_function("rasterize 1024²", |b| {
        b.iter(|| rasterize_max(&points, &grid))
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);

//! Triangulation and DSM against s2p's anchor, the procedural world's exact truth, and the plain
//! (unaccelerated) scheme.

mod support;

use camera::{altitude, evaluation_mask, rasterize_max, triangulate_disparity, DsmGrid, RpcModel};
use raster::formats::{read_png, read_tiff};
use raster::{Homography, Image, Mask};
use support::{s2p, S2P, S2P_IMG1, S2P_IMG2};

fn read_matrix(rel: &str) -> Homography {
    let text = std::fs::read_to_string(s2p(rel)).unwrap();
    let v: Vec<f64> = text
        .split_whitespace()
        .map(|t| t.parse().unwrap())
        .collect();
    assert_eq!(v.len(), 9, "{rel}");
    Homography([[v[0], v[1], v[2]], [v[3], v[4], v[5]], [v[6], v[7], v[8]]])
}

const PAIR: &str = "tests/data/input_triangulation/pair_1/";

/// s2p's tile in our convention: disparity negated (s2p: x_sec = x_ref + d; ours x_R = x_L − d),
/// secondary homography H_sec·A⁻¹ with the pointing correction A.
struct S2pTile {
    disparity: Image,
    mask: Mask,
    h_ref: Homography,
    h_sec: Homography,
    rpc_ref: RpcModel,
    rpc_sec: RpcModel,
}

fn s2p_tile() -> S2pTile {
    let disp = read_tiff(s2p(&format!("{PAIR}rectified_disp.tif")))
        .unwrap()
        .image;
    let m = read_png(s2p(&format!("{PAIR}rectified_mask.png"))).unwrap();
    assert_eq!(disp.size(), m.size());
    let mask = Mask::from_fn(m.width(), m.height(), |x, y| m.get(x, y, 0) > 0.0);
    let data = disp.data().iter().map(|d| -d).collect();
    let disparity = Image::new(disp.width(), disp.height(), 1, data).unwrap();
    let a = read_matrix("tests/data/input_triangulation/global_pointing_pair_1.txt");
    S2pTile {
        disparity,
        mask,
        h_ref: read_matrix(&format!("{PAIR}H_ref.txt")),
        h_sec: read_matrix(&format!("{PAIR}H_sec.txt")).compose(&a.inverse().unwrap()),
        rpc_ref: RpcModel::read_geotiff_rpc(s2p(S2P_IMG1)).unwrap(),
        rpc_sec: RpcModel::read_geotiff_rpc(s2p(S2P_IMG2)).unwrap(),
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

#[test]
fn s2p_tile_dsm_matches_s2p() {
    testdata::require!(S2P);
    let t = s2p_tile();
    let points = triangulate_disparity(
        &t.disparity,
        &t.h_ref,
        &t.h_sec,
        &t.rpc_ref,
        &t.rpc_sec,
        &t.mask,
    )
    .unwrap();
    let valid = points.valid_count();
    assert!(valid > 50_000, "only {valid} points");

    let gt_path = s2p("tests/data/expected_output/pair/dsm.tif");
    let gt = read_tiff(&gt_path).unwrap();
    let grid = DsmGrid::of_raster(&gt, "dsm.tif").unwrap();
    assert_eq!((grid.epsg, grid.resolution), (32740, 0.5));
    let dsm = rasterize_max(&points, &grid);

    let diffs: Vec<f64> = dsm
        .data()
        .iter()
        .zip(gt.image.data())
        .filter(|(a, b)| a.is_finite() && b.is_finite())
        .map(|(a, b)| (*a - *b) as f64)
        .collect();
    assert!(diffs.len() > 20_000, "only {} shared cells", diffs.len());
    let mean = diffs.iter().sum::<f64>() / diffs.len() as f64;
    let med = median(diffs.iter().map(|d| (d - mean).abs()).collect());
    println!(
        "s2p anchor: {valid} points, {} shared cells, mean offset {mean:.3} m, \
         median |Δh| after offset {med:.3} m",
        diffs.len()
    );
    assert!(mean.abs() < 2.0, "mean offset {mean}");
    assert!(med < 0.5, "median |Δh| {med}");
}

/// The plain scheme with every localisation polished to machine precision (Newton from rpcm's
/// answer): what both the plain and the fast scheme approximate.
fn exact_altitude(left: &RpcModel, right: &RpcModel, xl: (f64, f64), xr: (f64, f64)) -> f64 {
    let loc = |h: f64| {
        let (lon, lat) = left.localization(xl.0, xl.1, h).unwrap();
        let mut g = (lon, lat);
        for _ in 0..3 {
            g = left.localization_from(xl.0, xl.1, h, g.0, g.1).unwrap();
        }
        g
    };
    let mut h = 0.0;
    for _ in 0..100 {
        let (g0, g1) = (loc(h), loc(h + 1.0));
        let p0 = right.projection(g0.0, g0.1, h);
        let p1 = right.projection(g1.0, g1.1, h + 1.0);
        let (ax, ay) = (p1.0 - p0.0, p1.1 - p0.1);
        let inc = (ax * (xr.0 - p0.0) + ay * (xr.1 - p0.1)) / (ax * ax + ay * ay);
        h += inc;
        if inc.abs() < 1e-7 {
            break;
        }
    }
    h
}

#[test]
fn fast_triangulation_equals_the_plain_scheme() {
    testdata::require!(S2P);
    let t = s2p_tile();
    let inv_ref = t.h_ref.inverse().unwrap();
    let inv_sec = t.h_sec.inverse().unwrap();
    // Rows of pixels: the fast path warm-starts along rows, so test contiguous runs.
    let (w, h) = t.disparity.size();
    let mask = Mask::from_fn(w, h, |x, y| {
        t.mask.get(x, y) && y % 37 == 5 && (100..260).contains(&x)
    });
    let points = triangulate_disparity(
        &t.disparity,
        &t.h_ref,
        &t.h_sec,
        &t.rpc_ref,
        &t.rpc_sec,
        &mask,
    )
    .unwrap();
    let (mut n, mut worst, mut worst_deg): (usize, f64, f64) = (0, 0.0, 0.0);
    let (mut worst_exact, mut plain_vs_exact): (f64, f64) = (0.0, 0.0);
    for y in 0..h {
        for x in 0..w {
            if !mask.get(x, y) || !t.disparity.get(x, y, 0).is_finite() {
                continue;
            }
            let d = t.disparity.get(x, y, 0) as f64;
            let xl = inv_ref.apply(x as f64, y as f64);
            let xr = inv_sec.apply(x as f64 - d, y as f64);
            let plain = altitude(&t.rpc_ref, &t.rpc_sec, xl, xr).unwrap();
            let exact = exact_altitude(&t.rpc_ref, &t.rpc_sec, xl, xr);
            worst_exact = worst_exact.max((points.get(x, y)[2] - exact).abs());
            plain_vs_exact = plain_vs_exact.max((plain - exact).abs());
            let (lon, lat) = t.rpc_ref.localization(xl.0, xl.1, plain).unwrap();
            let p = points.get(x, y);
            worst = worst.max((p[2] - plain).abs());
            worst_deg = worst_deg.max((p[0] - lon).abs()).max((p[1] - lat).abs());
            n += 1;
        }
    }
    println!(
        "fast vs plain on {n} pixels: max |Δh| {worst:.3e} m, max |Δlon/lat| {worst_deg:.3e}°; \
         fast vs fully converged {worst_exact:.3e} m, plain vs fully converged {plain_vs_exact:.3e} m"
    );
    assert!(n > 1000, "{n}");
    assert!(worst < 1e-6, "{worst}");
    assert!(worst_deg < 1e-9, "{worst_deg}");
}

#[test]
fn world_altitudes_are_exact() {
    let world = world::generate(
        &world::WorldParams::new(128, 1),
        &world::Neutral,
        &|_, _| {},
    )
    .unwrap();
    let (w, h) = world.disparity.size();
    // The cameras exactly as the world writer stores them.
    let rpc = |cam: &world::camera::AffineCamera, id: &str| {
        let text = serde_json::to_string_pretty(&world.camera_json(cam, id)).unwrap();
        RpcModel::from_rpcm_json(&serde_json::from_str(&text).unwrap()).unwrap()
    };
    let (rpc_l, rpc_r) = (rpc(&world.camera_left, "A"), rpc(&world.camera_right, "B"));
    assert_eq!(rpc_l.scene_altitude_range(), world.altitude_range());

    let mask = Mask::from_fn(w, h, |x, y| !world.occluded.get(x, y));
    let points = triangulate_disparity(
        &world.disparity,
        &world.rectify_left,
        &world.rectify_right,
        &rpc_l,
        &rpc_r,
        &mask,
    )
    .unwrap();
    let mut worst: f64 = 0.0;
    let mut n = 0;
    for y in 0..h {
        for x in 0..w {
            if !mask.get(x, y) {
                continue;
            }
            let p = points.get(x, y);
            worst = worst.max((p[2] - world.left.height.get(x, y, 0) as f64).abs());
            n += 1;
        }
    }
    println!("world 128²: {n} non-occluded pixels, max |h − truth| {worst:.3e} m");
    assert!(n > w * h / 2);
    assert!(worst < 1e-3, "{worst}");

    // The benchmark's mask keeps a subset of those pixels.
    let eval = evaluation_mask(&world.disparity);
    assert!(!eval.get(10, 64) && !eval.get(64, 120));
    assert!(eval.get(64, 64));
}

#[test]
fn input_errors_are_clear() {
    testdata::require!(S2P);
    let rpc = RpcModel::read_geotiff_rpc(s2p(S2P_IMG1)).unwrap();
    let d = Image::filled(8, 6, 1, 1.0);
    let msg = triangulate_disparity(
        &d,
        &Homography::IDENTITY,
        &Homography::IDENTITY,
        &rpc,
        &rpc,
        &Mask::filled(8, 5, true),
    )
    .unwrap_err()
    .to_string();
    assert!(msg.contains("mask is 8x5") && msg.contains("8x6"), "{msg}");

    let singular = Homography([[1.0, 2.0, 0.0], [2.0, 4.0, 0.0], [0.0, 0.0, 1.0]]);
    let msg = triangulate_disparity(
        &d,
        &Homography::IDENTITY,
        &singular,
        &rpc,
        &rpc,
        &Mask::filled(8, 6, true),
    )
    .unwrap_err()
    .to_string();
    assert!(msg.contains("right homography is singular"), "{msg}");

    let rgb = Image::filled(8, 6, 3, 1.0);
    assert!(triangulate_disparity(
        &rgb,
        &Homography::IDENTITY,
        &Homography::IDENTITY,
        &rpc,
        &rpc,
        &Mask::filled(8, 6, true),
    )
    .is_err());
}

#[test]
fn evaluation_mask_follows_the_protocol() {
    let (w, h) = (100, 80);
    let d = Image::from_fn(w, h, |x, y| match (x, y) {
        (50, 40) => f32::NAN,
        (51, 40) => 0.0,
        (52, 40) => -1.0,
        (53, 40) => 54.0, // x − d < 0
        (40, _) => 39.5,  // x − d = 0.5 ≥ 0
        _ => 2.0,
    });
    let m = evaluation_mask(&d);
    for x in 50..54 {
        assert!(!m.get(x, 40), "{x}");
    }
    assert!(m.get(40, 40) && m.get(54, 40));
    assert!(m.get(32, 32) && m.get(67, 47));
    assert!(!m.get(31, 40) && !m.get(68, 40) && !m.get(50, 31) && !m.get(50, 48));
}

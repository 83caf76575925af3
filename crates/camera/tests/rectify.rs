//! Rectification from cameras: the affine fundamental matrix and rectifying homographies on
//! synthetic affine cameras, errors, and the s2p Pléiades pair rectified from its RPCs, matched,
//! triangulated and compared with s2p's DSM.

use camera::rectify::{
    affine_fundamental, matches_from_cameras, rectification, rectification_with, rectify_pair,
    rectifying_homographies, rectifying_similarities, Camera, GroundMatch, Match, RectifyError,
    Roi, Shear, GRID_ALTITUDES, GRID_POINTS,
};
use raster::{Homography, Image};

/// An affine camera: `(col, row) = P · (X, Y, Z, 1)` on planar ground coordinates (metres).
#[derive(Clone, Copy, Debug)]
struct Affine([[f64; 4]; 2]);

impl Camera for Affine {
    fn project(&self, x: f64, y: f64, z: f64) -> (f64, f64) {
        let p = &self.0;
        (
            p[0][0] * x + p[0][1] * y + p[0][2] * z + p[0][3],
            p[1][0] * x + p[1][1] * y + p[1][2] * z + p[1][3],
        )
    }
    fn localize(&self, col: f64, row: f64, z: f64) -> (f64, f64) {
        let p = &self.0;
        let (u, v) = (col - p[0][2] * z - p[0][3], row - p[1][2] * z - p[1][3]);
        let det = p[0][0] * p[1][1] - p[0][1] * p[1][0];
        (
            (u * p[1][1] - v * p[0][1]) / det,
            (p[0][0] * v - p[1][0] * u) / det,
        )
    }
}

/// A camera at 0.5 m GSD whose image axes are rotated by `angle` (radians) from the ground axes,
/// looking with incidence offsets `(kx, ky)` pixels per metre of altitude.
fn camera(angle: f64, kx: f64, ky: f64, offset: (f64, f64)) -> Affine {
    let (c, s) = (angle.cos() * 2.0, angle.sin() * 2.0);
    Affine([[c, -s, kx, offset.0], [s, c, ky, offset.1]])
}

/// Several synthetic pairs: across-track (epipolar lines ≈ rows), along-track (≈ columns, as for
/// most satellite pairs), oblique, and the mirror cases where the flip is needed.
fn pairs() -> Vec<(&'static str, Affine, Affine)> {
    vec![
        (
            "across-track",
            camera(0.0, 0.3, 0.0, (500.0, 500.0)),
            camera(0.02, -0.35, 0.01, (480.0, 510.0)),
        ),
        (
            "across-track, swapped",
            camera(0.02, -0.35, 0.01, (480.0, 510.0)),
            camera(0.0, 0.3, 0.0, (500.0, 500.0)),
        ),
        (
            "along-track",
            camera(0.1, 0.02, 0.4, (520.0, 400.0)),
            camera(0.12, -0.01, -0.3, (500.0, 560.0)),
        ),
        (
            "oblique, rotated views",
            camera(0.7, 0.25, -0.2, (300.0, 700.0)),
            camera(-0.4, -0.2, 0.3, (600.0, 300.0)),
        ),
        (
            "different scales",
            Affine([[2.0, 0.1, 0.3, 100.0], [-0.05, 2.1, 0.05, 200.0]]),
            Affine([[1.6, -0.2, -0.25, 150.0], [0.15, 1.7, 0.1, 180.0]]),
        ),
    ]
}

const ROI: Roi = Roi {
    x: 100,
    y: 120,
    width: 600,
    height: 500,
};
const ALT: (f64, f64) = (-20.0, 80.0);

fn residual(f: &[[f64; 3]; 3], &((xl, yl), (xr, yr)): &Match) -> f64 {
    let (a, b, c, d, e) = (f[0][2], f[1][2], f[2][0], f[2][1], f[2][2]);
    // Distance, in the 4D joint image space, of the match to the hyperplane.
    (a * xr + b * yr + c * xl + d * yl + e) / (a * a + b * b + c * c + d * d).sqrt()
}

#[test]
fn affine_fundamental_satisfies_the_epipolar_constraint() {
    for (name, l, r) in pairs() {
        let ground = matches_from_cameras(&l, &r, ROI, ALT).unwrap();
        assert_eq!(ground.len(), GRID_POINTS * GRID_POINTS * GRID_ALTITUDES);
        let pairs: Vec<Match> = ground.iter().map(GroundMatch::pair).collect();
        let f = affine_fundamental(&pairs).unwrap();
        assert_eq!([f[0][0], f[0][1], f[1][0], f[1][1]], [0.0; 4], "{name}");
        // Other ground points, off the grid and outside the altitude range, obey it too.
        let mut worst = 0.0f64;
        for i in 0..200 {
            let t = i as f64;
            let (col, row, z) = (
                50.0 + (t * 37.3) % 700.0,
                60.0 + (t * 53.9) % 600.0,
                -50.0 + (t * 7.7) % 200.0,
            );
            let (x, y) = l.localize(col, row, z);
            let m = (l.project(x, y, z), r.project(x, y, z));
            worst = worst.max(residual(&f, &m).abs());
        }
        assert!(worst < 1e-8, "{name}: epipolar residual {worst:e} px");
    }
}

#[test]
fn affine_fundamental_is_robust_to_pixel_noise() {
    let (_, l, r) = pairs()[2];
    let ground = matches_from_cameras(&l, &r, ROI, ALT).unwrap();
    // Deterministic pseudo-noise of ±0.25 px.
    let noise = |i: usize, k: u64| {
        let mut h = (i as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ k;
        h ^= h >> 29;
        h = h.wrapping_mul(0xBF58_476D_1CE4_E5B9);
        h ^= h >> 32;
        (h % 10_000) as f64 / 10_000.0 * 0.5 - 0.25
    };
    let noisy: Vec<Match> = ground
        .iter()
        .enumerate()
        .map(|(i, g)| {
            (
                (g.left.0 + noise(i, 1), g.left.1 + noise(i, 2)),
                (g.right.0 + noise(i, 3), g.right.1 + noise(i, 4)),
            )
        })
        .collect();
    let f = affine_fundamental(&noisy).unwrap();
    let exact = ground
        .iter()
        .map(|g| residual(&f, &g.pair()).abs())
        .fold(0.0, f64::max);
    assert!(exact < 0.1, "noise-free residual of the noisy fit: {exact}");
}

/// Rectified rows and disparities of a ground point.
fn rectified(
    h_l: &Homography,
    h_r: &Homography,
    l: &impl Camera,
    r: &impl Camera,
    (col, row, z): (f64, f64, f64),
) -> ((f64, f64), (f64, f64)) {
    let (x, y) = l.localize(col, row, z);
    let (pl, pr) = (l.project(x, y, z), r.project(x, y, z));
    (h_l.apply(pl.0, pl.1), h_r.apply(pr.0, pr.1))
}

#[test]
fn homographies_align_rows_and_make_disparity_grow_with_altitude() {
    let mut flips = 0;
    for (name, l, r) in pairs() {
        let rect = rectification(&l, &r, ROI, ALT).unwrap();
        flips += rect.flipped as usize;
        let (lo, hi) = rect.disparity_range;
        assert!(lo >= 1 && hi > lo, "{name}: range {lo}..{hi}");
        assert!(rect.max_row_error < 1e-8, "{name}: {}", rect.max_row_error);
        for i in 0..50 {
            let t = i as f64;
            let col = ROI.x as f64 + (t * 41.7) % ROI.width as f64;
            let row = ROI.y as f64 + (t * 29.3) % ROI.height as f64;
            let mut last = f64::NEG_INFINITY;
            for z in [ALT.0, 0.0, 30.0, ALT.1] {
                let (pl, pr) = rectified(&rect.h_left, &rect.h_right, &l, &r, (col, row, z));
                assert!(
                    (pl.1 - pr.1).abs() < 1e-8,
                    "{name}: rows {} vs {}",
                    pl.1,
                    pr.1
                );
                let d = pl.0 - pr.0;
                assert!(d > last, "{name}: disparity {d} at {z} m after {last}");
                assert!(
                    (lo as f64..=hi as f64).contains(&d),
                    "{name}: {d} outside {lo}..{hi}"
                );
                assert!(d >= 1.0, "{name}: disparity {d} is not positive");
                // The region of interest is inside the frame, and so is its match.
                let (w, h) = (rect.size.0 as f64, rect.size.1 as f64);
                assert!(
                    pl.0 >= -1e-9 && pl.0 <= w - 1.0 + 1e-9,
                    "{name}: x {}",
                    pl.0
                );
                assert!(
                    pl.1 >= -1e-9 && pl.1 <= h - 1.0 + 1e-9,
                    "{name}: y {}",
                    pl.1
                );
                assert!(pr.0 >= -1e-9, "{name}: right x {}", pr.0);
                last = d;
            }
        }
        // The disparity per metre is the pair's: an across-track pair with 0.3 + 0.35 px/m.
        if name == "across-track" {
            assert!((rect.pixels_per_metre - 0.65).abs() < 0.02, "{rect:?}");
        }
    }
    assert!(flips >= 1, "the pair list should exercise the flip");
}

/// The right image's shear levels the ground: one altitude has one disparity over the whole
/// region, so the search range is the altitude range's width and no more, even for views
/// rotated or scaled against each other (whose ground disparity otherwise tilts across the frame).
#[test]
fn one_altitude_has_one_disparity_and_the_range_is_the_altitudes_alone() {
    for (name, l, r) in pairs() {
        let rect = rectification(&l, &r, ROI, ALT).unwrap();
        let (lo, hi) = rect.disparity_range;
        let span = rect.pixels_per_metre * (ALT.1 - ALT.0);
        assert!(
            ((hi - lo) as f64) <= span + 3.0,
            "{name}: range {lo}..{hi} for {span:.1} px of altitudes"
        );
        for z in [ALT.0, 10.0, ALT.1] {
            let d: Vec<f64> = (0..40)
                .map(|i| {
                    let t = i as f64;
                    let col = ROI.x as f64 + (t * 41.7) % ROI.width as f64;
                    let row = ROI.y as f64 + (t * 29.3) % ROI.height as f64;
                    let (pl, pr) = rectified(&rect.h_left, &rect.h_right, &l, &r, (col, row, z));
                    pl.0 - pr.0
                })
                .collect();
            let spread = d.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
                - d.iter().cloned().fold(f64::INFINITY, f64::min);
            assert!(
                spread < 1e-6,
                "{name}: disparities at {z} m spread {spread} px"
            );
        }
        // Without the shear, views rotated or scaled against each other search more.
        let plain = rectification_with(&l, &r, ROI, ALT, Shear::None).unwrap();
        let width = |r: (i32, i32)| r.1 - r.0;
        assert!(
            width(plain.disparity_range) >= width(rect.disparity_range),
            "{name}"
        );
        if name == "different scales" {
            assert!(
                width(plain.disparity_range) > width(rect.disparity_range) + 20,
                "{name}: {:?} against {:?}",
                plain.disparity_range,
                rect.disparity_range
            );
        }
    }
}

#[test]
fn a_stretched_rectification_multiplies_disparities_and_keeps_rows() {
    for (name, l, r) in pairs() {
        let rect = rectification(&l, &r, ROI, ALT).unwrap();
        let wide = rect.stretched(2.0);
        let (lo, hi) = wide.disparity_range;
        assert_eq!(wide.size, (2 * rect.size.0, rect.size.1), "{name}");
        assert!((wide.pixels_per_metre - 2.0 * rect.pixels_per_metre).abs() < 1e-12);
        assert_eq!((rect.stretch, wide.stretch), (1.0, 2.0));
        for (i, z) in [ALT.0, 0.0, ALT.1].into_iter().enumerate() {
            let point = (ROI.x as f64 + 37.0 * i as f64, ROI.y as f64 + 53.0, z);
            let (pl, pr) = rectified(&rect.h_left, &rect.h_right, &l, &r, point);
            let (sl, sr) = rectified(&wide.h_left, &wide.h_right, &l, &r, point);
            assert!(
                (sl.1 - pl.1).abs() < 1e-9 && (sr.1 - sl.1).abs() < 1e-8,
                "{name}: rows"
            );
            let (d, ds) = (pl.0 - pr.0, sl.0 - sr.0);
            assert!((ds - 2.0 * d).abs() < 1e-8, "{name}: {ds} is not twice {d}");
            assert!(
                (lo as f64..=hi as f64).contains(&ds),
                "{name}: {ds} outside {lo}..{hi}"
            );
            assert!(
                sl.0 >= -1e-9 && sl.0 <= wide.size.0 as f64 - 1.0 + 1e-9,
                "{name}"
            );
        }
    }
}

#[test]
fn similarities_depend_on_f_only_up_to_sign() {
    let (_, l, r) = pairs()[3];
    let ground = matches_from_cameras(&l, &r, ROI, ALT).unwrap();
    let pairs: Vec<Match> = ground.iter().map(GroundMatch::pair).collect();
    let f = affine_fundamental(&pairs).unwrap();
    let neg = f.map(|row| row.map(|v| -2.0 * v));
    assert_eq!(
        rectifying_similarities(&f)
            .unwrap()
            .0
             .0
            .map(|r| r.map(|v| (v * 1e9).round())),
        rectifying_similarities(&neg)
            .unwrap()
            .0
             .0
            .map(|r| r.map(|v| (v * 1e9).round()))
    );
}

#[test]
fn errors() {
    let (_, l, r) = pairs()[0];
    let ground = matches_from_cameras(&l, &r, ROI, ALT).unwrap();
    let pairs: Vec<Match> = ground.iter().map(GroundMatch::pair).collect();

    // Too few matches.
    let e = affine_fundamental(&pairs[..3]).unwrap_err();
    assert!(matches!(e, RectifyError::TooFewMatches(3)), "{e}");
    assert!(e.to_string().contains("at least 4"), "{e}");
    assert!(matches!(
        affine_fundamental(&[]).unwrap_err(),
        RectifyError::TooFewMatches(0)
    ));

    // A single altitude: the matches follow an affinity, the epipolar lines are undetermined.
    let flat: Vec<Match> = ground
        .iter()
        .filter(|g| g.alt() == ALT.0)
        .map(GroundMatch::pair)
        .collect();
    assert!(flat.len() >= 100);
    let e = affine_fundamental(&flat).unwrap_err();
    assert!(matches!(e, RectifyError::Degenerate(_)), "{e}");

    // Collinear points, and one point repeated.
    let line: Vec<Match> = (0..20)
        .map(|i| {
            let t = i as f64;
            ((t, 2.0 * t), (t + 3.0, 2.0 * t - 1.0))
        })
        .collect();
    assert!(matches!(
        affine_fundamental(&line).unwrap_err(),
        RectifyError::Degenerate(_)
    ));
    assert!(matches!(
        affine_fundamental(&[pairs[0]; 10]).unwrap_err(),
        RectifyError::Degenerate(_)
    ));
    let mut nan = pairs.clone();
    nan[5].1 .0 = f64::NAN;
    assert!(matches!(
        affine_fundamental(&nan).unwrap_err(),
        RectifyError::Invalid(_)
    ));

    // Not an affine fundamental matrix.
    let zero_left = [[0.0, 0.0, 1.0], [0.0, 0.0, 0.0], [0.0, 0.0, 3.0]];
    assert!(rectifying_similarities(&zero_left).is_err());

    // The homographies need matches at several altitudes.
    let f = affine_fundamental(&pairs).unwrap();
    let one_alt: Vec<GroundMatch> = ground.iter().filter(|g| g.alt() == 0.0).copied().collect();
    let one_alt = if one_alt.is_empty() {
        ground
            .iter()
            .filter(|g| g.alt() == ALT.1)
            .copied()
            .collect()
    } else {
        one_alt
    };
    let e = rectifying_homographies(&f, &one_alt, ROI, Shear::Level).unwrap_err();
    assert!(e.to_string().contains("one altitude"), "{e}");

    // No baseline: the same camera twice.
    let e = rectification(&l, &l, ROI, ALT).unwrap_err();
    assert!(matches!(e, RectifyError::Degenerate(_)), "{e}");

    // Bad altitude range, empty region, region outside the image.
    for alt in [(10.0, 10.0), (5.0, -5.0), (f64::NAN, 1.0)] {
        let e = rectification(&l, &r, ROI, alt).unwrap_err();
        assert!(e.to_string().contains("altitude range"), "{e}");
    }
    let e = rectification(&l, &r, Roi::new(0, 0, 0, 10), ALT).unwrap_err();
    assert!(e.to_string().contains("empty"), "{e}");
    let img = Image::filled(300, 300, 1, 1.0);
    let e = rectify_pair(&img, &img, &l, &r, ROI, ALT).unwrap_err();
    assert!(e.to_string().contains("does not fit"), "{e}");
}

/// A deterministic ground texture (metres → grey) with detail at several scales.
fn texture(x: f64, y: f64) -> f32 {
    let s = (x * 0.9).sin() * (y * 1.3).cos()
        + 0.6 * ((x + 2.0 * y) * 0.37).sin()
        + 0.4 * ((3.1 * x - y) * 0.21).cos()
        + 0.3 * ((x * 2.3 + 1.0).sin() * (y * 1.9).sin());
    (100.0 + 40.0 * s) as f32
}

/// The image of a scene `height(x, y)` by an affine camera (ray marched from each pixel).
fn render(cam: &Affine, w: usize, h: usize, height: impl Fn(f64, f64) -> f64) -> Image {
    Image::from_fn(w, h, |c, r| {
        // Fixed point of z = height(localize(c, r, z)): scenes here are gentle enough.
        let mut z = 0.0;
        for _ in 0..30 {
            let (x, y) = cam.localize(c as f64, r as f64, z);
            z = height(x, y);
        }
        let (x, y) = cam.localize(c as f64, r as f64, z);
        texture(x, y)
    })
}

#[test]
fn rectified_synthetic_pair_matches_to_the_true_disparity() {
    let l = camera(0.3, 0.25, -0.1, (60.0, 40.0));
    let r = camera(0.25, -0.2, 0.05, (70.0, 30.0));
    // A gentle slope: height z(x, y) = 10 + 0.05 x metres.
    let z = |x: f64, _y: f64| 10.0 + 0.05 * x;
    let (w, h) = (260, 240);
    let (li, ri) = (render(&l, w, h, z), render(&r, w, h, z));
    let roi = Roi::new(40, 40, 180, 160);
    let pair = rectify_pair(&li, &ri, &l, &r, roi, (0.0, 40.0)).unwrap();
    assert_eq!(pair.left.size(), pair.size);
    assert_eq!(pair.right.size(), pair.size);
    assert!(pair.left.data().iter().any(|v| v.is_nan()), "NaN outside");
    let (lo, hi) = pair.disparity_range;
    let params = matching::SgmParams::default();
    let disp = matching::match_pair(&pair.left, &pair.right, (lo, hi), &params).unwrap();
    // The true disparity of each rectified left pixel of the region.
    let inv = pair.h_left.inverse().unwrap();
    let mut errors = Vec::new();
    let (rx, ry, rw, rh) = pair.rectification.roi_in_frame;
    for y in (ry..ry + rh).step_by(3) {
        for x in (rx..rx + rw).step_by(3) {
            let (c, rr) = inv.apply(x as f64, y as f64);
            if !(roi.x as f64..(roi.x + roi.width) as f64).contains(&c)
                || !(roi.y as f64..(roi.y + roi.height) as f64).contains(&rr)
            {
                continue;
            }
            let mut zz = 0.0;
            for _ in 0..30 {
                let (gx, gy) = l.localize(c, rr, zz);
                zz = z(gx, gy);
            }
            let ((xl, yl), (xr, yr)) = rectified(&pair.h_left, &pair.h_right, &l, &r, (c, rr, zz));
            assert!((yl - yr).abs() < 1e-6 && (xl - x as f64).abs() < 1e-6);
            let d = disp.get(x, y, 0);
            if d.is_finite() {
                errors.push((d as f64 - (xl - xr)).abs());
            }
        }
    }
    assert!(errors.len() > 500, "{} matched samples", errors.len());
    errors.sort_by(f64::total_cmp);
    let median = errors[errors.len() / 2];
    assert!(median < 0.25, "median disparity error {median} px");
}

// ---------------------------------------------------------------------------------------------
// The s2p Pléiades pair, read in place from s2p's test data.

/// The `tests/data` folder of s2p's test data, or None (the test skips) where it is absent.
fn s2p_data() -> Option<std::path::PathBuf> {
    testdata::dataset("anchors/data/s2p").map(|dir| dir.join("tests/data"))
}

/// s2p's region of interest for this pair (tests/data/input_pair/config.json).
const S2P_ROI: Roi = Roi {
    x: 150,
    y: 150,
    width: 700,
    height: 700,
};

/// The scene's altitudes, as a user would give them (s2p takes them from SRTM): s2p's DSM of the
/// region spans 2270–2376 m; the RPCs' own validity range (−20…2610 m) would mean a 1400-pixel
/// search.
const S2P_ALT: (f64, f64) = (2200.0, 2450.0);

fn s2p_pair(dir: &std::path::Path) -> (raster::formats::GeoRaster, raster::formats::GeoRaster) {
    let read = |name: &str| raster::formats::read_tiff(dir.join("input_pair").join(name)).unwrap();
    (read("img_01.tif"), read("img_02.tif"))
}

#[test]
fn s2p_pair_rectified_from_rpcs_matches_the_s2p_dsm() {
    use camera::{evaluation_mask, rasterize_max, triangulate_disparity, DsmGrid, RpcModel};
    use std::time::Instant;

    let Some(s2p) = s2p_data() else {
        return;
    };
    let (left, right) = s2p_pair(&s2p);
    let rpc_l = RpcModel::from_tiff_tag(left.rpc.as_ref().unwrap()).unwrap();
    let rpc_r = RpcModel::from_tiff_tag(right.rpc.as_ref().unwrap()).unwrap();

    let t = Instant::now();
    let pair = rectify_pair(&left.image, &right.image, &rpc_l, &rpc_r, S2P_ROI, S2P_ALT).unwrap();
    let t_rectify = t.elapsed();
    let (lo, hi) = pair.disparity_range;
    println!(
        "rectified {}x{} in {t_rectify:.2?}; disparity range {lo}..{hi} px ({:.3} px/m), flipped {}",
        pair.size.0, pair.size.1, pair.rectification.pixels_per_metre, pair.rectification.flipped
    );

    // RPC-projected ground points off the fitting grid land on one rectified row, with a positive
    // disparity that grows with altitude.
    let mut max_dy = 0.0f64;
    for i in 0..400 {
        let t = i as f64;
        let col = S2P_ROI.x as f64 + (t * 61.37) % S2P_ROI.width as f64;
        let row = S2P_ROI.y as f64 + (t * 17.93) % S2P_ROI.height as f64;
        let mut last = f64::NEG_INFINITY;
        for z in [2200.0, 2270.0, 2320.0, 2376.0, 2450.0] {
            let (pl, pr) = rectified(&pair.h_left, &pair.h_right, &rpc_l, &rpc_r, (col, row, z));
            max_dy = max_dy.max((pl.1 - pr.1).abs());
            let d = pl.0 - pr.0;
            assert!(d > 0.0 && d > last, "disparity {d} at {z} m after {last}");
            assert!(
                (lo as f64..=hi as f64).contains(&d),
                "{d} outside {lo}..{hi}"
            );
            last = d;
        }
    }
    println!("max |Δy| of RPC-projected ground points: {max_dy:.4} px");
    assert!(max_dy < 0.5, "max |Δy| = {max_dy} px");

    // Match over the camera-derived range, triangulate, rasterise on s2p's DSM grid.
    let t = Instant::now();
    let disparity = matching::match_pair(
        &pair.left,
        &pair.right,
        (lo, hi),
        &matching::SgmParams::default(),
    )
    .unwrap();
    let t_match = t.elapsed();
    let t = Instant::now();
    let mask = evaluation_mask(&disparity);
    let points = triangulate_disparity(
        &disparity,
        &pair.h_left,
        &pair.h_right,
        &rpc_l,
        &rpc_r,
        &mask,
    )
    .unwrap();
    let expected_path = s2p.join("expected_output/pair/dsm.tif");
    let expected = raster::formats::read_tiff(&expected_path).unwrap();
    let grid = DsmGrid::of_raster(&expected, "s2p dsm.tif").unwrap();
    let dsm = rasterize_max(&points, &grid);
    let t_dsm = t.elapsed();
    println!(
        "matched in {t_match:.2?} ({} of {} px valid), triangulated {} points and rasterised in {t_dsm:.2?}",
        disparity.data().iter().filter(|v| v.is_finite()).count(),
        disparity.data().len(),
        points.valid_count()
    );

    // Median |Δh| on shared cells after removing the mean vertical offset, at the best integer
    // shift within ±3 cells (s2p averages the points of a cell, we keep the maximum).
    let compare = |dx: i64, dy: i64| {
        let (w, h) = (grid.width as i64, grid.height as i64);
        let mut diffs = Vec::new();
        for y in 0..h {
            for x in 0..w {
                let (xs, ys) = (x + dx, y + dy);
                if xs < 0 || ys < 0 || xs >= w || ys >= h {
                    continue;
                }
                let a = expected.image.get(x as usize, y as usize, 0);
                let b = dsm.get(xs as usize, ys as usize, 0);
                if a.is_finite() && b.is_finite() {
                    diffs.push(a as f64 - b as f64);
                }
            }
        }
        let n = diffs.len();
        let offset = diffs.iter().sum::<f64>() / n.max(1) as f64;
        let mut abs: Vec<f64> = diffs.iter().map(|d| (d - offset).abs()).collect();
        abs.sort_by(f64::total_cmp);
        (abs.get(n / 2).copied().unwrap_or(f64::INFINITY), offset, n)
    };
    let (median0, offset0, n0) = compare(0, 0);
    let (mut best, mut best_shift) = ((median0, offset0, n0), (0i64, 0i64));
    for dy in -3..=3 {
        for dx in -3..=3 {
            let c = compare(dx, dy);
            if c.0 < best.0 {
                (best, best_shift) = (c, (dx, dy));
            }
        }
    }
    let expected_cells = expected
        .image
        .data()
        .iter()
        .filter(|v| v.is_finite())
        .count();
    println!(
        "vs s2p DSM: {n0} shared cells of {expected_cells}; median |Δh| {median0:.3} m after a \
         {offset0:+.3} m offset; best shift {best_shift:?} cells: median |Δh| {:.3} m, offset {:+.3} m",
        best.0, best.1
    );
    assert!(
        n0 as f64 > 0.5 * expected_cells as f64,
        "{n0} shared cells of {expected_cells}"
    );
    assert!(median0 < 1.0, "median |Δh| = {median0} m");
}

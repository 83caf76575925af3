//! End-to-end accuracy and robustness of census + SGM on synthetic rectified pairs with exact
//! ground truth (see `synthetic/mod.rs`: a background plane slanted from 3 to 8 px, a block at
//! 12 px and a block at 20 px, each with its own texture, occlusions painted in depth order).

mod synthetic;

use matching::{
    estimate_range, match_pair, match_pair_with_progress, memory_bytes, MatchError, Paths,
    SgmParams,
};
use raster::Image;
use std::sync::atomic::{AtomicUsize, Ordering};
use synthetic::{standard_pair, stats};

const W: usize = 256;
const H: usize = 256;

#[test]
fn accuracy_on_slanted_plane_and_blocks() {
    let pair = standard_pair(W, H);
    let disp = match_pair(&pair.left, &pair.right, (0, 31), &SgmParams::default()).unwrap();
    assert_eq!(disp.size(), (W, H));
    assert_eq!(disp.channels(), 1);
    let d = disp.data();
    let vis = stats(d, &pair.disp, |i| !pair.occluded[i]);
    eprintln!("visible: {vis:?}");
    assert!(vis.mae < 0.3, "mean abs error {:.3} px", vis.mae);
    assert!(vis.bad1 < 0.05, "bad-1 {:.3}", vis.bad1);
    assert!(vis.coverage > 0.85, "coverage {:.3}", vis.coverage);
    // Occluded pixels (beside the blocks and at the left border) are mostly rejected.
    let n_occ = pair.occluded.iter().filter(|o| **o).count();
    assert!(n_occ > 1500, "the scene has occlusions ({n_occ})");
    let occ = stats(d, &pair.disp, |i| pair.occluded[i]);
    eprintln!("occluded: {occ:?}");
    assert!(occ.coverage < 0.35, "occluded coverage {:.3}", occ.coverage);
    // Each block is found at its own height.
    let at = |x: usize, y: usize| d[y * W + x];
    assert!((at(100, 90) - 20.0).abs() < 0.5, "{}", at(100, 90));
    assert!((at(190, 180) - 12.0).abs() < 0.5, "{}", at(190, 180));
    // Only NaN or values inside the range.
    assert!(d.iter().all(|v| v.is_nan() || (0.0..=31.0).contains(v)));
}

#[test]
fn sub_pixel_refinement_helps_on_the_slanted_plane() {
    let pair = standard_pair(W, H);
    let run = |subpixel| {
        let p = SgmParams {
            subpixel,
            ..SgmParams::default()
        };
        let d = match_pair(&pair.left, &pair.right, (0, 31), &p).unwrap();
        stats(d.data(), &pair.disp, |i| !pair.occluded[i]).mae
    };
    let (with, without) = (run(true), run(false));
    eprintln!("mae with sub-pixel {with:.3}, without {without:.3}");
    assert!(with < 0.8 * without, "{with} vs {without}");
}

#[test]
fn four_paths_and_no_checks_still_match() {
    let pair = standard_pair(W, H);
    let params = SgmParams {
        paths: Paths::Four,
        lr_tolerance: None,
        uniqueness: None,
        median: false,
        p2_adaptive: None,
        ..SgmParams::default()
    };
    let d = match_pair(&pair.left, &pair.right, (0, 31), &params).unwrap();
    let vis = stats(d.data(), &pair.disp, |i| !pair.occluded[i]);
    eprintln!("four paths: {vis:?}");
    assert!(
        vis.mae < 0.4 && vis.bad1 < 0.05 && vis.coverage > 0.95,
        "{vis:?}"
    );
}

#[test]
fn negative_range_by_swapping_roles() {
    let pair = standard_pair(W, H);
    // The right image as reference: its disparities are −d, within [−31, 0].
    let disp = match_pair(&pair.right, &pair.left, (-31, 0), &SgmParams::default()).unwrap();
    let d = disp.data();
    // Right pixels whose source is visible: every right pixel shows the nearest surface, so all
    // are visible in the left image except where x_L = x_R − d_R falls out of frame.
    let visible = |i: usize| {
        let x = (i % W) as f32 - pair.disp_right[i];
        (0.0..(W - 1) as f32).contains(&x)
    };
    let s = stats(d, &pair.disp_right, visible);
    eprintln!("swapped: {s:?}");
    assert!(s.mae < 0.3 && s.bad1 < 0.05 && s.coverage > 0.85, "{s:?}");
    assert!(d.iter().all(|v| v.is_nan() || (-31.0..=0.0).contains(v)));
}

#[test]
fn range_with_negative_and_positive_disparities() {
    // Shift the whole scene by −10 px: disparities from −7 to +10.
    let pair = standard_pair(W, H);
    let shift = 10usize;
    let right = Image::from_fn(W, H, |x, y| pair.right.get((x + W - shift) % W, y, 0));
    let disp = match_pair(&pair.left, &right, (-16, 15), &SgmParams::default()).unwrap();
    let truth: Vec<f32> = pair.disp.iter().map(|d| d - shift as f32).collect();
    // Skip the wrapped band and the occlusions.
    let s = stats(disp.data(), &truth, |i| !pair.occluded[i] && i % W >= 40);
    eprintln!("shifted: {s:?}");
    assert!(s.mae < 0.3 && s.bad1 < 0.05 && s.coverage > 0.85, "{s:?}");
}

#[test]
fn range_estimation_brackets_the_true_range() {
    let pair = standard_pair(W, H);
    let (lo, hi) = estimate_range(&pair.left, &pair.right).unwrap();
    eprintln!("estimated range [{lo}, {hi}] for true [3, 20]");
    assert!(lo <= 3 && hi >= 20, "[{lo}, {hi}]");
    assert!(lo >= -16 && hi <= 40, "too wide: [{lo}, {hi}]");
    let disp = match_pair(&pair.left, &pair.right, (lo, hi), &SgmParams::default()).unwrap();
    let s = stats(disp.data(), &pair.disp, |i| !pair.occluded[i]);
    assert!(s.mae < 0.3 && s.coverage > 0.85, "{s:?}");
}

#[test]
fn invariant_to_value_range_and_channels() {
    let pair = standard_pair(128, 128);
    let params = SgmParams::default();
    let a = match_pair(&pair.left, &pair.right, (0, 31), &params).unwrap();
    // [0, 1] floats.
    let unit = |img: &Image| Image::from_fn(128, 128, |x, y| (img.get(x, y, 0) - 1000.0) / 3000.0);
    let b = match_pair(&unit(&pair.left), &unit(&pair.right), (0, 31), &params).unwrap();
    // Three identical channels.
    let rgb = |img: &Image| {
        let data = img.data().iter().flat_map(|&v| [v, v, v]).collect();
        Image::new(128, 128, 3, data).unwrap()
    };
    let c = match_pair(&rgb(&pair.left), &rgb(&pair.right), (0, 31), &params).unwrap();
    let same = |x: &Image, y: &Image| {
        x.data()
            .iter()
            .zip(y.data())
            .filter(|(p, q)| (p.is_nan() && q.is_nan()) || (*p - *q).abs() < 1e-3)
            .count() as f64
            / x.data().len() as f64
    };
    assert!(same(&a, &b) > 0.99, "{}", same(&a, &b));
    assert_eq!(same(&a, &c), 1.0);
}

#[test]
fn mismatched_sizes_are_an_error() {
    let a = Image::filled(32, 16, 1, 1.0);
    let b = Image::filled(31, 16, 1, 1.0);
    assert!(matches!(
        match_pair(&a, &b, (0, 63), &SgmParams::default()),
        Err(MatchError::SizeMismatch { .. })
    ));
    assert!(matches!(
        estimate_range(&a, &b),
        Err(MatchError::SizeMismatch { .. })
    ));
}

#[test]
fn empty_range_and_bad_parameters_are_errors() {
    let pair = standard_pair(32, 32);
    let err = match_pair(&pair.left, &pair.right, (5, 4), &SgmParams::default()).unwrap_err();
    assert!(
        matches!(err, MatchError::EmptyRange { d_min: 5, d_max: 4 }),
        "{err}"
    );
    let bad = SgmParams {
        p2: 5,
        p1: 10,
        ..SgmParams::default()
    };
    assert!(matches!(
        match_pair(&pair.left, &pair.right, (0, 31), &bad),
        Err(MatchError::InvalidParams(_))
    ));
    let empty = Image::filled(0, 0, 1, 0.0);
    assert!(matches!(
        match_pair(&empty, &empty, (0, 63), &SgmParams::default()),
        Err(MatchError::EmptyImage(0, 0))
    ));
    // A single disparity is a valid range.
    let one = match_pair(&pair.left, &pair.right, (7, 7), &SgmParams::default()).unwrap();
    assert!(one.data().iter().all(|v| v.is_nan() || *v == 7.0));
}

#[test]
fn memory_accounting_and_limit() {
    let m = memory_bytes(1024, 1024, 128);
    let volume = 1024 * 1024 * 128 * 3;
    assert!(m >= volume && m < volume + volume / 8, "{m}");
    let pair = standard_pair(64, 64);
    let params = SgmParams {
        max_memory: Some(memory_bytes(64, 64, 32) - 1),
        ..SgmParams::default()
    };
    assert!(matches!(
        match_pair(&pair.left, &pair.right, (0, 31), &params),
        Err(MatchError::TooLarge { .. })
    ));
    let params = SgmParams {
        max_memory: Some(memory_bytes(64, 64, 32)),
        ..params
    };
    assert!(match_pair(&pair.left, &pair.right, (0, 31), &params).is_ok());
}

#[test]
fn nan_input_pixels_give_nan_output() {
    let pair = standard_pair(W, H);
    let mut left = pair.left.clone();
    let mut right = pair.right.clone();
    // A NaN hole in the left image, a NaN column band in the right one.
    for y in 100..140 {
        for x in 150..190 {
            left.set(x, y, 0, f32::NAN);
        }
    }
    for y in 0..H {
        for x in 30..34 {
            right.set(x, y, 0, f32::NAN);
        }
    }
    let disp = match_pair(&left, &right, (0, 31), &SgmParams::default()).unwrap();
    let d = disp.data();
    for y in 100..140 {
        for x in 150..190 {
            assert!(d[y * W + x].is_nan(), "({x}, {y}) = {}", d[y * W + x]);
        }
    }
    // A match never lands on a NaN right pixel.
    for (i, v) in d.iter().enumerate() {
        if v.is_finite() {
            let xr = ((i % W) as f32 - v).round();
            assert!(
                !(30.0..34.0).contains(&xr),
                "pixel {i} matched NaN column {xr}"
            );
        }
    }
    let s = stats(d, &pair.disp, |i| {
        let (x, y) = (i % W, i / W);
        let in_hole = (95..145).contains(&y) && (145..195).contains(&x);
        !pair.occluded[i] && !in_hole
    });
    assert!(s.mae < 0.3 && s.coverage > 0.8, "{s:?}");
}

#[test]
fn constant_image_does_not_panic() {
    let flat = Image::filled(64, 48, 1, 7.0);
    // Every disparity has the same census cost: the values are arbitrary (SGM propagates the
    // border's out-of-image costs), but they are NaN or inside the range.
    let disp = match_pair(&flat, &flat, (-4, 11), &SgmParams::default()).unwrap();
    assert!(disp
        .data()
        .iter()
        .all(|v| v.is_nan() || (-4.0..=11.0).contains(v)));
    assert!(matches!(
        estimate_range(&flat, &flat),
        Err(MatchError::RangeEstimation(_))
    ));
}

#[test]
fn progress_reaches_its_total() {
    let pair = standard_pair(64, 40);
    let calls = AtomicUsize::new(0);
    let last = AtomicUsize::new(0);
    let total = AtomicUsize::new(0);
    let cb = |done: usize, t: usize| {
        calls.fetch_add(1, Ordering::Relaxed);
        last.fetch_max(done, Ordering::Relaxed);
        total.store(t, Ordering::Relaxed);
    };
    match_pair_with_progress(
        &pair.left,
        &pair.right,
        (0, 31),
        &SgmParams::default(),
        Some(&cb),
    )
    .unwrap();
    let t = total.load(Ordering::Relaxed);
    assert_eq!(t, 5 * 40);
    assert_eq!(last.load(Ordering::Relaxed), t);
    assert_eq!(calls.load(Ordering::Relaxed), t);
}

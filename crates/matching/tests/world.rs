//! Acceptance of the classical matcher on the procedural world, whose disparity is exact.

use matching::{match_pair, SgmParams};
use world::{generate, Neutral, WorldParams};

fn scores(seed: u64) -> (f64, f64, f64) {
    let w = generate(&WorldParams::new(256, seed), &Neutral, &|_, _| {}).unwrap();
    let (lo, hi) = w.disparity_range();
    let d = match_pair(
        &w.left.image,
        &w.right.image,
        (lo, hi),
        &SgmParams::default(),
    )
    .unwrap();
    let (mut n, mut matched, mut abs, mut bad2) = (0usize, 0usize, 0.0f64, 0usize);
    for i in 0..256 * 256 {
        if w.occluded.data()[i] {
            continue;
        }
        n += 1;
        let p = d.data()[i];
        if p.is_finite() {
            matched += 1;
            let e = (p - w.disparity.data()[i]).abs() as f64;
            abs += e;
            bad2 += (e > 2.0) as usize;
        }
    }
    (
        abs / matched as f64,
        bad2 as f64 / matched as f64,
        matched as f64 / n as f64,
    )
}

#[test]
fn sgm_is_accurate_on_a_256_world() {
    for seed in [1, 2] {
        let (mae, bad2, coverage) = scores(seed);
        eprintln!(
            "seed {seed}: MAE {mae:.3} px, bad-2 {:.2} %, coverage {:.1} %",
            100.0 * bad2,
            100.0 * coverage
        );
        assert!(mae < 0.5, "seed {seed}: MAE {mae}");
        assert!(bad2 < 0.05, "seed {seed}: bad-2 {bad2}");
        assert!(coverage > 0.85, "seed {seed}: coverage {coverage}");
    }
}

//! The one-cycle schedule against PyTorch's `OneCycleLR` formulas, computed by hand.

use train::schedule::{OneCycle, OneCycleConfig};

fn close(a: f64, b: f64) {
    assert!(
        (a - b).abs() <= 1e-15 + 1e-12 * b.abs(),
        "{a} != {b} (diff {})",
        a - b
    );
}

/// Paper run: 50,000 steps, lr 5e-4, upstream total_steps = 50,100, pct_start 0.01.
/// Phase 1 ends at 0.01·50100 − 1 = 500, phase 2 at 50099.
#[test]
fn paper_schedule_matches_torch_at_key_steps() {
    let s = OneCycle::new(5e-4, 50_000, &OneCycleConfig::default()).unwrap();
    assert_eq!(s.total_steps(), 50_100);
    let initial = 5e-4 / 25.0; // 2e-5
    let min = initial / 1e4; // 2e-9
    close(s.lr(0), initial);
    // Warm-up: linear from initial to max over steps 0..=500.
    close(s.lr(1), initial + (5e-4 - initial) * (1.0 / 500.0));
    close(s.lr(250), initial + (5e-4 - initial) * 0.5);
    close(s.lr(500), 5e-4);
    // Annealing: pct = (s − 500) / (50099 − 500).
    let pct = |step: f64| (step - 500.0) / (50_099.0 - 500.0);
    close(s.lr(501), (min - 5e-4) * pct(501.0) + 5e-4);
    close(s.lr(25_300), (min - 5e-4) * pct(25_300.0) + 5e-4);
    // The last training step (49,999) never reaches the minimum (the +100 of upstream).
    close(s.lr(49_999), (min - 5e-4) * pct(49_999.0) + 5e-4);
    assert!(s.lr(49_999) > 1e-6);
    close(s.lr(50_099), min);
    // Past the end: held at the minimum (PyTorch raises).
    close(s.lr(60_000), min);
}

/// A fractional phase boundary (pct_start·T − 1 not an integer), as PyTorch computes it.
#[test]
fn fractional_phase_boundary() {
    let cfg = OneCycleConfig {
        pct_start: 0.3,
        extra_steps: 0,
        ..OneCycleConfig::default()
    };
    let s = OneCycle::new(1e-3, 25, &cfg).unwrap();
    let end1 = 0.3 * 25.0 - 1.0; // 6.5
    let initial = 1e-3 / 25.0;
    close(s.lr(6), initial + (1e-3 - initial) * (6.0 / end1));
    let min = initial / 1e4;
    close(
        s.lr(7),
        (min - 1e-3) * ((7.0 - end1) / (24.0 - end1)) + 1e-3,
    );
    close(s.lr(24), min);
}

#[test]
fn bad_parameters_are_rejected() {
    let bad = OneCycleConfig {
        pct_start: 1.5,
        ..OneCycleConfig::default()
    };
    assert!(OneCycle::new(1e-3, 10, &bad).is_err());
    assert!(OneCycle::new(0.0, 10, &OneCycleConfig::default()).is_err());
    let none = OneCycleConfig {
        extra_steps: 0,
        ..OneCycleConfig::default()
    };
    assert!(OneCycle::new(1e-3, 0, &none).is_err());
}

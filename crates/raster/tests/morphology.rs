//! The morphology operations against straightforward reference implementations on random masks,
//! and their speed on a 1024² mask (linear time, no recursion). The exact match with scipy on the
//! fixture's synthetic mask is in `crates/nn/tests/parity_segformer.rs`.

use std::time::Instant;

use raster::morphology::{dilate_square, fill_holes, label_components, remove_small_components};
use raster::Mask;

/// Deterministic blobby random mask: thresholded sum of a few random boxes (xorshift).
fn random_mask(w: usize, h: usize, seed: u64, density: u32) -> Mask {
    let mut s = seed.max(1);
    let mut next = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        s
    };
    let mut m = Mask::filled(w, h, false);
    for _ in 0..(w * h) as u32 * density / 400 {
        let (x, y) = (next() as usize % w, next() as usize % h);
        let (bw, bh) = (1 + next() as usize % 4, 1 + next() as usize % 4);
        for yy in y..(y + bh).min(h) {
            for xx in x..(x + bw).min(w) {
                m.set(xx, yy, true);
            }
        }
    }
    m
}

/// Component label per pixel by repeated neighbour-min propagation (slow, obviously correct).
fn reference_labels(m: &Mask, value: bool) -> Vec<usize> {
    let (w, h) = m.size();
    let mut id: Vec<usize> = (0..w * h)
        .map(|i| if m.data()[i] == value { i + 1 } else { 0 })
        .collect();
    loop {
        let mut changed = false;
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                if id[i] == 0 {
                    continue;
                }
                for ny in y.saturating_sub(1)..=(y + 1).min(h - 1) {
                    for nx in x.saturating_sub(1)..=(x + 1).min(w - 1) {
                        let j = ny * w + nx;
                        if id[j] != 0 && id[j] < id[i] {
                            id[i] = id[j];
                            changed = true;
                        }
                    }
                }
            }
        }
        if !changed {
            return id;
        }
    }
}

fn size_of(id: &[usize]) -> std::collections::HashMap<usize, usize> {
    let mut sizes = std::collections::HashMap::new();
    for &l in id.iter().filter(|&&l| l != 0) {
        *sizes.entry(l).or_insert(0) += 1;
    }
    sizes
}

#[test]
fn labelling_removal_and_filling_match_a_reference() {
    for seed in 1..6 {
        let m = random_mask(37, 29, seed, 30 + 10 * seed as u32);
        let (w, h) = m.size();
        for value in [true, false] {
            let id = reference_labels(&m, value);
            let comps = label_components(&m, value);
            assert_eq!(comps.count(), size_of(&id).len(), "seed {seed}");
            // Same partition: a one-to-one map between reference ids and labels.
            let mut to_label = std::collections::HashMap::new();
            let mut to_ref = std::collections::HashMap::new();
            for (i, &r) in id.iter().enumerate() {
                let l = comps.labels()[i];
                assert_eq!(r == 0, l == 0, "seed {seed}: pixel {i}");
                if r != 0 {
                    assert_eq!(*to_label.entry(r).or_insert(l), l, "seed {seed}");
                    assert_eq!(*to_ref.entry(l).or_insert(r), r, "seed {seed}");
                }
            }
        }
        let id = reference_labels(&m, true);
        let sizes = size_of(&id);
        let want = Mask::from_fn(w, h, |x, y| {
            let l = id[y * w + x];
            l != 0 && sizes[&l] >= 5
        });
        assert_eq!(remove_small_components(&m, 5), want, "seed {seed}");

        let holes = reference_labels(&m, false);
        let hole_sizes = size_of(&holes);
        let border: std::collections::HashSet<usize> = (0..w * h)
            .filter(|i| {
                let (x, y) = (i % w, i / w);
                x == 0 || y == 0 || x == w - 1 || y == h - 1
            })
            .map(|i| holes[i])
            .collect();
        let want = Mask::from_fn(w, h, |x, y| {
            let l = holes[y * w + x];
            m.get(x, y) || (!border.contains(&l) && hole_sizes[&l] < 4)
        });
        assert_eq!(fill_holes(&m, 4), want, "seed {seed}");
    }
}

#[test]
fn dilation_matches_iterated_3x3_dilation() {
    let m = random_mask(41, 23, 7, 3);
    let step = |m: &Mask| {
        let (w, h) = m.size();
        Mask::from_fn(w, h, |x, y| {
            (y.saturating_sub(1)..=(y + 1).min(h - 1))
                .any(|ny| (x.saturating_sub(1)..=(x + 1).min(w - 1)).any(|nx| m.get(nx, ny)))
        })
    };
    let mut it = m.clone();
    for r in 1..=4 {
        it = step(&it);
        assert_eq!(dilate_square(&m, r), it, "radius {r}");
    }
    assert_eq!(dilate_square(&m, 0), m);
}

#[test]
fn a_1024_mask_is_cleaned_in_milliseconds() {
    let m = random_mask(1024, 1024, 42, 40);
    let t = Instant::now();
    let removed = remove_small_components(&m, 1049);
    let filled = fill_holes(&removed, 1049);
    let dilated = dilate_square(&filled, 3);
    let elapsed = t.elapsed();
    eprintln!(
        "1024² removal + filling + dilation: {:.1} ms ({} → {} px)",
        elapsed.as_secs_f64() * 1e3,
        m.count(),
        dilated.count()
    );
    // Linear time: generous bound for a debug build on a loaded machine.
    assert!(elapsed.as_secs_f64() < 2.0, "{elapsed:?}");
    // One huge snake-shaped component: the labelling needs no recursion.
    let snake = Mask::from_fn(1024, 1024, |x, y| {
        y % 2 == 0 || (y % 4 == 1 && x == 1023) || (y % 4 == 3 && x == 0)
    });
    assert_eq!(label_components(&snake, true).count(), 1);
}

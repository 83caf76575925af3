//! Two DSMs compared on the cells both cover (`score --against`), on real data: s2p's DSMs of
//! the DFC2019 JAX_068 development pairs cut onto the truth's grid (`s2p/truth-grid/`), whose
//! scores the set's README lists (MAE filtered, coverage, within 1 m); and s2p's DSMs on their
//! own grid, which `score` cuts onto the truth's.

use camera::UtmZone;
use eval::score::{read_on_truth_grid, read_truth, score_dsm_file, score_versus_files};
use eval::Truth;

use testdata::jax;

fn truth() -> Truth {
    read_truth(
        &jax("truth/JAX_068_DSM.tif"),
        UtmZone::new(17, true).unwrap(),
    )
    .unwrap()
}

#[test]
fn an_s2p_dsm_against_itself_shares_every_cell_and_keeps_its_own_scores() {
    testdata::require!(testdata::JAX_DEV);
    let truth = truth();
    let s2p = jax("s2p/truth-grid/014-015.tif");
    let v = score_versus_files(&s2p, &s2p, &truth).unwrap();
    let alone = score_dsm_file(&s2p, &truth).unwrap();
    assert_eq!(v.ours, alone);
    assert_eq!(v.other, alone);
    assert_eq!(v.common_ours, v.common_other);
    assert_eq!(v.common_ours.mae, alone.mae_filtered);
    assert_eq!(v.common_ours.cells, alone.cells);
    assert_eq!((v.only_ours.cells, v.only_other.cells), (0, 0));
    // The set's README: 1.283 m, 71.1 % coverage, 60.5 % within 1 m, on s2p's own grid; the
    // cut onto the truth's grid (nearest cells) gives 1.324 m, 71.0 %, 60.3 %.
    let mae = alone.mae_filtered.unwrap();
    assert!((mae - 1.283).abs() < 0.05, "MAE {mae}");
    let coverage = alone.coverage.unwrap();
    assert!((coverage - 0.711).abs() < 0.01, "coverage {coverage}");
    let within = alone.within_1m.unwrap();
    assert!((within - 0.605).abs() < 0.02, "within 1 m {within}");
    assert!(alone.within_2m.unwrap() > within);
    // Every filtered truth cell is common or neither.
    let filtered_cells = truth
        .dsm
        .data()
        .iter()
        .zip(truth.exclusions.foliage.data())
        .filter(|(g, &f)| g.is_finite() && !f)
        .count();
    assert_eq!(v.common_ours.cells + v.neither, filtered_cells);
}

#[test]
fn two_s2p_dsms_split_the_truth_cells_and_their_maes_add_up() {
    testdata::require!(testdata::JAX_DEV);
    let truth = truth();
    let (near, cross) = (
        jax("s2p/truth-grid/013-014.tif"),
        jax("s2p/truth-grid/006-020.tif"),
    );
    let v = score_versus_files(&near, &cross, &truth).unwrap();
    // Each one's cells are its common and its own ones; its MAE is their weighted mean.
    for (own, common, scores) in [
        (v.only_ours, v.common_ours, &v.ours),
        (v.only_other, v.common_other, &v.other),
    ] {
        assert_eq!(own.cells + common.cells, scores.cells);
        let weighted = (own.mae.unwrap_or(0.0) * own.cells as f64
            + common.mae.unwrap() * common.cells as f64)
            / scores.cells as f64;
        assert!((weighted - scores.mae_filtered.unwrap()).abs() < 1e-9);
    }
    assert!(v.common_ours.cells > 100_000, "{v:?}");
    assert!(
        v.only_ours.cells > 1000 && v.only_other.cells > 1000,
        "{v:?}"
    );
    // The same-season pair beats the winter–summer one on the cells both cover (README: 0.98
    // against 1.73 m on their own cells).
    assert!(
        v.common_ours.mae.unwrap() + 0.3 < v.common_other.mae.unwrap(),
        "{v:?}"
    );
    // Swapping the two swaps the figures.
    let w = score_versus_files(&cross, &near, &truth).unwrap();
    assert_eq!((w.common_ours, w.only_ours), (v.common_other, v.only_other));
}

#[test]
fn s2p_dsms_on_their_own_grid_are_cut_onto_the_truth_s_as_the_set_s_truth_grid_copies() {
    testdata::require!(testdata::JAX_DEV);
    let truth = truth();
    let pairs: Vec<String> = std::fs::read_dir(jax("s2p"))
        .unwrap()
        .filter_map(|e| {
            let name = e.unwrap().file_name().into_string().unwrap();
            name.strip_suffix(".tif").map(str::to_owned)
        })
        .collect();
    assert_eq!(pairs.len(), 12, "{pairs:?}");
    for pair in &pairs {
        let native = jax(&format!("s2p/{pair}.tif"));
        let copy = jax(&format!("s2p/truth-grid/{pair}.tif"));
        let own = camera::DsmGrid::read(&native, None).unwrap();
        assert_ne!(own, truth.grid, "{pair}: s2p's grid is its own");
        // Cell for cell the set's copy (nearest cell, NaN outside).
        let cut = read_on_truth_grid(&native, &truth).unwrap();
        let expected = camera::read_dsm(&copy, None).unwrap().image;
        let same = |a: f32, b: f32| a == b || (a.is_nan() && b.is_nan());
        let differ = (cut.data().iter().zip(expected.data()))
            .filter(|(a, b)| !same(**a, **b))
            .count();
        assert_eq!(differ, 0, "{pair}: cells that differ from the copy");
        assert_eq!(
            score_dsm_file(&native, &truth).unwrap(),
            score_dsm_file(&copy, &truth).unwrap(),
            "{pair}"
        );
    }
    // Against another method, the native file stands for its copy too.
    let (native, copy) = (jax("s2p/014-015.tif"), jax("s2p/truth-grid/014-015.tif"));
    let other = jax("s2p/truth-grid/013-014.tif");
    assert_eq!(
        score_versus_files(&native, &other, &truth).unwrap(),
        score_versus_files(&copy, &other, &truth).unwrap()
    );
}

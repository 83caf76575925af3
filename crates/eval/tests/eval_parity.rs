//! Parity of `seasonstereo eval` with the benchmark's released evaluator, on recorded numbers.
//!
//! # What is compared
//!
//! Product disparities (seasonstereo's census + SGM, `seasonstereo predict --method sgm`) of five
//! real WorldView-3 pairs of the `data/dfc2019-jax068-dev` set (four of them larger than 1024 px,
//! hence centre-cropped) and of one procedural world pair are fixtures here. Both evaluators scored
//! exactly these disparities; this test runs seasonstereo's whole `eval` chain on them (layout,
//! crop, mask, triangulation with the bundle-adjusted RPCs read in place (see `testdata`), DSM on
//! the truth's grid, registration, the three MAEs) and asserts every MAE, shift and offset equals
//! the release's: MAE and offset to 1e-3 m, shifts exactly. Cases:
//! - `real`: the five pairs against `JAX_068_DSM.tif` + `.txt` + `_CLS.tif` as distributed;
//! - `water`: the same pairs with a synthetic `JAX_068_WATER.png` (fixture; 0 = water, 255 land,
//!   a disc and a band covering 13 % of the grid) beside that truth;
//! - `world`: `seasonstereo world --size 320 --seed 3`, whose `_CLS.tif` has water (9) and foliage
//!   (5), with a synthetic `WORLD_3_WATER.png` (a disc, 11 %); truth and cameras are fixtures.
//!
//! # Fixtures (`tests/fixtures/eval_parity/`)
//!
//! `<stem>.disparity.png`: the disparity of the (cropped) rectified pair as a 16-bit grey PNG,
//! `v = 0` for NaN, else `d = (v − 32768) / 16` (the SGM output rounded to 1/16 px; both
//! evaluators read the decoded values, which are exact in float32). `<stem>.npz`: the pair's
//! `Hleft`/`Hright` (raw → full rectified frame) from `seasonstereo rectify`. The full rectified
//! sizes are in [`FULL_SIZE`]; the test writes a placeholder left image of that size so the
//! centre crop is found as for the real pair.
//!
//! # How the reference numbers were produced
//!
//! Release: `multimedia-eurecat/SeasonStereo` at commit
//! 7b948142c69c945d063c11395415117628a9a1ad, `season_stereo/eval_test.py`, `utils/misc.py`,
//! `utils/dsmr.py`, `generate_table.py`, unmodified. Environment (outside this repository):
//! Debian 12, Python 3.11, GDAL 3.6.2 (Debian `python3-gdal`), numpy 1.26.4, numba 0.68.1,
//! rasterio 1.4.4, rpcm 1.4.10, pyproj 3.7.2, scipy 1.17.1, scikit-image 0.26.0, iio 29.
//!
//! 1. `seasonstereo rectify images/JAX_068_<L>_RGB.tif images/JAX_068_<R>_RGB.tif --rpc-left
//!    rpcs/ba/JAX_068_<L>_RGB.json --rpc-right rpcs/ba/JAX_068_<R>_RGB.json -o pairs` (main at
//!    c2a96ed), the images centre-cropped to ≤ 1024 px as `center_crop_if_large` does, then
//!    `seasonstereo predict --method sgm --range A:B` with the range rectify printed; the world
//!    pair: `seasonstereo world --size 320 --seed 3`, `predict --method sgm --range 1:45`.
//! 2. The release needs a georeferenced truth: `JAX_068_DSM.tif`'s values rewritten as a GeoTIFF
//!    with rasterio, `from_origin(E, N + 512·0.5, 0.5, 0.5)` from `JAX_068_DSM.txt`, EPSG:32617
//!    (no nodata, as the original), `_CLS.tif` copied beside it.
//! 3. A driver script imported `eval_test.py` (stubbing `torch`, `matplotlib`, `tqdm`,
//!    `thirdparty`, unused for scoring) and called `_save_pair_outputs_and_row(meta, disp, …,
//!    border_trim_k=32)` per pair with `meta["crop"]` from `center_crop_if_large` on the full
//!    rectified size, i.e. the release's own homography shift, double mask, trim, triangulation,
//!    rasterisation and its three `align_dsm_with_gt` calls. Recording wrappers around
//!    `misc.align_dsm_with_gt` and `dsmr.compute_shift` (they call the originals and log
//!    arguments and results) gave the full-precision MAEs and each call's `(dx, dy, a, b)`; a
//!    wrapper around `gdal.Warp` confirmed no reprojection happened.
//! 4. `generate_table.py --summary summary.csv` on the CSV that
//!    [`table_aggregation_matches_generate_table`] rebuilds, with `disparity/<pair>.iio` files
//!    holding the maxima listed there.
//!
//! The release's `compute_shift` returns the shift with which it SAMPLES the prediction
//! (`aligned(i, j) = pred(i + dx, j + dy) + b`); seasonstereo reports the shift APPLIED to the
//! prediction, its negation. [`Reference::shift`] keeps the release's sign.

use std::path::{Path, PathBuf};

use eval::aggregate::{aggregate, exceeds_disparity_limit};
use eval::records::{PairRecord, STATUS_DROPPED, STATUS_SCORED};
use eval::{evaluate, EvalOptions, Method, Protocol, Split};
use raster::Image;
use workflow::Silent;

const FIXTURES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/eval_parity");

/// Full rectified size (width, height) of each pair, as `seasonstereo rectify` wrote it.
const FULL_SIZE: [(&str, usize, usize); 6] = [
    ("JAX_068_003_RGB-JAX_068_004_RGB", 1258, 1122),
    ("JAX_068_004_RGB-JAX_068_013_RGB", 1117, 969),
    ("JAX_068_006_RGB-JAX_068_020_RGB", 1226, 1017),
    ("JAX_068_012_RGB-JAX_068_015_RGB", 1294, 1021),
    ("JAX_068_014_RGB-JAX_068_015_RGB", 986, 858),
    ("WORLD_3_A-WORLD_3_B", 320, 320),
];

/// The release's numbers for one pair.
struct Reference {
    case: &'static str,
    stem: &'static str,
    /// `mae`, `mae_no_water`, `mae_filtered`, metres.
    mae: [f64; 3],
    /// The release's `(dx, dy, b)` of `compute_shift` for each of the three scores.
    shift: [(i32, i32, f64); 3],
}

const REFERENCES: [Reference; 11] = [
    Reference {
        case: "real",
        stem: "JAX_068_003_RGB-JAX_068_004_RGB",
        mae: [1.1091703176498413, 1.1091703176498413, 1.079567790031433],
        shift: [
            (0, -1, 0.6338013296098541),
            (0, -1, 0.6338013296098541),
            (0, -1, 0.6631682968389168),
        ],
    },
    Reference {
        case: "real",
        stem: "JAX_068_004_RGB-JAX_068_013_RGB",
        mae: [1.4178353548049927, 1.4178353548049927, 1.3717666864395142],
        shift: [
            (0, -2, 0.7259573107217481),
            (0, -2, 0.7259573107217481),
            (0, -2, 0.7403775321386483),
        ],
    },
    Reference {
        case: "real",
        stem: "JAX_068_006_RGB-JAX_068_020_RGB",
        mae: [2.1995599269866943, 2.1995599269866943, 2.12078857421875],
        shift: [
            (-1, -1, 0.10923556519435529),
            (-1, -1, 0.10923556519435529),
            (0, 0, 0.13793707028901636),
        ],
    },
    Reference {
        case: "real",
        stem: "JAX_068_012_RGB-JAX_068_015_RGB",
        mae: [1.6393285989761353, 1.6393285989761353, 1.5746123790740967],
        shift: [
            (-1, -1, 0.508265330687431),
            (-1, -1, 0.508265330687431),
            (-1, -1, 0.521939309019622),
        ],
    },
    Reference {
        case: "real",
        stem: "JAX_068_014_RGB-JAX_068_015_RGB",
        mae: [1.0477055311203003, 1.0477055311203003, 1.0250009298324585],
        shift: [
            (-1, -1, 0.7136319603740766),
            (-1, -1, 0.7136319603740766),
            (-1, -1, 0.7167858249880794),
        ],
    },
    Reference {
        case: "water",
        stem: "JAX_068_003_RGB-JAX_068_004_RGB",
        mae: [1.1091703176498413, 1.1520118713378906, 1.123508095741272],
        shift: [
            (0, -1, 0.6338013296098541),
            (0, -1, 0.5768099858424822),
            (0, -1, 0.6060383690011601),
        ],
    },
    Reference {
        case: "water",
        stem: "JAX_068_004_RGB-JAX_068_013_RGB",
        mae: [1.4178353548049927, 1.493911623954773, 1.4425075054168701],
        shift: [
            (0, -2, 0.7259573107217481),
            (0, -2, 0.6758140258197844),
            (0, -2, 0.6901274518442477),
        ],
    },
    Reference {
        case: "water",
        stem: "JAX_068_006_RGB-JAX_068_020_RGB",
        mae: [2.1995599269866943, 2.0605509281158447, 1.961902141571045],
        shift: [
            (-1, -1, 0.10923556519435529),
            (-1, -1, 0.15490913148256347),
            (0, 0, 0.191442793125983),
        ],
    },
    Reference {
        case: "water",
        stem: "JAX_068_012_RGB-JAX_068_015_RGB",
        mae: [1.6393285989761353, 1.5476322174072266, 1.4689809083938599],
        shift: [
            (-1, -1, 0.508265330687431),
            (-1, -1, 0.5448681516825058),
            (-1, -1, 0.5607281478632444),
        ],
    },
    Reference {
        case: "water",
        stem: "JAX_068_014_RGB-JAX_068_015_RGB",
        mae: [1.0477055311203003, 1.0984117984771729, 1.07219660282135],
        shift: [
            (-1, -1, 0.7136319603740766),
            (-1, -1, 0.6807591463252702),
            (-1, -1, 0.6838330683754936),
        ],
    },
    Reference {
        case: "world",
        stem: "WORLD_3_A-WORLD_3_B",
        mae: [0.3152216970920563, 0.2760148346424103, 0.26036959886550903],
        shift: [
            (-1, 0, -0.08080889578018446),
            (-1, 0, -0.014236828108773913),
            (-1, 0, -0.03425646255923276),
        ],
    },
];

/// A fixture disparity: 16-bit PNG, 0 = NaN, else (v − 32768) / 16.
fn decode_disparity(path: &Path) -> Image {
    let q = raster::read_image(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .channel(0);
    let (w, h) = q.size();
    Image::from_fn(w, h, |x, y| {
        let v = q.get(x, y, 0);
        if v == 0.0 {
            f32::NAN
        } else {
            (v - 32768.0) / 16.0
        }
    })
}

/// A split folder for `stems` under `root`: a placeholder `L/<stem>.iio` of the full rectified
/// size, the homographies, and the decoded predictions in `<root>/preds`. Returns (split, preds).
fn layout(root: &Path, fixtures: &Path, stems: &[&str]) -> (PathBuf, PathBuf) {
    let (split, preds) = (root.join("split"), root.join("preds"));
    for d in ["L", "homography"] {
        std::fs::create_dir_all(split.join(d)).unwrap();
    }
    std::fs::create_dir_all(&preds).unwrap();
    for stem in stems {
        let &(_, w, h) = FULL_SIZE.iter().find(|s| s.0 == *stem).expect("a size");
        raster::write_image(
            split.join(format!("L/{stem}.iio")),
            &Image::filled(w, h, 1, 0.0),
        )
        .unwrap();
        std::fs::copy(
            fixtures.join(format!("{stem}.npz")),
            split.join(format!("homography/{stem}.npz")),
        )
        .unwrap();
        let d = decode_disparity(&fixtures.join(format!("{stem}.disparity.png")));
        raster::write_image(preds.join(format!("{stem}.iio")), &d).unwrap();
    }
    (split, preds)
}

/// Runs `eval --predictions` on the layout under `protocol` and returns the rows by stem order.
fn run(
    root: &Path,
    split: &Path,
    preds: &Path,
    rpc: &Path,
    truth: &Path,
    protocol: Protocol,
) -> Vec<PairRecord> {
    let mut opts = EvalOptions::new(
        vec![Split {
            name: "parity".into(),
            dir: split.to_path_buf(),
        }],
        rpc,
        truth,
        Method::Predictions(preds.to_path_buf()),
        root.join(format!("eval-{}", protocol.name())),
    );
    opts.protocol = protocol;
    let r = evaluate(&opts, &Silent).unwrap();
    assert_eq!(r.scored, r.records.len());
    r.records
}

/// Asserts one row equals the release's numbers; returns the largest |ΔMAE| and |Δoffset|.
fn check(row: &PairRecord, reference: &Reference) -> (f64, f64) {
    let who = format!("{} {}", reference.case, reference.stem);
    assert_eq!(row.status, STATUS_SCORED, "{who}: {row:?}");
    let ours = [
        (row.mae_raw, row.dx_raw, row.dy_raw, row.offset_raw),
        (
            row.mae_no_water,
            row.dx_no_water,
            row.dy_no_water,
            row.offset_no_water,
        ),
        (row.mae_filtered, row.dx, row.dy, row.offset),
    ];
    let (mut dm, mut db) = (0.0f64, 0.0f64);
    for (k, name) in ["mae", "mae_no_water", "mae_filtered"].iter().enumerate() {
        let (mae, dx, dy, offset) = ours[k];
        let (rdx, rdy, rb) = reference.shift[k];
        // The release samples pred(x + dx, y + dy); seasonstereo applies (dx, dy) to the pred.
        assert_eq!(
            (dx, dy),
            (Some(-rdx), Some(-rdy)),
            "{who} {name}: shift (release sign {rdx}, {rdy})"
        );
        let (m, b) = (mae.unwrap(), offset.unwrap());
        let (em, eb) = ((m - reference.mae[k]).abs(), (b - rb).abs());
        assert!(
            em <= 1e-3,
            "{who} {name}: {m} vs the release's {}",
            reference.mae[k]
        );
        assert!(eb <= 1e-3, "{who} {name}: offset {b} vs the release's {rb}");
        (dm, db) = (dm.max(em), db.max(eb));
    }
    let c = row.coverage.unwrap();
    assert!(c > 0.0 && c <= 1.0, "{who}: coverage {c}");
    (dm, db)
}

fn copy_into(dir: &Path, files: &[PathBuf]) {
    std::fs::create_dir_all(dir).unwrap();
    for f in files {
        std::fs::copy(f, dir.join(f.file_name().unwrap())).unwrap();
    }
}

#[test]
fn real_pairs_match_the_released_evaluator() {
    let dev = testdata::require!("data/dfc2019-jax068-dev");
    let fixtures = PathBuf::from(FIXTURES);
    let tmp = tempfile::tempdir().unwrap();
    let stems: Vec<&str> = FULL_SIZE[..5].iter().map(|s| s.0).collect();
    let (split, preds) = layout(tmp.path(), &fixtures, &stems);
    let rpc = dev.join("rpcs/ba");

    // The truth as distributed, read in place; then the same beside a _WATER.png.
    let water_truth = tmp.path().join("truth-water");
    let t = dev.join("truth");
    copy_into(
        &water_truth,
        &[
            t.join("JAX_068_DSM.tif"),
            t.join("JAX_068_DSM.txt"),
            t.join("JAX_068_CLS.tif"),
            fixtures.join("JAX_068_WATER.png"),
        ],
    );
    for (case, truth) in [("real", t.clone()), ("water", water_truth)] {
        let root = tmp.path().join(case);
        let rows = run(&root, &split, &preds, &rpc, &truth, Protocol::Release);
        assert_eq!(rows.len(), 5);
        for row in &rows {
            let reference = REFERENCES
                .iter()
                .find(|r| r.case == case && r.stem == row.stem)
                .expect("a reference");
            let (dm, db) = check(row, reference);
            println!(
                "{case} {}: |ΔMAE| ≤ {dm:.2e} m, |Δoffset| ≤ {db:.2e} m",
                row.stem
            );
        }
        if case == "real" {
            // No water in JAX_068: the no-water score is the raw one, registration included.
            for r in &rows {
                assert_eq!(r.mae_no_water, r.mae_raw);
                assert_eq!(r.offset_no_water, r.offset_raw);
            }
        }
    }

    // The robust protocol registers once: the three scores share the raw registration.
    let rows = run(
        &tmp.path().join("robust"),
        &split,
        &preds,
        &rpc,
        &t,
        Protocol::Robust,
    );
    for r in &rows {
        assert_eq!((r.dx, r.dy, r.offset), (r.dx_raw, r.dy_raw, r.offset_raw));
    }
    let a = rows
        .iter()
        .find(|r| r.stem == "JAX_068_006_RGB-JAX_068_020_RGB")
        .unwrap();
    // The release registers this pair's filtered score at another shift.
    assert_ne!((a.dx, a.dy), (Some(0), Some(0)));
}

#[test]
fn world_with_water_classes_and_mask_matches_the_released_evaluator() {
    let fixtures = PathBuf::from(FIXTURES).join("world");
    let tmp = tempfile::tempdir().unwrap();
    let stem = "WORLD_3_A-WORLD_3_B";
    let (split, preds) = layout(tmp.path(), &fixtures, &[stem]);
    let rows = run(
        tmp.path(),
        &split,
        &preds,
        &fixtures.join("rpc"),
        &fixtures.join("truth"),
        Protocol::Release,
    );
    let reference = REFERENCES.iter().find(|r| r.case == "world").unwrap();
    let (dm, db) = check(&rows[0], reference);
    println!("world: |ΔMAE| ≤ {dm:.2e} m, |Δoffset| ≤ {db:.2e} m");
    // Water and foliage change both the score and its registration.
    let r = &rows[0];
    assert!(r.mae_filtered < r.mae_no_water && r.mae_no_water < r.mae_raw);
    assert_ne!(r.offset_raw, r.offset_no_water);
}

/// The rows of the constructed `summary.csv` given to `generate_table.py`: (split, AOI, pair
/// MAE, ground-truth disparity maximum: `Some(v)` a file whose largest value is v, `Some(NaN)`
/// a file that is NaN everywhere, `None` no file). `Err` rows are errors (not aggregated).
#[allow(clippy::type_complexity)]
fn constructed_summary() -> Vec<(&'static str, &'static str, Result<f64, ()>, Option<f32>)> {
    let mut rows = Vec::new();
    for (split, aoi, maes) in [
        ("jax", "JAX_004", &[1.20, 0.95, 1.61][..]),
        ("jax", "JAX_068", &[2.05, 1.10]),
        ("jax", "JAX_214", &[0.80]),
        ("buenos_aires", "IARPA_001", &[1.5, 1.7, 1.3, 2.2]),
        ("buenos_aires", "IARPA_002", &[0.9]),
    ] {
        for &m in maes {
            rows.push((split, aoi, Ok(m), None));
        }
    }
    rows.push(("jax", "JAX_068", Err(()), None));
    for (split, aoi, m, g) in [
        ("omaha_synchronic", "OMA_084", 1.0, Some(100.0)),
        ("omaha_synchronic", "OMA_084", 3.0, Some(250.0)),
        ("omaha_synchronic", "OMA_084", 1.4, Some(-300.0)),
        ("omaha_synchronic", "OMA_132", 2.5, Some(192.0)),
        ("omaha_synchronic", "OMA_132", 0.7, Some(192.5)),
        ("omaha_synchronic", "OMA_132", 0.6, Some(f32::INFINITY)),
        ("omaha_synchronic", "OMA_132", 1.1, Some(50.0)),
        ("omaha_diachronic", "OMA_212", 1.9, None),
        ("omaha_diachronic", "OMA_212", 2.3, Some(f32::NAN)),
        ("omaha_diachronic", "OMA_212", 1.2, Some(10.0)),
    ] {
        rows.push((split, aoi, Ok(m), g));
    }
    rows
}

#[test]
fn table_aggregation_matches_generate_table() {
    // generate_table.py's output on that CSV (comparison_table_v2.csv): per split mean, sample
    // std (None = nan), AOIs, pairs kept, Omaha pairs dropped by the 192-px rule.
    let expected = [
        ("jax", 1.191667, Some(0.387567), 3, 6, 0),
        ("buenos_aires", 1.250000, Some(0.494975), 2, 5, 0),
        ("omaha_synchronic", 1.500000, Some(0.424264), 2, 4, 3),
        ("omaha_diachronic", 1.550000, None, 1, 2, 1),
    ];
    let mut records = Vec::new();
    for (i, (split, aoi, mae, gt_max)) in constructed_summary().into_iter().enumerate() {
        // The Omaha rule as `eval` applies it: on the ground-truth disparity file, if any.
        let omaha = split.starts_with("omaha");
        let dropped = omaha
            && gt_max.is_some_and(|g| {
                // A 4×4 disparity of 5 px with a NaN and the maximum (or NaN everywhere).
                let mut d = Image::filled(4, 4, 1, 5.0);
                d.set(0, 0, 0, f32::NAN);
                if g.is_nan() {
                    d = Image::filled(4, 4, 1, f32::NAN);
                } else {
                    d.set(2, 1, 0, g);
                }
                exceeds_disparity_limit(&d, 192.0).0
            });
        let status = match (mae, dropped) {
            (Err(()), _) => "error".to_string(),
            (_, true) => STATUS_DROPPED.to_string(),
            _ => STATUS_SCORED.to_string(),
        };
        let m = mae.ok();
        records.push(PairRecord {
            mae_raw: m,
            mae_no_water: m,
            mae_filtered: m,
            ..PairRecord::unscored(split, &format!("{aoi}_{i}-{aoi}_x"), aoi, "M", &status)
        });
    }
    let table = aggregate(&records);
    assert_eq!(table.rows.len(), 1);
    let row = &table.rows[0];
    for (split, mean, std, n_aoi, n_ok, n_dropped) in expected {
        let col = table
            .columns
            .iter()
            .position(|c| c.key == eval::layout::canonical_split(split).unwrap())
            .unwrap();
        let s = row.splits[col].as_ref().unwrap();
        assert!(
            (s.mean - mean).abs() < 1e-6,
            "{split}: {} vs {mean}",
            s.mean
        );
        match std {
            Some(v) => assert!((s.std.unwrap() - v).abs() < 1e-6, "{split}: {:?}", s.std),
            None => assert!(s.std.is_none(), "{split}"),
        }
        assert_eq!((s.aois.len(), s.pairs), (n_aoi, n_ok), "{split}");
        let dropped = records
            .iter()
            .filter(|r| r.split == split && r.status == STATUS_DROPPED)
            .count();
        assert_eq!(dropped, n_dropped, "{split}");
    }
    // The paper's average over the four splits (not printed by generate_table.py).
    let avg = (1.191667 + 1.25 + 1.5 + 1.55) / 4.0;
    assert!((row.average.unwrap() - avg).abs() < 1e-6);
}

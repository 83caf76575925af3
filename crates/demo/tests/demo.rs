//! The demo end to end at its default size: the story it tells (four seasons, a synchronic and a
//! winter ↔ summer pair, two DSMs scored against the truth) and its accuracy on the synchronic pair;
//! and a drastically reduced `demo --ablation`.

use std::path::Path;

#[cfg(feature = "network")]
use demo::ablation::{run_ablation, AblationOptions, CROSS_SEASON, SYNCHRONIC};
use demo::{run_demo, DemoOptions, DemoSummary};
use matching::SgmParams;
use workflow::Silent;

fn run(dir: &Path, size: usize) -> DemoSummary {
    let opts = DemoOptions {
        size,
        seed: 1,
        out_dir: dir.to_path_buf(),
        sgm: SgmParams::default(),
    };
    run_demo(&opts, &Silent).unwrap()
}

/// Every `src="…"` of the page.
fn sources(html: &str) -> Vec<String> {
    html.split("src=\"")
        .skip(1)
        .map(|s| s.split('"').next().unwrap().to_string())
        .collect()
}

#[test]
fn demo_tells_the_season_story_and_keeps_its_accuracy() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path();
    let s = run(out, 512);

    // The synchronic pair keeps the demo's acceptance on pixels visible in both views.
    let v = &s.visible;
    let (mae, bad2) = (v.mae.unwrap(), v.bad2.unwrap());
    assert!(mae <= 0.25, "synchronic MAE {mae} px");
    assert!(bad2 <= 0.015, "synchronic bad-2 {bad2}");
    assert!(v.coverage.unwrap() > 0.9, "coverage {:?}", v.coverage);

    // Both pairs have finite disparity and altitude scores; the DSMs are real rasters.
    assert_eq!(s.pairs.len(), 2);
    let (sync, cross) = (&s.pairs[0], &s.pairs[1]);
    assert_eq!(sync.visible, s.visible);
    for p in &s.pairs {
        let d = &p.dsm.scores;
        for (what, x) in [
            ("disparity MAE", p.visible.mae),
            ("bad-2", p.visible.bad2),
            ("DSM MAE filtered", d.mae_filtered),
            ("DSM MAE raw", d.mae_raw),
            ("DSM coverage", d.coverage),
        ] {
            assert!(x.is_some_and(f64::is_finite), "{}: {what} {x:?}", p.name);
        }
        assert!(
            d.coverage.unwrap() > 0.5,
            "{}: coverage {:?}",
            p.name,
            d.coverage
        );
        assert!(d.cells > 1000, "{}: {} cells", p.name, d.cells);
        let (ground, building) = (&p.dsm.by_class[0], &p.dsm.by_class[1]);
        assert_eq!(
            (ground.0.as_str(), building.0.as_str()),
            ("ground", "building")
        );
        assert!(ground.1.is_some_and(f64::is_finite) && building.1.is_some_and(f64::is_finite));
        let tif = raster::formats::read_tiff(&p.dsm.path).unwrap();
        assert!(
            tif.georef.is_some(),
            "{} is georeferenced",
            p.dsm.path.display()
        );
    }
    // The synchronic DSM is accurate (the chain alone is exact to centimetres); the seasons make
    // the cross-season pair harder, never easier by much.
    let (ms, mc) = (
        sync.dsm.scores.mae_filtered.unwrap(),
        cross.dsm.scores.mae_filtered.unwrap(),
    );
    assert!(ms < 1.0, "synchronic DSM MAE {ms} m");
    assert!(mc > 0.8 * ms, "cross-season {mc} m vs synchronic {ms} m");

    // The report: four season thumbnails, both pairs, both DSMs, the table, the commands.
    let html = std::fs::read_to_string(&s.report).unwrap();
    for season in ["summer", "autumn", "winter", "spring"] {
        let thumb = format!("seasons/left_{season}_thumb.png");
        assert!(html.contains(&thumb), "report lacks {thumb}");
    }
    for needle in [
        "left_winter.png",
        "right_summer.png",
        "dsm_truth.png",
        "dsm_synchronic.png",
        "dsm_cross_season.png",
        "dsm_error_synchronic.png",
        "dsm_error_cross_season.png",
        "DSM MAE (filtered)",
        "DSM coverage",
        "<td>synchronic</td>",
        "<td>winter ↔ summer</td>",
        "<svg",
        "Timings",
        "seasonstereo reconstruct LEFT.tif RIGHT.tif",
        "seasonstereo eval --world",
        "seasonstereo score",
    ] {
        assert!(html.contains(needle), "report lacks {needle}");
    }
    let row = html
        .split("<tr>")
        .find(|r| r.starts_with("<td>winter ↔ summer</td>"))
        .unwrap();
    assert!(row.contains(&format!("{mc:.3} m")), "{row}");
    for debug in ["Some(", "None", "{:?}", "Paths::", "Eight", "Mgm"] {
        assert!(!html.contains(debug), "debug text {debug:?} in the report");
    }
    // Self-contained: every image lies beside the report, nothing is fetched.
    let srcs = sources(&html);
    assert!(srcs.len() >= 19, "{srcs:?}");
    for src in &srcs {
        assert!(!src.contains("://"), "{src}");
        let img = raster::read_image(out.join(src)).unwrap();
        assert!(img.width() > 0 && img.height() > 0, "{src}");
    }
    let links = html.replace("xmlns=\"http://www.w3.org/2000/svg\"", "");
    assert!(!links.contains("http"), "the report links outside itself");
    assert!(!html.contains("<script") && !html.contains("<link"));
}

/// A drastically reduced `demo --ablation` (one 128² world per role, 2 steps a run; the full run
/// is measured in BENCHMARKS.md): S1 and S3 start from the same weights and seed and train on
/// different lists, every method is scored on both held-out splits, and the report holds the
/// table, the curves and no debug text.
#[test]
#[cfg(feature = "network")]
fn ablation_trains_s1_and_s3_on_different_data_and_reports_the_table() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path();
    let mut opts = AblationOptions::new(out);
    opts.size = 128;
    opts.train_worlds = 1;
    opts.val_worlds = 1;
    opts.heldout_worlds = 1;
    opts.steps = 2;
    opts.validate_every = 2;
    opts.valid_pairs = 1;
    let s = run_ablation(&opts, &Silent).unwrap();

    // Same initialisation and seed, different training data.
    let (s1, s3) = (&s.runs[0], &s.runs[1]);
    assert_eq!(s1.config.model.init, s3.config.model.init);
    assert_eq!(s1.config.run.seed, s3.config.run.seed);
    assert_eq!(s1.config.run.steps, s3.config.run.steps);
    assert!(s1.config.model.init.as_ref().unwrap().is_file());
    let list = |c: &train::TrainConfig| {
        let name = c.data.experiment.clone().unwrap();
        std::fs::read_to_string(c.data.root.join(format!("experiments/{name}.csv"))).unwrap()
    };
    let (l1, l3) = (list(&s1.config), list(&s3.config));
    assert_ne!(l1, l3);
    assert!(!l1.contains("__"), "S1 holds real pairs only:\n{l1}");
    assert!(
        l1.lines().skip(1).all(|row| l3.contains(row)),
        "S3 extends S1"
    );
    let c = &s3.samples;
    assert!(c.real == s1.samples.total && c.synchronic_synthetic > 0 && c.diachronic > 0);
    // The shared weights score the same before training; the runs then see different batches.
    assert_eq!(s1.validations[0].scores.epe, s3.validations[0].scores.epe);
    assert_eq!((s1.steps.len(), s3.validations.len()), (2, 2));
    assert!(s1
        .steps
        .iter()
        .chain(&s3.steps)
        .all(|r| r.terms.total.is_finite()));
    assert_ne!(s1.steps[1].terms.total, s3.steps[1].terms.total);

    // The table: the classical matcher and both networks, both held-out splits; the classical
    // matcher's numbers are finite (2 steps from random weights may leave a network without a
    // single triangulated pixel: recorded as "no overlap", shown as "–").
    let methods: Vec<&str> = s.table.rows.iter().map(|r| r.method.as_str()).collect();
    assert_eq!(methods, [s.classical.as_str(), &s1.name, &s3.name]);
    let columns: Vec<&str> = s.table.columns.iter().map(|c| c.title.as_str()).collect();
    assert_eq!(columns, [SYNCHRONIC, CROSS_SEASON]);
    for cell in &s.table.rows[0].splits {
        let cell = cell.as_ref().unwrap();
        assert!(cell.mean.is_finite() && cell.mean < 2.0, "{cell:?}");
        assert!(cell.coverage.is_some_and(|c| c > 0.1), "{cell:?}");
    }
    assert_eq!(s.records.len(), 3 * 2);
    for r in &s.records {
        assert!(
            r.status == "no_overlap" || r.mae_filtered.is_some_and(f64::is_finite),
            "{r:?}"
        );
    }

    let html = std::fs::read_to_string(&s.report).unwrap();
    for needle in [
        "DSM MAE",
        "<td>S1 (real only)</td>",
        "<polyline",
        "validation EPE",
        "What this shows, and what it does not",
        "seasonstereo demo --ablation",
        "Timings",
    ] {
        assert!(html.contains(needle), "report lacks {needle}");
    }
    let mae = s.table.rows[0].splits[1].as_ref().unwrap().mean;
    assert!(
        html.contains(&format!("{mae:.2}")),
        "the cross-season MAE of the table"
    );
    for debug in ["Some(", "None", "{:?}", "NaN", "inf "] {
        assert!(!html.contains(debug), "debug text {debug:?} in the report");
    }
    for src in sources(&html) {
        assert!(!src.contains("://"), "{src}");
        let img = raster::read_image(out.join(&src)).unwrap();
        assert!(img.width() > 0, "{src}");
    }
}

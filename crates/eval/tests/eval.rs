//! The evaluation protocol: registration, scores, aggregation, the Omaha rule, the whole chain on
//! a procedural world, resumability and errors.

use std::path::Path;

use eval::aggregate::{exceeds_disparity_limit, mean_std, median, SplitStat};
use eval::metrics::water_from_png;
use eval::records::{read_records, STATUS_DROPPED, STATUS_NO_OVERLAP, STATUS_SCORED};
use eval::{
    aggregate, align, evaluate, score_dsm, AlignParams, EvalOptions, Exclusions, Method,
    PairRecord, Protocol, ScoreParams,
};
use raster::{Image, Mask};
use workflow::Silent;

/// A DSM with relief at several scales (so NCC has a clear peak) and some NaN holes.
fn synthetic_dsm(w: usize, h: usize) -> Image {
    Image::from_fn(w, h, |x, y| {
        let (xf, yf) = (x as f32, y as f32);
        // Blocks of random heights (no periodic pattern that a shift could map onto itself).
        let (bx, by) = ((x / 12) as u64, (y / 10) as u64);
        let hash = ((bx * 0x9E37_79B9) ^ (by * 0x85EB_CA6B)).wrapping_mul(0xC2B2_AE35) >> 7;
        let building = (hash % 4) as f32 * 4.0;
        let v = 3.0 * (xf * 0.11).sin() * (yf * 0.07).cos() + 0.02 * xf + building;
        if (x * 7 + y * 13) % 31 == 0 {
            f32::NAN
        } else {
            v
        }
    })
}

#[test]
fn alignment_recovers_a_known_shift_and_offset() {
    let (w, h) = (160, 120);
    let gt = synthetic_dsm(w, h);
    // aligned(x, y) = pred(x − 3, y + 2) + b must equal gt(x, y):
    // pred(x, y) = gt(x + 3, y − 2) − 1.7, with holes of its own.
    let pred = Image::from_fn(w, h, |x, y| {
        let (sx, sy) = (x as i64 + 3, y as i64 - 2);
        if sx < 0 || sy < 0 || sx >= w as i64 || sy >= h as i64 || (x * 3 + y) % 17 == 0 {
            f32::NAN
        } else {
            gt.get(sx as usize, sy as usize, 0) - 1.7
        }
    });
    for params in [AlignParams::release(), AlignParams::robust()] {
        let a = align(&gt, &pred, &params).unwrap();
        assert_eq!((a.dx, a.dy), (3, -2), "{a:?}");
        assert!((a.offset - 1.7).abs() < 1e-4, "offset {}", a.offset);
        assert!(a.ncc.unwrap() > 0.999);
    }

    let s = score_dsm(&pred, &gt, &Exclusions::none(w, h), &ScoreParams::default()).unwrap();
    assert_eq!((s.filtered.dx, s.filtered.dy), (Some(3), Some(-2)));
    assert_eq!(
        s.raw, s.filtered,
        "nothing masked: the same registration and MAE"
    );
    assert!(s.filtered.mae.unwrap() < 1e-4, "{s:?}");
    assert!(s.coverage.unwrap() > 0.8 && s.coverage.unwrap() < 1.0);

    // A larger shift is found through the pyramid (beyond one level's ±5 window).
    let pred = Image::from_fn(w, h, |x, y| {
        let (sx, sy) = (x as i64 - 9, y as i64 + 7);
        if sx < 0 || sy < 0 || sx >= w as i64 || sy >= h as i64 {
            f32::NAN
        } else {
            gt.get(sx as usize, sy as usize, 0) + 0.5
        }
    });
    for params in [AlignParams::release(), AlignParams::robust()] {
        let a = align(&gt, &pred, &params).unwrap();
        assert_eq!((a.dx, a.dy), (-9, 7), "{a:?}");
        assert!((a.offset + 0.5).abs() < 1e-4);
    }
}

#[test]
fn each_score_registers_on_its_own_masked_truth() {
    // The prediction is the truth raised by 1 m, and by 5 m over a "water" block: the release
    // masks the water BEFORE registering, so the no-water offset is exactly −1 m and its MAE
    // vanishes; registered once on the whole truth (robust), the offset is pulled by the water
    // and every cell keeps an error.
    let (w, h) = (160, 120);
    let gt = synthetic_dsm(w, h);
    let is_water = |x: usize, y: usize| (40..80).contains(&x) && (30..70).contains(&y);
    let pred = Image::from_fn(w, h, |x, y| {
        gt.get(x, y, 0) + if is_water(x, y) { 5.0 } else { 1.0 }
    });
    // _WATER.png: zero is water.
    let png = Image::from_fn(w, h, |x, y| if is_water(x, y) { 0.0 } else { 255.0 });
    let classes = Image::filled(w, h, 1, 2.0);
    let ex = Exclusions::from_classes(&classes, Some(&water_from_png(&png)));
    assert_eq!(ex.water.count(), 40 * 40);

    let s = score_dsm(&pred, &gt, &ex, &Protocol::Release.score_params()).unwrap();
    let (raw, nw) = (s.raw, s.no_water);
    assert_eq!(
        (raw.dx, raw.dy, nw.dx, nw.dy),
        (Some(0), Some(0), Some(0), Some(0))
    );
    let share = raw.offset.unwrap() + 1.0;
    assert!(
        share < -0.27 && share > -0.4,
        "raw offset pulled by the water: {raw:?}"
    );
    assert!((nw.offset.unwrap() + 1.0).abs() < 1e-5, "{nw:?}");
    assert!(nw.mae.unwrap() < 1e-5 && raw.mae.unwrap() > 0.5, "{s:?}");
    assert_eq!(
        s.filtered, nw,
        "no foliage: the filtered score is the no-water one"
    );

    let r = score_dsm(&pred, &gt, &ex, &Protocol::Robust.score_params()).unwrap();
    assert_eq!(r.no_water.offset, r.raw.offset);
    assert!(
        (r.no_water.mae.unwrap() - share.abs()).abs() < 1e-4,
        "{r:?}"
    );
}

#[test]
fn scores_on_hand_made_rasters() {
    // 3×2 cells, too few for a shift search: shift (0, 0), offset from the shared cells.
    let n = f32::NAN;
    let gt = Image::new(3, 2, 1, vec![1.0, 2.0, 3.0, 4.0, 5.0, n]).unwrap();
    let pred = Image::new(3, 2, 1, vec![1.0, 2.0, n, 4.0, 9.0, 9.0]).unwrap();
    // Shared cells 0, 1, 3, 4: offset = (12 − 16) / 4 = −1; aligned 0, 1, 3, 8; errors 1, 1, 1, 3.
    let classes = Image::new(3, 2, 1, vec![9.0, 2.0, 2.0, 2.0, 5.0, 2.0]).unwrap();
    // One registration for the three scores (robust protocol), so the masks only select cells.
    let params = Protocol::Robust.score_params();
    let ex = Exclusions::from_classes(&classes, None);
    let s = score_dsm(&pred, &gt, &ex, &params).unwrap();
    assert_eq!((s.filtered.dx, s.filtered.dy), (Some(0), Some(0)));
    assert!((s.filtered.offset.unwrap() + 1.0).abs() < 1e-12);
    assert!((s.raw.mae.unwrap() - 1.5).abs() < 1e-9, "{s:?}");
    // Without the water cell 0: errors 1, 1, 3.
    assert!((s.no_water.mae.unwrap() - 5.0 / 3.0).abs() < 1e-9);
    // Without water and foliage (cell 4): errors 1, 1.
    assert!((s.filtered.mae.unwrap() - 1.0).abs() < 1e-9);
    assert_eq!(s.filtered.cells, 2);
    // 4 of the 5 finite ground-truth cells have a prediction.
    assert!((s.coverage.unwrap() - 0.8).abs() < 1e-12);

    // A _WATER.png mask adds water cells: cell 1 too → filtered over cell 3 alone (error 1),
    // no-water over cells 3 and 4 (errors 1, 3).
    let water = Mask::new(3, 2, vec![false, true, false, false, false, false]).unwrap();
    let ex = Exclusions::from_classes(&classes, Some(&water));
    let s = score_dsm(&pred, &gt, &ex, &params).unwrap();
    assert!((s.no_water.mae.unwrap() - 2.0).abs() < 1e-9);
    assert!((s.filtered.mae.unwrap() - 1.0).abs() < 1e-9);
    assert_eq!(s.filtered.cells, 1);

    // Size mismatches are errors, not panics.
    assert!(score_dsm(&Image::filled(2, 2, 1, 0.0), &gt, &ex, &params).is_err());
}

#[test]
fn empty_overlap_is_a_clear_result() {
    let (w, h) = (40, 40);
    let gt = Image::from_fn(w, h, |x, y| if x < 10 { (x + y) as f32 } else { f32::NAN });
    let pred = Image::from_fn(w, h, |x, y| if x >= 30 { (x * y) as f32 } else { f32::NAN });
    assert!(align(&gt, &pred, &AlignParams::default()).is_none());
    let s = score_dsm(&pred, &gt, &Exclusions::none(w, h), &ScoreParams::default()).unwrap();
    assert!(s.no_overlap());
    assert_eq!(
        (s.raw.mae, s.filtered.mae, s.filtered.offset),
        (None, None, None)
    );
    assert_eq!(s.coverage, Some(0.0));
    // Nothing at all, on either side.
    let empty = Image::filled(w, h, 1, f32::NAN);
    let s = score_dsm(
        &empty,
        &empty,
        &Exclusions::none(w, h),
        &ScoreParams::default(),
    )
    .unwrap();
    assert!(s.no_overlap() && s.coverage.is_none());
}

fn row(split: &str, aoi: &str, method: &str, status: &str, mae: Option<f64>) -> PairRecord {
    let stem = format!("{aoi}_{}-{aoi}_x", mae.unwrap_or(-1.0));
    PairRecord {
        mae_raw: mae,
        mae_no_water: mae,
        mae_filtered: mae,
        coverage: Some(0.9),
        dx: Some(0),
        dy: Some(0),
        offset: Some(0.0),
        dx_raw: Some(0),
        dy_raw: Some(0),
        offset_raw: Some(0.0),
        dx_no_water: Some(0),
        dy_no_water: Some(0),
        offset_no_water: Some(0.0),
        pixels: 10,
        cells: 10,
        ..PairRecord::unscored(split, &stem, aoi, method, status)
    }
}

#[test]
fn aggregation_median_per_aoi_sample_std_and_average() {
    assert_eq!(median(&[3.0, 1.0, 2.0]), Some(2.0));
    assert_eq!(median(&[4.0, 1.0, 2.0, 3.0]), Some(2.5));
    assert_eq!(median(&[]), None);
    let (m, s) = mean_std(&[2.0, 4.0, 9.0]);
    assert_eq!(m, Some(5.0));
    // Sample std: sqrt((9 + 1 + 16) / 2) = sqrt(13).
    assert!((s.unwrap() - 13f64.sqrt()).abs() < 1e-12);
    assert_eq!(mean_std(&[1.5]), (Some(1.5), None));

    let s = "Jacksonville";
    let records = vec![
        row(s, "JAX_1", "M", STATUS_SCORED, Some(1.0)),
        row(s, "JAX_1", "M", STATUS_SCORED, Some(10.0)),
        row(s, "JAX_1", "M", STATUS_SCORED, Some(2.0)),
        row(s, "JAX_2", "M", STATUS_SCORED, Some(3.0)),
        row(s, "JAX_2", "M", STATUS_SCORED, Some(5.0)),
        // Neither a dropped pair nor a pair without overlap counts.
        row(s, "JAX_2", "M", STATUS_DROPPED, Some(100.0)),
        row(s, "JAX_2", "M", STATUS_NO_OVERLAP, None),
        row("omaha-sync", "OMA_1", "M", STATUS_SCORED, Some(1.0)),
        row("Omaha Diach.", "OMA_2", "Other", STATUS_SCORED, Some(0.5)),
    ];
    let t = aggregate(&records);
    let titles: Vec<&str> = t.columns.iter().map(|c| c.title.as_str()).collect();
    assert_eq!(
        titles,
        [
            "Jacksonville",
            "Buenos Aires",
            "Omaha Synch.",
            "Omaha Diach."
        ]
    );
    assert_eq!(t.rows.len(), 2);
    let m = &t.rows[0];
    assert_eq!(m.method, "M");
    // Medians per AOI: JAX_1 → 2, JAX_2 → 4; mean 3, sample std sqrt(2).
    let jax = m.splits[0].as_ref().unwrap();
    assert_eq!(
        jax.aois,
        vec![("JAX_1".into(), 2.0, 3), ("JAX_2".into(), 4.0, 2)]
    );
    assert!((jax.mean - 3.0).abs() < 1e-12);
    assert!((jax.std.unwrap() - 2f64.sqrt()).abs() < 1e-12);
    assert!(m.splits[1].is_none());
    let oma = m.splits[2].as_ref().unwrap();
    assert_eq!((oma.mean, oma.std), (1.0, None));
    assert!((m.average.unwrap() - 2.0).abs() < 1e-12);
    assert_eq!(t.rows[1].average, Some(0.5));
    let text = t.to_text();
    assert!(text.contains("3.00 ± 1.41"), "{text}");
    assert!(text.contains("1.00 ± –") && text.contains("2.00"), "{text}");
    let md = t.to_markdown();
    assert!(
        md.contains("| M | 3.00 ± 1.41 | – | 1.00 ± – | – | 2.00 |"),
        "{md}"
    );
    assert!(SplitStat::from_pairs(&[]).is_none());
    // Coverage is printed beside the MAE (every constructed row covers 90 %).
    assert_eq!(jax.coverage, Some(0.9));
    assert!(
        md.contains("| M (coverage) | 90.0 % | – | 90.0 % | – |  |"),
        "{md}"
    );
    assert!(
        text.contains("M (coverage)") && text.contains("90.0 %"),
        "{text}"
    );
}

#[test]
fn omaha_rule_drops_pairs_over_192_px() {
    let d = |v: f32| Image::new(3, 1, 1, vec![f32::NAN, 10.0, v]).unwrap();
    assert_eq!(
        exceeds_disparity_limit(&d(192.0), 192.0),
        (false, Some(192.0))
    );
    assert_eq!(
        exceeds_disparity_limit(&d(192.5), 192.0),
        (true, Some(192.5))
    );
    // The release's rule is np.nanmax(d) > 192, signed: a large negative disparity stays, an
    // infinite one goes, and so does a disparity that is NaN everywhere (its nanmax is NaN).
    assert_eq!(
        exceeds_disparity_limit(&d(-200.0), 192.0),
        (false, Some(10.0))
    );
    assert!(exceeds_disparity_limit(&d(f32::INFINITY), 192.0).0);
    let none = Image::filled(2, 2, 1, f32::NAN);
    assert_eq!(exceeds_disparity_limit(&none, 192.0), (true, None));
}

fn make_world(dir: &Path, size: usize, seed: u64) -> String {
    let world = world::generate(
        &world::WorldParams::new(size, seed),
        &world::Neutral,
        &|_, _| {},
    )
    .unwrap();
    let paths = eval::world_io::save_world(&world, dir, &format!("WORLD_{seed}")).unwrap();
    paths.stem
}

#[test]
fn world_ground_truth_and_sgm_through_the_whole_chain() {
    let tmp = tempfile::tempdir().unwrap();
    let wdir = tmp.path().join("world");
    let stem = make_world(&wdir, 224, 5);
    assert!(wdir.join("truth/WORLD_5_DSM.tif").is_file());
    assert!(wdir.join("truth/WORLD_5_CLS.tif").is_file());
    let out = tmp.path().join("eval");

    let gt_opts = EvalOptions::world(&wdir, "World", Method::GroundTruth, &out);
    let r = evaluate(&gt_opts, &Silent).unwrap();
    assert_eq!((r.scored, r.skipped, r.dropped), (1, 0, 0));
    let g = r.records[0].clone();
    assert_eq!(
        (g.stem.as_str(), g.aoi.as_str()),
        (stem.as_str(), "WORLD_5")
    );
    let mae = g.mae_filtered.unwrap();
    println!("world GT disparity: {g:?}");
    assert!(mae < 0.05, "chain error {mae} m");
    assert_eq!((g.dx, g.dy), (Some(0), Some(0)));
    assert!(g.offset.unwrap().abs() < 0.05);
    assert!(g.coverage.unwrap() > 0.3, "{g:?}");
    assert!(g.mae_raw.unwrap() < 0.05);

    let sgm_opts = EvalOptions::world(
        &wdir,
        "World",
        Method::Matcher(workflow::matcher::Matcher::Classical(
            matching::SgmParams::default(),
        )),
        &out,
    );
    let r = evaluate(&sgm_opts, &Silent).unwrap();
    assert_eq!((r.scored, r.skipped), (1, 0));
    let s = r.records[1].clone();
    println!("world SGM: {s:?}");
    let (mae_s, cov_s) = (s.mae_filtered.unwrap(), s.coverage.unwrap());
    assert!(mae_s.is_finite() && mae_s > mae && mae_s < 5.0, "{s:?}");
    assert!(cov_s > 0.2 && cov_s <= 1.0, "{s:?}");
    let text = r.table.to_text();
    println!("{text}");
    // The classical matcher's row is named by its aggregation (MGM by default).
    let sgm_name = sgm_opts.method_name.clone();
    assert!(sgm_name.ends_with("GM (census)"), "{sgm_name}");
    assert!(text.contains("ground-truth disparity") && text.contains(&sgm_name));
    assert!(
        text.contains("Jacksonville") && text.contains("Omaha Diach.") && text.contains("World")
    );
    let md = std::fs::read_to_string(&r.markdown).unwrap();
    assert!(md.contains(&format!("| {sgm_name} |")), "{md}");

    // Resumability: rerunning both methods scores nothing and adds no row.
    let csv_before = std::fs::read(&r.csv).unwrap();
    for opts in [&gt_opts, &sgm_opts] {
        let again = evaluate(opts, &Silent).unwrap();
        assert_eq!((again.scored, again.skipped), (0, 1));
    }
    assert_eq!(std::fs::read(&r.csv).unwrap(), csv_before);
    let rows = read_records(&r.csv).unwrap();
    assert_eq!(rows.len(), 2);
    let mut keys: Vec<_> = rows.iter().map(|r| r.key()).collect();
    keys.dedup();
    assert_eq!(keys.len(), 2);

    // The same world as an Omaha split with a tiny disparity limit: the pair is dropped and
    // leaves the table's Omaha column empty.
    let mut omaha = EvalOptions::world(&wdir, "Omaha Synch.", Method::GroundTruth, &out);
    omaha.omaha_max_disparity = 5.0;
    let r = evaluate(&omaha, &Silent).unwrap();
    assert_eq!((r.scored, r.dropped), (0, 1));
    let dropped = r
        .records
        .iter()
        .find(|x| x.split == "Omaha Synch.")
        .unwrap();
    assert_eq!(dropped.status, STATUS_DROPPED);
    assert!(dropped.max_gt_disparity.unwrap() > 5.0);
    assert!(r.table.rows[0].splits[2].is_none());

    // Centre crop (as for inputs over 1024 px): the homographies follow the crop, so the true
    // disparity still triangulates exactly; a prediction at the crop's size is accepted as is.
    let mut cropped = EvalOptions::world(&wdir, "World", Method::GroundTruth, tmp.path().join("c"));
    cropped.crop = 160;
    let c = evaluate(&cropped, &Silent).unwrap().records[0].clone();
    assert!(c.mae_filtered.unwrap() < 0.05, "{c:?}");
    assert!(c.pixels < g.pixels && c.coverage.unwrap() < g.coverage.unwrap());
    let full_d = raster::read_image(wdir.join(format!("disparity/{stem}.iio"))).unwrap();
    let crop_d = raster::geometry::crop(&full_d, 32, 32, 160, 160).unwrap();
    let preds = tmp.path().join("preds");
    raster::write_image(preds.join(format!("{stem}.iio")), &crop_d).unwrap();
    let mut p = EvalOptions::world(
        &wdir,
        "World",
        Method::Predictions(preds),
        tmp.path().join("p"),
    );
    p.crop = 160;
    let pc = evaluate(&p, &Silent).unwrap().records[0].clone();
    assert_eq!(pc.method, "preds");
    assert_eq!((pc.mae_filtered, pc.pixels), (c.mae_filtered, c.pixels));

    // Saved DSMs are GeoTIFFs on the truth's grid.
    let mut save = EvalOptions::world(&wdir, "World", Method::GroundTruth, tmp.path().join("e2"));
    save.save_dsm = true;
    evaluate(&save, &Silent).unwrap();
    let dsm_path = tmp
        .path()
        .join("e2/dsm/ground-truth_disparity/World")
        .join(format!("{stem}.tif"));
    let dsm = raster::formats::read_tiff(&dsm_path).unwrap();
    let truth = raster::formats::read_tiff(wdir.join("truth/WORLD_5_DSM.tif")).unwrap();
    assert_eq!(dsm.georef, truth.georef);
    assert_eq!(dsm.image.size(), truth.image.size());
}

/// The files of `dir`, recursively, relative names (to prove nothing half-written is left).
fn files_under(dir: &Path) -> Vec<String> {
    let mut out = Vec::new();
    if let Ok(rd) = std::fs::read_dir(dir) {
        for e in rd.flatten() {
            let p = e.path();
            if p.is_dir() {
                out.extend(files_under(&p));
            } else {
                out.push(p.display().to_string());
            }
        }
    }
    out
}

#[test]
fn errors_name_the_file_and_leave_nothing_half_written() {
    let tmp = tempfile::tempdir().unwrap();
    let wdir = tmp.path().join("world");
    let stem = make_world(&wdir, 128, 2);
    let out = tmp.path().join("eval");

    // A prediction of the wrong size.
    let preds = tmp.path().join("preds");
    raster::write_image(
        preds.join(format!("{stem}.iio")),
        &Image::filled(10, 12, 1, 5.0),
    )
    .unwrap();
    let opts = EvalOptions::world(&wdir, "World", Method::Predictions(preds.clone()), &out);
    let msg = format!("{:#}", evaluate(&opts, &Silent).unwrap_err());
    assert!(
        msg.contains(&format!("{stem}.iio")) && msg.contains("10x12"),
        "{msg}"
    );
    assert!(files_under(&out).is_empty(), "{:?}", files_under(&out));

    // A missing prediction lists the paths tried.
    std::fs::remove_file(preds.join(format!("{stem}.iio"))).unwrap();
    let msg = format!("{:#}", evaluate(&opts, &Silent).unwrap_err());
    assert!(
        msg.contains("no predicted disparity") && msg.contains(&stem),
        "{msg}"
    );

    // A missing RPC JSON.
    let rpc = wdir.join("rpc/WORLD_2_B.json");
    let saved = std::fs::read(&rpc).unwrap();
    std::fs::remove_file(&rpc).unwrap();
    let gt_opts = EvalOptions::world(&wdir, "World", Method::GroundTruth, &out);
    let msg = format!("{:#}", evaluate(&gt_opts, &Silent).unwrap_err());
    assert!(msg.contains("WORLD_2_B.json"), "{msg}");
    std::fs::write(&rpc, saved).unwrap();

    // A malformed RPC JSON.
    let left_rpc = wdir.join("rpc/WORLD_2_A.json");
    let saved = std::fs::read(&left_rpc).unwrap();
    std::fs::write(&left_rpc, b"{\"rpc\": {}}").unwrap();
    let msg = format!("{:#}", evaluate(&gt_opts, &Silent).unwrap_err());
    assert!(msg.contains("WORLD_2_A.json"), "{msg}");
    std::fs::write(&left_rpc, saved).unwrap();

    // A ground-truth DSM without georeference.
    let dsm = wdir.join("truth/WORLD_2_DSM.tif");
    let good = std::fs::read(&dsm).unwrap();
    raster::write_image(&dsm, &Image::filled(50, 50, 1, 1.0)).unwrap();
    let msg = format!("{:#}", evaluate(&gt_opts, &Silent).unwrap_err());
    assert!(
        msg.contains("WORLD_2_DSM.tif") && msg.contains("georeference"),
        "{msg}"
    );
    std::fs::write(&dsm, good).unwrap();
    assert!(files_under(&out).is_empty(), "{:?}", files_under(&out));

    // A CSV that is not ours is an error and is not overwritten.
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(out.join("pairs.csv"), "a,b\n1,2\n").unwrap();
    let msg = format!("{:#}", evaluate(&gt_opts, &Silent).unwrap_err());
    assert!(msg.contains("pairs.csv"), "{msg}");
    assert_eq!(
        std::fs::read_to_string(out.join("pairs.csv")).unwrap(),
        "a,b\n1,2\n"
    );
    std::fs::remove_file(out.join("pairs.csv")).unwrap();

    // Everything back in place: it works.
    let r = evaluate(&gt_opts, &Silent).unwrap();
    assert_eq!(r.scored, 1);
    assert!(r.records[0].mae_filtered.unwrap() < 0.05);
}

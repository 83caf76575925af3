//! `seasonstereo reconstruct-many` on the DFC2019 development images: pairs chosen, reconstructed,
//! fused; bad input refused before any work with the inputs untouched.

use std::path::{Path, PathBuf};

mod support;
use support::{seasonstereo, stderr};

fn image(d: &Path, id: &str) -> String {
    d.join(format!("images/JAX_068_{id}_RGB.tif"))
        .to_str()
        .unwrap()
        .to_string()
}

/// Four images, three pairs, on the truth's grid: the fused DSM covers more than any pair
/// measured, and is accurate.
#[test]
fn four_dates_fuse_into_one_dsm_on_the_truth_grid() {
    let d = testdata::require!("data/dfc2019-jax068-dev");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("fused.tif");
    let truth = d.join("truth/JAX_068_DSM.tif");
    let truth = truth.to_str().unwrap();
    let rpc_dir = d.join("rpcs/ba");
    let images: Vec<String> = ["003", "004", "013", "014"]
        .iter()
        .map(|id| image(&d, id))
        .collect();
    let mut args: Vec<&str> = vec!["reconstruct-many"];
    args.extend(images.iter().map(String::as_str));
    args.extend([
        "--rpc-dir",
        rpc_dir.to_str().unwrap(),
        "--pairs",
        "3",
        "--like",
        truth,
        "--truth",
        truth,
        "-o",
        out.to_str().unwrap(),
    ]);
    // The dry run names the pairs with their terms and writes nothing.
    let mut dry = args.clone();
    dry.push("--dry-run");
    let o = seasonstereo(&dry);
    assert!(o.status.success(), "{}", stderr(&o));
    let printed = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(
        printed.contains("6 overlapping pairs; chosen 3"),
        "{printed}"
    );
    assert!(printed.contains("convergence"), "{printed}");
    assert!(!out.exists() && !dir.path().join("fused_work").exists());

    let o = seasonstereo(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    let stdout = String::from_utf8_lossy(&o.stdout).into_owned();
    for f in [
        "fused.tif",
        "fused_count.tif",
        "fused_spread.tif",
        "fused_confidence.tif",
    ] {
        assert!(dir.path().join(f).is_file(), "{f}\n{stdout}");
    }
    let report: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("fused_report.json")).unwrap(),
    )
    .unwrap();
    let pairs = report["pairs"].as_array().unwrap();
    assert_eq!(pairs.len(), 3, "{stdout}");
    let best_pair_coverage = pairs
        .iter()
        .map(|p| {
            assert_eq!(p["status"], "done", "{p}");
            p["scores"]["coverage"].as_f64().unwrap()
        })
        .fold(0.0, f64::max);
    // Every pair was compared with the fusion; the weights are equal by default.
    for p in pairs {
        let a = &p["agreement"];
        let compared = a["compared"].as_f64().unwrap();
        let share = a["agreeing"].as_f64().unwrap() / compared;
        assert!(compared > 1e4 && share > 0.5, "{p}");
        assert_eq!(p["weight"].as_f64(), Some(1.0), "{p}");
    }
    assert!(stdout.contains("agrees with the fusion on"), "{stdout}");
    let coverage = report["scores"]["coverage"].as_f64().unwrap();
    let mae = report["scores"]["mae_filtered"].as_f64().unwrap();
    assert!(
        coverage > best_pair_coverage && coverage > 0.95,
        "fused {coverage} vs best pair {best_pair_coverage}\n{stdout}"
    );
    assert!(mae < 1.3, "fused MAE {mae}\n{stdout}");
    // The count raster says how many pairs measured each cell (0..=3).
    let count = raster::read_image(dir.path().join("fused_count.tif")).unwrap();
    let max = count.data().iter().copied().fold(0.0f32, f32::max);
    assert_eq!(max, 3.0);
    // Each pair left its matcher's confidence beside its DSM, and the fusion kept the cells
    // whose agreeing pairs' confidences sum to the default 0.1 a pair, and only those.
    for p in pairs {
        let stem = p["stem"].as_str().unwrap();
        let c = dir
            .path()
            .join(format!("fused_work/pairs/{stem}_confidence.tif"));
        assert!(c.is_file(), "{}", c.display());
    }
    let least = report["fusion"]["min_confidence"].as_f64().unwrap() as f32;
    assert!((least - 0.3).abs() < 1e-6, "{least}");
    assert_eq!(report["fusion"]["min_support"].as_u64(), Some(1));
    let confidence = raster::read_image(dir.path().join("fused_confidence.tif")).unwrap();
    let kept: Vec<f32> = confidence
        .data()
        .iter()
        .copied()
        .filter(|c| c.is_finite())
        .collect();
    assert!(kept.len() > 100_000, "{}", kept.len());
    assert!(kept.iter().all(|&c| (least..=3.0).contains(&c)));
    assert!(stdout.contains("vs truth: MAE filtered"), "{stdout}");
    // A rerun resumes: every pair's tiles are finished, none is recomputed.
    let record = dir.path().join("fused_work/pairs").join(format!(
        "{}_work/tiles/r000_c000.json",
        pairs[0]["stem"].as_str().unwrap()
    ));
    let before = std::fs::metadata(&record).unwrap().modified().unwrap();
    let o = seasonstereo(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(
        std::fs::metadata(&record).unwrap().modified().unwrap(),
        before
    );
}

/// The report's scores of a DSM: MAE filtered, coverage, within 1 m.
fn scores(v: &serde_json::Value) -> (f64, f64, f64) {
    let get = |k: &str| v[k].as_f64().unwrap_or_else(|| panic!("no {k} in {v}"));
    (get("mae_filtered"), get("coverage"), get("within_1m"))
}

/// The procedural world on six dates (`world --dates`): the selection puts the three
/// same-season pairs first, and the fused DSM of six pairs beats the best of them through
/// `reconstruct` against the exact truth: lower MAE, more cells within 1 m, as much coverage.
/// `--pair-weights` weights each pair by its agreement to the 8th power.
#[test]
fn a_six_date_world_fuses_better_than_its_best_pair() {
    let dir = tempfile::tempdir().unwrap();
    let world = dir.path().join("world");
    let o = seasonstereo(&[
        "world",
        "--dates",
        "--size",
        "384",
        "-o",
        world.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let truth = world.join("truth/WORLD_1_DSM.tif");
    let truth = truth.to_str().unwrap();
    let rpc = world.join("rpc");
    let images: Vec<String> = (1..=6)
        .map(|k| {
            let p = world.join(format!("raw/WORLD_1_D{k}.tif"));
            assert!(rpc.join(format!("WORLD_1_D{k}.json")).is_file());
            p.to_str().unwrap().to_string()
        })
        .collect();
    let fused = dir.path().join("fused.tif");
    let mut args: Vec<&str> = vec!["reconstruct-many"];
    args.extend(images.iter().map(String::as_str));
    args.extend([
        "--rpc-dir",
        rpc.to_str().unwrap(),
        "--pairs",
        "6",
        "--like",
        truth,
        "--truth",
        truth,
        "-o",
        fused.to_str().unwrap(),
    ]);
    let o = seasonstereo(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    let read = |p: PathBuf| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
    };
    let report = read(dir.path().join("fused_report.json"));
    let chosen = report["chosen"].as_array().unwrap();
    for c in &chosen[..3] {
        assert!(c["terms"]["days"].as_f64().unwrap() <= 7.0, "{c}");
    }
    let (mae, coverage, within) = scores(&report["scores"]);

    // The best-scored pair alone, through `reconstruct` with its defaults (filled, median).
    let (l, r) = (
        chosen[0]["left"].as_u64().unwrap(),
        chosen[0]["right"].as_u64().unwrap(),
    );
    let single = dir.path().join("single.tif");
    let json = dir.path().join("single.json");
    let camera = |i: u64| rpc.join(format!("WORLD_1_D{}.json", i + 1));
    let o = seasonstereo(&[
        "reconstruct",
        &images[l as usize],
        &images[r as usize],
        "--rpc-left",
        camera(l).to_str().unwrap(),
        "--rpc-right",
        camera(r).to_str().unwrap(),
        "--like",
        truth,
        "-o",
        single.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = seasonstereo(&[
        "score",
        single.to_str().unwrap(),
        "--truth",
        truth,
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (single_mae, single_coverage, single_within) = scores(&read(json));
    assert!(
        mae < single_mae && within > single_within && coverage > single_coverage - 0.005,
        "fused {mae} m, {coverage} covered, {within} within 1 m; best pair {single_mae} m, \
         {single_coverage}, {single_within}"
    );

    // With --pair-weights (the pairs' DSMs are reused) every weight is agreement^8.
    let weighted = dir.path().join("weighted.tif");
    let work = dir.path().join("fused_work");
    let mut args: Vec<&str> = args[..args.len() - 1].to_vec();
    args.extend([
        weighted.to_str().unwrap(),
        "--work",
        work.to_str().unwrap(),
        "--pair-weights",
    ]);
    let o = seasonstereo(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    let report = read(dir.path().join("weighted_report.json"));
    for p in report["pairs"].as_array().unwrap() {
        let a = &p["agreement"];
        let share = a["agreeing"].as_f64().unwrap() / a["compared"].as_f64().unwrap();
        let weight = p["weight"].as_f64().unwrap();
        assert!((weight - share.powi(8)).abs() < 1e-5, "{p}");
    }
}

/// `reconstruct-many` of dev dates 003, 004 and 013 with their cameras, the best 2 pairs.
fn two_pairs_of_three_dates(d: &Path) -> Vec<String> {
    let mut args = vec!["reconstruct-many".to_string()];
    args.extend(["003", "004", "013"].iter().map(|id| image(d, id)));
    let rpc_dir = d.join("rpcs/ba").to_str().unwrap().to_string();
    args.extend(["--rpc-dir".into(), rpc_dir, "--pairs".into(), "2".into()]);
    args
}

/// Pairs that fail are named: exit 2 when the others give a DSM, 3 (nothing written) when none
/// does. A memory budget that fits one pair's tile and not the other's makes them fail.
#[test]
fn failed_pairs_exit_2_when_partial_and_3_when_nothing_is_produced() {
    let d = testdata::require!("data/dfc2019-jax068-dev");
    let dir = tempfile::tempdir().unwrap();
    let base = two_pairs_of_three_dates(&d);
    let run = |memory: &str, name: &str| {
        let out = dir.path().join(name);
        let mut args: Vec<&str> = base.iter().map(String::as_str).collect();
        args.extend(["--max-memory", memory, "-o", out.to_str().unwrap()]);
        (seasonstereo(&args), out)
    };
    // With the process's 0.25 GiB, 004–013 needs about 0.55 GiB, 004–003 about 0.70 GiB.
    let (o, out) = run("0.65", "partial.tif");
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(out.is_file() && dir.path().join("partial_count.tif").is_file());
    assert!(
        stderr(&o).contains("JAX_068_004_RGB-JAX_068_003_RGB FAILED"),
        "{}",
        stderr(&o)
    );
    let (o, out) = run("0.3", "none.tif");
    assert_eq!(o.status.code(), Some(3), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("no pair produced a DSM"),
        "{}",
        stderr(&o)
    );
    assert!(!out.exists() && !dir.path().join("none_report.json").exists());
}

/// Two shards share the pairs' tiles (each pair has one tile: they spread by pair), then the run
/// without a shard assembles and fuses them: the files of one unsharded run, byte for byte.
#[test]
fn shards_share_the_pairs_tiles_and_the_last_run_fuses_them() {
    let d = testdata::require!("data/dfc2019-jax068-dev");
    let dir = tempfile::tempdir().unwrap();
    let base = two_pairs_of_three_dates(&d);
    let run = |name: &str, extra: &[&str]| {
        let out = dir.path().join(name);
        let work = dir.path().join(format!("{name}_work"));
        let mut args: Vec<&str> = base.iter().map(String::as_str).collect();
        args.extend([
            "--work",
            work.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
        ]);
        args.extend(extra);
        let o = seasonstereo(&args);
        assert!(o.status.success(), "{}", stderr(&o));
        String::from_utf8_lossy(&o.stdout).into_owned()
    };
    run("one.tif", &[]);
    // Pairs whose tile is finished in the shared work folder.
    let finished = || {
        let pairs = dir.path().join("sharded.tif_work/pairs");
        std::fs::read_dir(pairs).map_or(0, |entries| {
            entries
                .flatten()
                .filter(|e| e.path().join("tiles/r000_c000.json").is_file())
                .count()
        })
    };
    let first = run("sharded.tif", &["--shard", "0/2"]);
    assert!(
        first.contains("shard 0/2: its tiles of 2 pairs ran"),
        "{first}"
    );
    assert!(
        !dir.path().join("sharded.tif").exists(),
        "a shard fuses nothing"
    );
    assert_eq!(finished(), 1, "shard 0 ran one pair's tile");
    run("sharded.tif", &["--shard", "1/2"]);
    assert_eq!(finished(), 2);
    let last = run("sharded.tif", &[]);
    assert!(last.contains("wrote"), "{last}");
    for suffix in [".tif", "_confidence.tif", "_count.tif", "_spread.tif"] {
        let (a, b) = (
            dir.path().join(format!("one{suffix}")),
            dir.path().join(format!("sharded{suffix}")),
        );
        assert!(
            std::fs::read(&a).unwrap() == std::fs::read(&b).unwrap(),
            "{}",
            a.display()
        );
    }
}

fn bytes(paths: &[PathBuf]) -> Vec<Vec<u8>> {
    paths.iter().map(|p| std::fs::read(p).unwrap()).collect()
}

/// One image given twice (the same file, or a copy), a missing camera, a single image, an output
/// that is an input: exit 1 before any work, naming the file, inputs unchanged.
#[test]
fn bad_input_is_refused_before_any_work() {
    let d = testdata::require!("data/dfc2019-jax068-dev");
    let dir = tempfile::tempdir().unwrap();
    let rpc_dir = d.join("rpcs/ba");
    let rpc = rpc_dir.to_str().unwrap();
    let (a, b) = (image(&d, "003"), image(&d, "004"));
    let inputs = [PathBuf::from(&a), PathBuf::from(&b)];
    let before = bytes(&inputs);
    let out = dir.path().join("dsm.tif");
    let o_path = out.to_str().unwrap();
    let refused = |args: &[&str], needle: &str| {
        let o = seasonstereo(args);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {}", stderr(&o));
        assert!(stderr(&o).contains(needle), "{args:?}: {}", stderr(&o));
    };
    let m = "reconstruct-many";
    refused(
        &[m, &a, &b, &a, "--rpc-dir", rpc, "-o", o_path],
        "the same file",
    );
    // A copy of an image under another name (its camera copied too).
    let copy = dir.path().join("JAX_068_999_RGB.tif");
    std::fs::copy(&a, &copy).unwrap();
    let cams = dir.path().join("cams");
    std::fs::create_dir(&cams).unwrap();
    for id in ["003", "004", "999"] {
        let src = rpc_dir.join(format!(
            "JAX_068_{}_RGB.json",
            if id == "999" { "003" } else { id }
        ));
        std::fs::copy(src, cams.join(format!("JAX_068_{id}_RGB.json"))).unwrap();
    }
    let cams = cams.to_str().unwrap();
    let c = copy.to_str().unwrap();
    refused(
        &[m, &a, &b, c, "--rpc-dir", cams, "-o", o_path],
        "identical pixels",
    );
    // A missing camera JSON names the image and the file it looked for.
    refused(
        &[m, &a, &b, c, "--rpc-dir", rpc, "-o", o_path],
        "JAX_068_999_RGB.json",
    );
    refused(
        &[m, &a, "--rpc-dir", rpc, "-o", o_path],
        "two or more images",
    );
    // The output may not be an input.
    refused(&[m, &a, &b, "--rpc-dir", rpc, "-o", &b], "is the input");
    refused(
        &[m, &a, &b, "--rpc-dir", rpc, "--pairs", "0", "-o", o_path],
        "--pairs",
    );
    // A malformed command line is an error before work too (1, not clap's 2 = partial).
    refused(&[m, &a, &b, "--no-such-flag"], "--no-such-flag");
    // An image whose camera puts it 0.05° (5 km) north of the others overlaps none of them.
    let far = dir.path().join("far");
    std::fs::create_dir(&far).unwrap();
    let mut cam: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(rpc_dir.join("JAX_068_005_RGB.json")).unwrap(),
    )
    .unwrap();
    let lat = cam["rpc"]["lat_offset"].as_f64().unwrap();
    cam["rpc"]["lat_offset"] = serde_json::json!(lat + 0.05);
    std::fs::write(far.join("JAX_068_005_RGB.json"), cam.to_string()).unwrap();
    for id in ["003", "004"] {
        let name = format!("JAX_068_{id}_RGB.json");
        std::fs::copy(rpc_dir.join(&name), far.join(&name)).unwrap();
    }
    let e = image(&d, "005");
    refused(
        &[
            m,
            &a,
            &b,
            &e,
            "--rpc-dir",
            far.to_str().unwrap(),
            "-o",
            o_path,
        ],
        "JAX_068_005_RGB.tif overlaps none of the other images",
    );
    assert_eq!(bytes(&inputs), before, "an input changed");
    assert!(!out.exists() && !dir.path().join("dsm_work").exists());
}

/// A piped run (a batch log) says what it does as it does it: the pointing corrections and the
/// chosen pairs before any pair is matched, and each pair when it finishes, the first well before
/// the run is half done.
#[test]
fn a_piped_run_logs_its_pairs_as_they_finish() {
    use std::io::{BufRead, BufReader};
    use std::process::{Command, Stdio};
    use std::time::Instant;
    let d = testdata::require!("data/dfc2019-jax068-dev");
    let dir = tempfile::tempdir().unwrap();
    let mut images: Vec<String> = std::fs::read_dir(d.join("vendor"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "TIF"))
        .map(|p| p.to_str().unwrap().to_string())
        .collect();
    images.sort();
    assert_eq!(images.len(), 10);
    let start = Instant::now();
    let mut child = Command::new(env!("CARGO_BIN_EXE_seasonstereo"))
        .arg("reconstruct-many")
        .args(&images)
        .args(["--pairs", "4", "-o"])
        .arg(dir.path().join("dsm.tif"))
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let lines: Vec<(f64, String)> = BufReader::new(child.stderr.take().unwrap())
        .lines()
        .map(|l| (start.elapsed().as_secs_f64(), l.unwrap()))
        .collect();
    assert!(child.wait().unwrap().success(), "{lines:?}");
    let total = start.elapsed().as_secs_f64();
    let first = |prefix: &str| {
        lines
            .iter()
            .find(|(_, l)| l.starts_with(prefix))
            .map(|(t, _)| *t)
            .unwrap_or_else(|| panic!("no line {prefix:?} in {lines:?}"))
    };
    let (chosen, pair1, pair4) = (first("chosen 4 of"), first("pair 1/4"), first("pair 4/4"));
    assert_eq!(
        lines
            .iter()
            .filter(|(_, l)| l.starts_with("pointing: JAX_068"))
            .count(),
        10
    );
    assert!(first("pointing: JAX_068") <= chosen && chosen < pair1 && pair1 < pair4);
    assert!(
        pair1 < 0.5 * total,
        "first pair at {pair1:.1} s of {total:.1} s"
    );
}

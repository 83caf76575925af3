//! The command line as a user drives it: real files in, real files out, clear errors.

use std::path::Path;

mod support;
use support::{seasonstereo, stderr};

#[test]
fn world_then_predict_in_every_output_format() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("world");
    let o = seasonstereo(&[
        "world",
        "--size",
        "96",
        "--seed",
        "4",
        "-o",
        root.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let stem = "WORLD_4_A-WORLD_4_B";
    for f in ["L", "R", "disparity", "height"] {
        assert!(root.join(f).join(format!("{stem}.iio")).is_file(), "{f}");
    }
    assert!(root
        .join("homography")
        .join(format!("{stem}.npz"))
        .is_file());
    assert!(root.join("rpc/WORLD_4_A.json").is_file() && root.join("world.json").is_file());

    let left = root.join("L").join(format!("{stem}.iio"));
    let right = root.join("R").join(format!("{stem}.iio"));
    let truth = raster::read_image(root.join("disparity").join(format!("{stem}.iio"))).unwrap();
    for ext in ["iio", "tif", "pfm"] {
        let out = dir.path().join(format!("d.{ext}"));
        let o = seasonstereo(&[
            "predict",
            "--method",
            "sgm",
            "--range",
            "0:48",
            left.to_str().unwrap(),
            right.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let d = raster::read_image(&out).unwrap();
        assert_eq!(d.size(), (96, 96));
        // The prediction agrees with the truth on most pixels.
        let good = d
            .data()
            .iter()
            .zip(truth.data())
            .filter(|(p, t)| p.is_finite() && (*p - *t).abs() < 1.0)
            .count();
        assert!(good > 96 * 96 * 3 / 4, "{ext}: {good} good pixels");
    }
    let png = dir.path().join("d.png");
    let o = seasonstereo(&[
        "predict",
        left.to_str().unwrap(),
        right.to_str().unwrap(),
        "-o",
        png.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(raster::read_image(&png).unwrap().channels(), 3);
}

#[test]
fn demo_writes_a_report() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo");
    let o = seasonstereo(&["demo", "--size", "128", "-o", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    for needle in [
        "left.png",
        "truth.png",
        "prediction.png",
        "error.png",
        "bad-2",
        "MAE",
    ] {
        assert!(html.contains(needle), "report lacks {needle}");
    }
    for img in [
        "left.png",
        "right.png",
        "truth.png",
        "prediction.png",
        "error.png",
    ] {
        assert!(Path::new(&out.join(img)).is_file(), "{img}");
    }
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        stdout.contains("MAE") && stdout.contains("report.html"),
        "{stdout}"
    );
    assert!(
        stdout.contains("synchronic pair:") && stdout.contains("winter ↔ summer pair:"),
        "{stdout}"
    );
    // The six-date step: its section, its stack and both DSMs (how the fusion compares with the
    // best pair is tested at a size where it means something, in reconstruct_many.rs).
    assert!(
        html.contains("7. Many dates, one DSM"),
        "no many-dates section"
    );
    assert!(
        stdout.contains("six dates (128² px), 6 pairs fused"),
        "{stdout}"
    );
    for f in [
        "dates/raw/WORLD_1_D6.tif",
        "dates/rpc/WORLD_1_D1.json",
        "dates/fused.tif",
        "dates/fused_report.json",
        "dates/best_pair.tif",
    ] {
        assert!(out.join(f).is_file(), "{f}");
    }
    // The report's `score` command scores the demo's DSMs as the demo did.
    let truth = out.join("world/truth/WORLD_1_DSM.tif");
    let dsm = out.join("dsm/cross_season.tif");
    let o = seasonstereo(&[
        "score",
        dsm.to_str().unwrap(),
        "--truth",
        truth.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let scored = String::from_utf8_lossy(&o.stdout);
    let demo_line = stdout
        .lines()
        .find(|l| l.starts_with("winter ↔ summer pair:"))
        .unwrap();
    let mae = demo_line
        .split("DSM MAE ")
        .nth(1)
        .and_then(|s| s.split(" m filtered").next())
        .unwrap();
    assert!(
        scored.contains(&format!("MAE filtered {mae} m")),
        "{scored} vs {demo_line}"
    );
}

#[test]
fn errors_name_the_file_and_exit_nonzero() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("missing.iio");
    let other = dir.path().join("other.iio");
    raster::write_image(&other, &raster::Image::filled(16, 16, 1, 0.0)).unwrap();
    let o = seasonstereo(&[
        "predict",
        missing.to_str().unwrap(),
        other.to_str().unwrap(),
        "-o",
        "x.iio",
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("missing.iio"), "{}", stderr(&o));

    let garbage = dir.path().join("garbage.tif");
    std::fs::write(&garbage, b"not a tiff at all").unwrap();
    let o = seasonstereo(&[
        "predict",
        garbage.to_str().unwrap(),
        other.to_str().unwrap(),
        "-o",
        "x.iio",
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("garbage.tif"), "{}", stderr(&o));

    let small = dir.path().join("small.iio");
    raster::write_image(&small, &raster::Image::filled(8, 16, 1, 0.0)).unwrap();
    let o = seasonstereo(&[
        "predict",
        small.to_str().unwrap(),
        other.to_str().unwrap(),
        "-o",
        "x.iio",
    ]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("small.iio") && stderr(&o).contains("other.iio"),
        "{}",
        stderr(&o)
    );

    let o = seasonstereo(&[
        "predict",
        "--range",
        "9:3",
        small.to_str().unwrap(),
        other.to_str().unwrap(),
        "-o",
        "x.iio",
    ]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("MIN must not exceed MAX"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn ablation_flags_need_ablation() {
    let o = seasonstereo(&["demo", "--steps", "5"]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--ablation"), "{}", stderr(&o));
    let help = seasonstereo(&["demo", "--help"]);
    let text = String::from_utf8_lossy(&help.stdout);
    for flag in [
        "--ablation",
        "--steps",
        "--train-worlds",
        "--heldout-worlds",
    ] {
        assert!(text.contains(flag), "{text}");
    }
}

#[test]
fn help_lists_every_command() {
    let o = seasonstereo(&["--help"]);
    let text = String::from_utf8_lossy(&o.stdout);
    for c in ["world", "rectify", "predict", "dsm", "demo", "eval"] {
        assert!(text.contains(c), "{text}");
    }
}

#[test]
fn world_disparity_to_dsm_and_eval_agree_with_the_truth() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("world");
    let root_s = root.to_str().unwrap();
    assert!(
        seasonstereo(&["world", "--size", "128", "--seed", "4", "-o", root_s])
            .status
            .success()
    );
    let stem = "WORLD_4_A-WORLD_4_B";
    let file = |sub: &str, name: &str| root.join(sub).join(name).to_str().unwrap().to_owned();
    let truth = file("truth", "WORLD_4_DSM.tif");
    let dsm = dir.path().join("dsm.tif");
    let o = seasonstereo(&[
        "dsm",
        &file("disparity", &format!("{stem}.iio")),
        "--homography",
        &file("homography", &format!("{stem}.npz")),
        "--rpc-left",
        &file("rpc", "WORLD_4_A.json"),
        "--rpc-right",
        &file("rpc", "WORLD_4_B.json"),
        "--like",
        &truth,
        "--compare",
        &truth,
        "-o",
        dsm.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("median |Δh| 0.000 m"), "{stdout}");
    let written = raster::formats::read_tiff(&dsm).unwrap();
    assert_eq!(
        written.georef.unwrap().epsg,
        Some(32617),
        "the world lies in UTM 17N"
    );

    let out = dir.path().join("eval");
    let eval = || {
        seasonstereo(&[
            "eval",
            "--world",
            root_s,
            "--method",
            "ground-truth",
            "-o",
            out.to_str().unwrap(),
        ])
    };
    let o = eval();
    assert!(o.status.success(), "{}", stderr(&o));
    let table = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(
        table.contains("Jacksonville")
            && table.contains("World")
            && table.contains("1 pairs scored"),
        "{table}"
    );
    let again = String::from_utf8_lossy(&eval().stdout).into_owned();
    assert!(
        again.contains("0 pairs scored, 1 already scored"),
        "{again}"
    );
}

#[test]
fn dsm_errors_name_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path().join("d.iio");
    raster::write_image(&d, &raster::Image::filled(16, 16, 1, 3.0)).unwrap();
    let bad_json = dir.path().join("bad.json");
    std::fs::write(&bad_json, "{\"rpc\": {\"row_offset\": 1}}").unwrap();
    let h = dir.path().join("h.npz");
    raster::formats::write_homographies(
        &h,
        &raster::Homography::IDENTITY,
        &raster::Homography::IDENTITY,
    )
    .unwrap();
    let o = seasonstereo(&[
        "dsm",
        d.to_str().unwrap(),
        "--homography",
        h.to_str().unwrap(),
        "--rpc-left",
        bad_json.to_str().unwrap(),
        "--rpc-right",
        bad_json.to_str().unwrap(),
        "-o",
        dir.path().join("out.tif").to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("bad.json"), "{}", stderr(&o));
    assert!(
        !dir.path().join("out.tif").exists(),
        "nothing written on error"
    );
}

/// The MonSter++ parity fixture: a test reading it starts with `testdata::require!(MONSTER)`.
const MONSTER: &str = "fixtures/monsterpp-tiny";

fn monster_fixture() -> std::path::PathBuf {
    testdata::checked(MONSTER)
}

/// An f32 tensor of the fixture's tensors.safetensors: (shape, values).
fn fixture_tensor(name: &str) -> (Vec<usize>, Vec<f32>) {
    let bytes = std::fs::read(monster_fixture().join("tensors.safetensors")).unwrap();
    let st = safetensors::SafeTensors::deserialize(&bytes).unwrap();
    let view = st.tensor(name).unwrap();
    assert_eq!(view.dtype(), safetensors::Dtype::F32, "{name}");
    let values = view
        .data()
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    (view.shape().to_vec(), values)
}

/// The fixture's 1×3×H×W input written as an (H, W, 3) `.iio`.
fn write_fixture_image(name: &str, path: &Path) {
    let (shape, v) = fixture_tensor(name);
    let (h, w) = (shape[2], shape[3]);
    let mut data = vec![0f32; h * w * 3];
    for c in 0..3 {
        for i in 0..h * w {
            data[i * 3 + c] = v[c * h * w + i];
        }
    }
    raster::write_image(path, &raster::Image::new(w, h, 3, data).unwrap()).unwrap();
}

#[test]
fn predict_monsterpp_reproduces_the_upstream_fixture() {
    testdata::require!(MONSTER);
    let dir = tempfile::tempdir().unwrap();
    let (l, r, out) = (
        dir.path().join("L.iio"),
        dir.path().join("R.iio"),
        dir.path().join("out.iio"),
    );
    write_fixture_image("input.left", &l);
    write_fixture_image("input.right", &r);
    let weights = monster_fixture().join("weights.safetensors");
    let o = seasonstereo(&[
        "predict",
        "--model",
        "monsterpp",
        "--weights",
        weights.to_str().unwrap(),
        "--config",
        "tiny",
        "--iters",
        "8",
        l.to_str().unwrap(),
        r.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("MonSter++ tiny"), "{stdout}");
    let d = raster::read_image(&out).unwrap();
    assert_eq!((d.width(), d.height(), d.channels()), (128, 64, 1));
    let (_, want) = fixture_tensor("output.disp");
    let err = d
        .data()
        .iter()
        .zip(&want)
        .map(|(a, b)| (a - b).abs())
        .fold(0f32, f32::max);
    assert!(err <= 1e-3, "max abs error {err} px");
}

#[test]
fn predict_monsterpp_errors_name_the_file_and_the_keys() {
    testdata::require!(MONSTER);
    let dir = tempfile::tempdir().unwrap();
    let (l, r, out) = (
        dir.path().join("L.iio"),
        dir.path().join("R.iio"),
        dir.path().join("out.iio"),
    );
    write_fixture_image("input.left", &l);
    write_fixture_image("input.right", &r);
    let run = |weights: &str, config: &str| {
        seasonstereo(&[
            "predict",
            "--model",
            "monsterpp",
            "--weights",
            weights,
            "--config",
            config,
            l.to_str().unwrap(),
            r.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
        ])
    };
    let missing = dir.path().join("mix_all.pth");
    let o = run(missing.to_str().unwrap(), "vitl");
    assert!(!o.status.success());
    let msg = stderr(&o);
    assert!(
        msg.contains("mix_all.pth") && msg.contains("no such file"),
        "{msg}"
    );

    let weights = monster_fixture().join("weights.safetensors");
    let o = run(weights.to_str().unwrap(), "vits");
    assert!(!o.status.success());
    let msg = stderr(&o);
    assert!(
        msg.contains("do not fit") && msg.contains("`vits`"),
        "{msg}"
    );
    assert!(
        msg.contains("mono_encoder.") && msg.contains("wrong shape"),
        "names the keys: {msg}"
    );
    assert!(
        msg.contains("--config tiny"),
        "suggests the right preset: {msg}"
    );
    assert!(!out.exists());

    // --model needs --weights; --range belongs to SGM.
    let o = seasonstereo(&[
        "predict",
        "--model",
        "monsterpp",
        "a.iio",
        "b.iio",
        "-o",
        "d.iio",
    ]);
    assert!(
        !o.status.success() && stderr(&o).contains("--weights"),
        "{}",
        stderr(&o)
    );
    let help = seasonstereo(&["predict", "--help"]);
    let help = String::from_utf8_lossy(&help.stdout);
    for flag in [
        "--model",
        "--weights",
        "--config",
        "--iters",
        "--max-disp",
        "--normalise",
        "--strip-rows",
    ] {
        assert!(help.contains(flag), "{flag} missing from predict --help");
    }
}

/// Data rows of an experiment list, and how many are flagged diachronic.
fn experiment_rows(path: &Path) -> (usize, usize) {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut lines = text.lines();
    assert_eq!(
        lines.next(),
        Some("filename,diachronic"),
        "{}",
        path.display()
    );
    let rows: Vec<&str> = lines.filter(|l| !l.is_empty()).collect();
    let diachronic = rows.iter().filter(|l| l.ends_with(",True")).count();
    (rows.len(), diachronic)
}

#[test]
fn dataset_world_writes_25_combinations_per_pair_and_the_subsets() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("set");
    let args = [
        "dataset",
        "world",
        "--size",
        "96",
        "--worlds",
        "2",
        "--val-worlds",
        "1",
        "--seed",
        "5",
        "-o",
        out.to_str().unwrap(),
    ];
    let o = seasonstereo(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    let stdout = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(stdout.contains("S3"), "{stdout}");

    // 25 combinations per pair on both views: 5 tags (real + 4 seasons) on each side.
    let tags = ["", "__summer", "__autumn", "__winter", "__spring"];
    for seed in [5, 6] {
        let (a, b) = (format!("W{seed:06}_A"), format!("W{seed:06}_B"));
        for tl in tags {
            for tr in tags {
                for side in ["L", "R"] {
                    let f = out
                        .join("train")
                        .join(side)
                        .join(format!("{a}{tl}-{b}{tr}.npy"));
                    assert!(f.is_file(), "{}", f.display());
                }
            }
        }
        let pair = format!("{a}-{b}");
        assert!(out
            .join("disparity_maps/sgm")
            .join(format!("{pair}.iio"))
            .is_file());
        assert!(out
            .join("disparity_maps/GT")
            .join(format!("{pair}.iio"))
            .is_file());
        for m in ["masks", "water_masks", "tree_masks", "building_masks"] {
            assert!(
                out.join("train")
                    .join(m)
                    .join("L")
                    .join(format!("{pair}.npy"))
                    .is_file(),
                "{m}"
            );
        }
    }
    assert_eq!(std::fs::read_dir(out.join("train/L")).unwrap().count(), 50);

    // The three subsets (and the full list): S1 real only, S2 + 4 synchronic synthetic per pair,
    // S3 the same budget half synchronic half diachronic.
    let exp = out.join("experiments");
    assert_eq!(experiment_rows(&exp.join("sub1_synchronic.csv")), (2, 0));
    assert_eq!(experiment_rows(&exp.join("sub2_synchronic.csv")), (10, 0));
    assert_eq!(experiment_rows(&exp.join("sub5_syndiach.csv")), (10, 4));
    assert_eq!(experiment_rows(&exp.join("sub3_diachronic.csv")), (50, 40));
    assert_eq!(experiment_rows(&exp.join("sub_val.csv")), (25, 20));
    let manifest = std::fs::read_to_string(out.join("manifest.json")).unwrap();
    for key in ["sub5_syndiach", "\"teacher\": \"sgm\"", "builtin"] {
        assert!(manifest.contains(key), "{key} not in {manifest}");
    }

    // A rerun finds everything done.
    let o = seasonstereo(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    let stdout = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(stdout.contains("0 built now, 2 already built"), "{stdout}");

    // Bad shards are refused with the expected form.
    let o = seasonstereo(&[
        "dataset",
        "build",
        "--pairs",
        out.join("sources/train/pairs").to_str().unwrap(),
        "--teacher",
        out.join("sources/train/teacher").to_str().unwrap(),
        "--shard",
        "2/2",
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("0 ≤ i < n"), "{}", stderr(&o));
}

#[test]
fn dataset_help_documents_layout_subsets_and_shards() {
    let o = seasonstereo(&["dataset", "build", "--help"]);
    let text = String::from_utf8_lossy(&o.stdout).into_owned();
    for key in [
        "sub1_synchronic",
        "sub5_syndiach",
        "--shard",
        "water_masks",
        "Resumable",
    ] {
        assert!(
            text.contains(key),
            "{key} not in `dataset build --help`:\n{text}"
        );
    }
    let o = seasonstereo(&["synthesize", "--help"]);
    let text = String::from_utf8_lossy(&o.stdout).into_owned();
    for key in [
        "--generator",
        "cropped-synthetic",
        "--crop",
        "--shard",
        "rejected.csv",
    ] {
        assert!(
            text.contains(key),
            "{key} not in `synthesize --help`:\n{text}"
        );
    }
}

/// `train --config tiny` on a procedural-world set: runs, stops with a checkpoint, resumes to
/// the end, writes the logs; bad input is named.
#[test]
fn train_tiny_stops_resumes_and_logs() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("set");
    let o = seasonstereo(&[
        "dataset",
        "world",
        "-o",
        data.to_str().unwrap(),
        "--size",
        "128",
        "--worlds",
        "1",
        "--val-worlds",
        "1",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let run = dir.path().join("run");
    let small = [
        "--set",
        "run.batch_size=1",
        "--set",
        "run.train_iters=7",
        "--set",
        "run.valid_iters=7",
        "--set",
        "augment.crop_height=32",
        "--set",
        "augment.crop_width=64",
        "--set",
        "model.max_disp=32",
        "--set",
        "loss.max_disp=32.0",
        "--set",
        "loss.ignore_border=2",
        "--set",
        "run.valid_crop=64",
        "--set",
        "data.valid_limit=1",
        "--set",
        "run.validate_every=3",
    ];
    let mut args = vec![
        "train",
        "--config",
        "tiny",
        "--data",
        data.to_str().unwrap(),
        "-o",
        run.to_str().unwrap(),
        "--steps",
        "3",
        "--stop-after",
        "2",
        "--device",
        "cpu",
    ];
    args.extend(small);
    let o = seasonstereo(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(out.contains("stopped after 2 of 3 steps"), "{out}");
    assert!(run.join("checkpoints/step-0000002/state.json").is_file());

    let o = seasonstereo(&["train", "--resume", run.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(out.contains("done: 3 of 3 steps"), "{out}");
    assert!(out.contains("validation EPE"), "{out}");
    let metrics = std::fs::read_to_string(run.join("metrics.csv")).unwrap();
    assert_eq!(metrics.lines().count(), 4, "{metrics}");
    assert!(metrics.starts_with("step,lr,total,disp,photo,smooth"));
    assert!(run.join("final.safetensors").is_file() && run.join("config.toml").is_file());
    // One TensorBoard event file per session (the first run and the resumed one).
    let event_files = std::fs::read_dir(&run)
        .unwrap()
        .filter(|e| {
            e.as_ref()
                .unwrap()
                .file_name()
                .to_string_lossy()
                .starts_with("events.out.tfevents.")
        })
        .count();
    assert_eq!(event_files, 2);

    // Errors name the problem.
    if !cfg!(feature = "wgpu") {
        let o = seasonstereo(&["train", "--config", "tiny", "--device", "wgpu"]);
        assert!(
            !o.status.success() && stderr(&o).contains("--features wgpu"),
            "{}",
            stderr(&o)
        );
    }
    let o = seasonstereo(&["train", "--config", "tiny", "--device", "tpu"]);
    assert!(
        !o.status.success() && stderr(&o).contains("possible values"),
        "{}",
        stderr(&o)
    );
    let o = seasonstereo(&["train", "--config", "tiny", "--set", "run.stepz=3"]);
    assert!(
        !o.status.success() && stderr(&o).contains("stepz"),
        "{}",
        stderr(&o)
    );
    let o = seasonstereo(&[
        "train",
        "--config",
        "tiny",
        "--data",
        dir.path().join("none").to_str().unwrap(),
    ]);
    assert!(
        !o.status.success() && stderr(&o).contains("none"),
        "{}",
        stderr(&o)
    );
    let o = seasonstereo(&["train"]);
    assert!(
        !o.status.success() && stderr(&o).contains("--config"),
        "{}",
        stderr(&o)
    );
}

/// `teacher` → `curate` → `masks` on two procedural worlds, sharded and resumed as an array job
/// would run them.
#[test]
fn data_stages_teacher_curate_masks() {
    let dir = tempfile::tempdir().unwrap();
    let pairs = dir.path().join("pairs");
    for seed in [3, 4, 5] {
        let o = seasonstereo(&[
            "world",
            "-o",
            pairs.to_str().unwrap(),
            "--size",
            "80",
            "--seed",
            &seed.to_string(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
    }
    let teacher = dir.path().join("teacher");
    let t = teacher.to_str().unwrap();
    let p = pairs.to_str().unwrap();
    for shard in ["0/2", "1/2"] {
        let o = seasonstereo(&[
            "teacher", "--pairs", p, "-o", t, "--range", "0:40", "--shard", shard,
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
    }
    let o = seasonstereo(&["teacher", "--pairs", p, "-o", t, "--range", "0:40"]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("0 processed, 3 already done"), "{out}");
    assert!(
        teacher.join("WORLD_4_A-WORLD_4_B.iio").is_file() && teacher.join("teacher.json").is_file()
    );

    let cur = dir.path().join("curate");
    let o = seasonstereo(&[
        "curate",
        "--pairs",
        p,
        "--teacher",
        t,
        "-o",
        cur.to_str().unwrap(),
        "--keep",
        "2",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.contains("offline histogram descriptor") && out.contains("K = 2"),
        "{out}"
    );
    let csv = std::fs::read_to_string(cur.join("scores.csv")).unwrap();
    assert_eq!(csv.lines().count(), 4, "{csv}");
    let selected = std::fs::read_to_string(cur.join("selected.txt")).unwrap();
    assert!((1..=2).contains(&selected.lines().count()), "{selected}");
    assert!(cur.join("report.html").is_file() && cur.join("curate.json").is_file());

    let seg = dir.path().join("seg");
    let o = seasonstereo(&[
        "masks",
        "--images",
        &format!("{p}/L"),
        "-o",
        seg.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.contains("offline rules") && out.contains("colour only"),
        "{out}"
    );
    for class in ["water", "tree", "building"] {
        let m = seg.join(format!(
            "{class}_segmentation/masks/WORLD_3_A-WORLD_3_B_mask.png"
        ));
        assert!(m.is_file(), "{}", m.display());
        let txt = std::fs::read_to_string(
            seg.join(format!("{class}_segmentation/{class}_percentages.txt")),
        )
        .unwrap();
        assert_eq!(txt.lines().count(), 4, "{txt}");
    }

    // Errors name the problem and the fix.
    let o = seasonstereo(&[
        "curate",
        "--pairs",
        p,
        "--teacher",
        dir.path().join("none").to_str().unwrap(),
        "-o",
        cur.to_str().unwrap(),
    ]);
    assert!(
        !o.status.success() && stderr(&o).contains("seasonstereo teacher"),
        "{}",
        stderr(&o)
    );
    let o = seasonstereo(&["teacher", "--pairs", p, "-o", t, "--shard", "2/2"]);
    assert!(
        !o.status.success() && stderr(&o).contains("0 ≤ i < n"),
        "{}",
        stderr(&o)
    );
    let o = seasonstereo(&[
        "curate",
        "--pairs",
        p,
        "--teacher",
        t,
        "-o",
        cur.to_str().unwrap(),
        "--keep",
        "0",
    ]);
    assert!(
        !o.status.success() && stderr(&o).contains("at least 1"),
        "{}",
        stderr(&o)
    );
    let o = seasonstereo(&[
        "masks",
        "--images",
        p,
        "-o",
        seg.to_str().unwrap(),
        "--segformer",
        dir.path().join("no.pt").to_str().unwrap(),
    ]);
    assert!(
        !o.status.success() && stderr(&o).contains("no.pt"),
        "{}",
        stderr(&o)
    );
    for cmd in ["teacher", "curate", "masks"] {
        let o = seasonstereo(&[cmd, "--help"]);
        let help = String::from_utf8_lossy(&o.stdout);
        assert!(
            o.status.success() && help.contains("--shard") && help.contains("Example"),
            "{help}"
        );
    }
}

#[test]
fn reconstruct_a_real_pair_then_score_it_on_the_dfc2019_truth() {
    let d = testdata::require!("data/dfc2019-jax068-dev");
    let p = |rel: &str| d.join(rel).to_str().unwrap().to_string();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("003-004.tif");
    let truth = p("truth/JAX_068_DSM.tif");
    let o = seasonstereo(&[
        "reconstruct",
        &p("images/JAX_068_003_RGB.tif"),
        &p("images/JAX_068_004_RGB.tif"),
        "--rpc-left",
        &p("rpcs/ba/JAX_068_003_RGB.json"),
        "--rpc-right",
        &p("rpcs/ba/JAX_068_004_RGB.json"),
        "--like",
        &truth,
        "--truth",
        &truth,
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let stdout = String::from_utf8_lossy(&o.stdout).into_owned();
    let line = stdout.lines().find(|l| l.starts_with("vs truth:")).unwrap();
    let mae = line
        .split("MAE filtered ")
        .nth(1)
        .unwrap()
        .split(' ')
        .next()
        .unwrap();
    assert!(mae.parse::<f64>().unwrap() < 1.6, "{line}");
    // One tile (the crop is under --tile 1024), its record beside its cells.
    let record = dir.path().join("003-004_work/tiles/r000_c000.json");
    let record: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&record).unwrap()).unwrap();
    assert_eq!(record["status"], "done", "{record}");
    // `score` takes the UTM zone of the plain-TIFF truth from the DSM and agrees.
    let json = dir.path().join("scores.jsonl");
    let o = seasonstereo(&[
        "score",
        out.to_str().unwrap(),
        "--truth",
        &truth,
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let scored = String::from_utf8_lossy(&o.stdout);
    assert!(
        scored.contains(&format!("MAE filtered {mae} m")),
        "{scored} vs {line}"
    );
    let v: serde_json::Value = serde_json::from_str(
        std::fs::read_to_string(&json)
            .unwrap()
            .lines()
            .next()
            .unwrap(),
    )
    .unwrap();
    assert!(v["coverage"].as_f64().unwrap() > 0.88, "{v}");
    // --truth must be the grid given to --like.
    let o = seasonstereo(&[
        "reconstruct",
        &p("images/JAX_068_003_RGB.tif"),
        &p("images/JAX_068_004_RGB.tif"),
        "--like",
        &p("truth/JAX_068_CLS.tif"),
        "--truth",
        &truth,
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--like"), "{}", stderr(&o));
}

/// s2p's DSMs as s2p writes them (each on its own 0.5 m grid) are scored and compared as the
/// benchmark does: cut onto the truth's grid, which the log says; the scores are those of the
/// set's copies already cut onto it.
#[test]
fn score_cuts_s2p_dsms_on_their_own_grid_onto_the_truth_and_compares_them() {
    let d = testdata::require!("data/dfc2019-jax068-dev");
    let p = |rel: &str| d.join(rel).to_str().unwrap().to_string();
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("versus.jsonl");
    let truth = p("truth/JAX_068_DSM.tif");
    let o = seasonstereo(&[
        "score",
        &p("s2p/013-014.tif"),
        "--against",
        &p("s2p/006-020.tif"),
        "--truth",
        &truth,
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let log = stderr(&o);
    for pair in [
        "013-014.tif: on its own grid",
        "006-020.tif: on its own grid",
    ] {
        assert!(log.contains(pair), "{log}");
    }
    assert!(log.contains("cut onto the truth's grid"), "{log}");
    let v: serde_json::Value =
        serde_json::from_str(std::fs::read_to_string(&json).unwrap().trim()).unwrap();
    assert!(v["common_ours"]["cells"].as_u64().unwrap() > 100_000, "{v}");
    // The same figures as the copies on the truth's grid, which the log does not mention.
    let o = seasonstereo(&["score", &p("s2p/truth-grid/013-014.tif"), "--truth", &truth]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!stderr(&o).contains("own grid"), "{}", stderr(&o));
    let copy = String::from_utf8_lossy(&o.stdout);
    let mae = format!(
        "MAE filtered {:.3} m",
        v["ours"]["mae_filtered"].as_f64().unwrap()
    );
    assert!(copy.contains(&mae), "{copy} vs {mae}");
}

/// `bench` times a workload after a warm-up and prints one JSON line; bad presets are refused.
#[test]
fn bench_times_a_network_pass_and_prints_json() {
    let o = seasonstereo(&[
        "bench",
        "monsterpp",
        "--config",
        "tiny",
        "--height",
        "64",
        "--width",
        "64",
        "--iters",
        "7",
        "--runs",
        "2",
        "--device",
        "cpu",
        "--json",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value =
        serde_json::from_str(String::from_utf8_lossy(&o.stdout).trim()).expect("one JSON line");
    assert_eq!(v["workload"], "monsterpp");
    assert_eq!(v["times_s"].as_array().unwrap().len(), 2);
    let (median, min) = (
        v["median_s"].as_f64().unwrap(),
        v["min_s"].as_f64().unwrap(),
    );
    assert!(min > 0.0 && median >= min, "{v}");
    assert!(v["peak_rss_mib"].as_f64().unwrap() > 1.0, "{v}");
    let o = seasonstereo(&["bench", "segformer", "--config", "mit-b9"]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("mit-b2"), "{}", stderr(&o));
}

/// `seasonstereo ARGS` (a help request), laid out for a terminal `columns` wide: clap wraps
/// help text to `COLUMNS` when the output is no terminal.
fn help_text(args: &[&str], columns: usize) -> String {
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_seasonstereo"))
        .args(args)
        .env("COLUMNS", columns.to_string())
        .output()
        .expect("the binary runs");
    assert!(o.status.success(), "{args:?}: {}", stderr(&o));
    String::from_utf8(o.stdout).expect("UTF-8 help")
}

/// One option's entry in a help text: its name (`--long`, or `<NAME>` of a positional) and the
/// lines of its description.
struct Entry {
    name: String,
    lines: Vec<String>,
}

/// The name of the option an entry line starts: `  -o, --output <OUTPUT>  …`,
/// `      --rpc-left <CAMERA>  …` or `  <LEFT>  …` (descriptions are indented further).
fn entry_name(line: &str) -> Option<String> {
    let spec = if let Some(rest) = line.strip_prefix("      --") {
        format!("--{rest}")
    } else if let Some(rest) = line.strip_prefix("  -") {
        let rest = rest.get(2..)?.trim_start();
        rest.starts_with("--").then(|| rest.to_string())?
    } else if let Some(rest) = line.strip_prefix("  <") {
        format!("<{rest}")
    } else {
        return None;
    };
    let name = spec.split([' ', '=']).next()?;
    Some(name.to_string())
}

/// The option sections of a help text, in order: heading → entries. A heading is an unindented
/// line ending in `:` followed by an option's entry; the epilogue ends the last section.
fn sections(help: &str) -> Vec<(String, Vec<Entry>)> {
    let lines: Vec<&str> = help.lines().collect();
    let mut out: Vec<(String, Vec<Entry>)> = Vec::new();
    let mut open = false;
    for (i, line) in lines.iter().enumerate() {
        let next_is_entry = lines.get(i + 1).and_then(|l| entry_name(l)).is_some();
        if !line.starts_with(' ') && line.ends_with(':') && next_is_entry {
            out.push((line.trim_end_matches(':').to_string(), Vec::new()));
            open = true;
        } else if line.is_empty() || !line.starts_with(' ') {
            // A blank line separates entries (long help) or sections; prose ends the sections.
            open = open && line.is_empty();
        } else if let (true, Some((_, entries))) = (open, out.last_mut()) {
            match entry_name(line) {
                Some(name) => entries.push(Entry {
                    name,
                    lines: vec![line.to_string()],
                }),
                None => entries
                    .last_mut()
                    .expect("a description follows its entry")
                    .lines
                    .push(line.to_string()),
            }
        }
    }
    out
}

/// The example commands of a help text, each with its continuation lines joined: a command
/// starts at a line `  seasonstereo …` and goes on while a line ends in ` \`. Fails on a line
/// that continues a command without the backslash before it (a wrapped line cannot be pasted).
fn example_commands(help: &str) -> Vec<String> {
    let lines: Vec<&str> = help.lines().collect();
    let mut commands = Vec::new();
    let mut i = 0;
    while i < lines.len() {
        if !lines[i].starts_with("  seasonstereo ") {
            i += 1;
            continue;
        }
        let mut command = lines[i].trim().to_string();
        while command.ends_with(" \\") {
            i += 1;
            let next = lines.get(i).unwrap_or(&"");
            assert!(
                next.starts_with("    ") && !next.trim().is_empty(),
                "`{command}` ends in a backslash but the next line is {next:?}:\n{help}"
            );
            command.truncate(command.len() - 2);
            command.push(' ');
            command.push_str(next.trim());
        }
        let after = lines.get(i + 1).copied().unwrap_or("");
        let ends = after.is_empty()
            || !after.starts_with(' ')
            || after.starts_with("  seasonstereo ")
            || after.starts_with("  #")
            || after.starts_with("  D=");
        assert!(
            ends,
            "the line after `{command}` continues it without a backslash: {after:?}:\n{help}"
        );
        commands.push(command);
        i += 1;
    }
    commands
}

/// `reconstruct` and `reconstruct-many`: `-h` fits a screen (60 lines at 100 columns), holds
/// only the common options under the headings Inputs, Outputs, Region, Quality, Performance and
/// Cluster, one line each; `--help` lists every option, those `-h` leaves out under headings of
/// their own; the examples of both paste (every continuation after a ` \`, also on an
/// 80-column terminal), use the data folder as a user's relative `$D`, and only real options.
#[test]
fn reconstruct_help_is_one_screen_grouped_and_its_examples_paste() {
    let common = [
        "Inputs",
        "Outputs",
        "Region",
        "Quality",
        "Performance",
        "Cluster",
    ];
    let cases = [
        (
            "reconstruct",
            "<LEFT>",
            "seasonstereo reconstruct $D/vendor/JAX_068_006_RGB.TIF \
             $D/vendor/JAX_068_020_RGB.TIF -o out/jax/006-020.tif",
            &[
                "--method",
                "--model",
                "--fill-holes",
                "--fill-reach",
                "--p1",
                "--keep-intermediates",
            ] as &[&str],
        ),
        (
            "reconstruct-many",
            "<IMAGE>...",
            "seasonstereo reconstruct-many $D/vendor/*.TIF -o out/jax-many/dsm.tif",
            &[
                "--method",
                "--model",
                "--fill-holes",
                "--cluster-tolerance",
                "--p1",
            ],
        ),
    ];
    for (cmd, positional, vendor_example, must_hide) in cases {
        let short = help_text(&[cmd, "-h"], 100);
        let long = help_text(&[cmd, "--help"], 100);
        let n = short.lines().count();
        assert!(n <= 60, "`{cmd} -h` is {n} lines:\n{short}");
        assert!(long.lines().count() > 2 * n, "`{cmd} --help` is not longer");

        let short_sections = sections(&short);
        let long_sections = sections(&long);
        let headings: Vec<&str> = short_sections.iter().map(|(h, _)| h.as_str()).collect();
        for h in common {
            assert!(headings.contains(&h), "`{cmd} -h` has no {h}: {headings:?}");
        }
        for h in &headings {
            assert!(
                *h == "Options" || common.contains(h),
                "`{cmd} -h` has the heading {h}, not one of {common:?}"
            );
        }
        let under = |sections: &[(String, Vec<Entry>)], heading: &str| -> Vec<String> {
            sections
                .iter()
                .filter(|(h, _)| h == heading)
                .flat_map(|(_, e)| e.iter().map(|e| e.name.clone()))
                .collect()
        };
        assert!(under(&short_sections, "Inputs").contains(&positional.to_string()));
        assert!(under(&short_sections, "Outputs").contains(&"--output".to_string()));

        // -h: one line per option (two when clap puts the description under a long name).
        for (heading, entries) in &short_sections {
            for e in entries {
                let beside = e.lines[0].trim().contains("  ");
                let allowed = if beside { 1 } else { 2 };
                assert!(
                    e.lines.len() == allowed,
                    "`{cmd} -h`: {} under {heading} takes {} lines:\n{}",
                    e.name,
                    e.lines.len(),
                    e.lines.join("\n")
                );
            }
        }

        // --help: everything, the options -h hides under headings -h does not have.
        let short_names: Vec<String> = short_sections
            .iter()
            .flat_map(|(_, e)| e.iter().map(|e| e.name.clone()))
            .collect();
        let mut hidden = Vec::new();
        for (heading, entries) in &long_sections {
            for e in entries {
                if short_names.contains(&e.name) {
                    assert!(
                        under(&short_sections, heading).contains(&e.name),
                        "`{cmd}`: {} is under {heading} in --help only",
                        e.name
                    );
                } else {
                    assert!(
                        !headings.contains(&heading.as_str()),
                        "`{cmd} --help` lists {}, hidden by -h, under the common heading {heading}",
                        e.name
                    );
                    hidden.push(e.name.clone());
                }
            }
        }
        let long_names: Vec<String> = long_sections
            .iter()
            .flat_map(|(_, e)| e.iter().map(|e| e.name.clone()))
            .collect();
        for name in &short_names {
            assert!(long_names.contains(name), "`{cmd} --help` lacks {name}");
        }
        for name in must_hide.iter() {
            assert!(
                hidden.contains(&name.to_string()),
                "`{cmd}`: {name} should be in --help only; hidden: {hidden:?}"
            );
        }

        // The examples paste, on an 80-column terminal too.
        for text in [
            short.clone(),
            long.clone(),
            help_text(&[cmd, "-h"], 80),
            help_text(&[cmd, "--help"], 80),
        ] {
            let commands = example_commands(&text);
            assert!(
                commands.iter().any(|c| c == vendor_example),
                "`{cmd}`: no `{vendor_example}` among {commands:#?}"
            );
            assert!(
                text.contains("\n  D=../shared/data/dfc2019-jax068-dev\n"),
                "{text}"
            );
            for c in &commands {
                assert!(c.starts_with(&format!("seasonstereo {cmd} ")), "{c}");
                for word in c.split_whitespace() {
                    assert!(!word.starts_with('/'), "an absolute path in `{c}`");
                    if let Some(flag) = word.strip_prefix("--") {
                        let flag = format!("--{}", flag.split('=').next().unwrap());
                        assert!(long_names.contains(&flag), "`{c}`: no option {flag}");
                    }
                }
            }
        }
        // The long epilogue also shows a run on the truth's grid, scored against it.
        assert!(
            example_commands(&long)
                .iter()
                .any(|c| c.contains("--truth")),
            "`{cmd} --help` has no example scored against the truth"
        );
    }

    // The top level: the commands under headings, one line each, on one screen.
    let top = help_text(&["-h"], 100);
    assert!(top.lines().count() <= 60, "{top}");
    for c in ["reconstruct", "reconstruct-many", "demo", "train", "jobs"] {
        let line = top
            .lines()
            .find(|l| l.split_whitespace().next() == Some(c))
            .unwrap_or_else(|| panic!("`seasonstereo -h` lacks {c}:\n{top}"));
        assert!(line.len() <= 100, "{line}");
    }
    assert!(top.contains("\nSatellite images to DSMs:\n"), "{top}");
}

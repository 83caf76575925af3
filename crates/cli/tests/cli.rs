//! The command line as a user drives it: real files in, real files out, clear errors.

use std::path::Path;
use std::process::{Command, Output};

fn seasonstereo(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_seasonstereo"))
        .args(args)
        .output()
        .expect("the binary runs")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

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

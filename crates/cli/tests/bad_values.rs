//! Every subcommand given bad values (missing, empty or corrupt files, malformed cameras, NaN
//! disparities, zero sizes, wrong extensions, one input given twice) exits 1 with one error line
//! and never panics. No case reaches a reconstruction: each is refused while reading or checking.

mod support;
use support::{code, seasonstereo, stderr};

/// The bad files, and good ones beside them so that each case has one fault.
struct Files {
    dir: tempfile::TempDir,
}

impl Files {
    fn new() -> Files {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path();
        // A raw pair with its cameras, and a rectified world with its disparity and homography.
        let raw = p.join("raw_world");
        let o = seasonstereo(&[
            "world",
            "--raw",
            "--size",
            "128",
            "--seed",
            "3",
            "-o",
            raw.to_str().unwrap(),
        ]);
        assert_eq!(code(&o), 0, "{}", stderr(&o));
        let world = p.join("world");
        let o = seasonstereo(&[
            "world",
            "--size",
            "64",
            "--seed",
            "4",
            "-o",
            world.to_str().unwrap(),
        ]);
        assert_eq!(code(&o), 0, "{}", stderr(&o));
        std::fs::write(p.join("empty.tif"), b"").unwrap();
        std::fs::write(p.join("empty.json"), b"").unwrap();
        std::fs::write(p.join("empty.npz"), b"").unwrap();
        // A TIFF header, then garbage.
        let mut corrupt = b"II*\0\x08\0\0\0".to_vec();
        corrupt.extend((0..4096u32).map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8));
        std::fs::write(p.join("corrupt.tif"), corrupt).unwrap();
        std::fs::write(p.join("bad.json"), b"{\"rpc\": {\"row_offset\": ").unwrap();
        std::fs::write(
            p.join("bad.RPB"),
            b"satId = \"WV03\";\nBEGIN_GROUP = IMAGE\n",
        )
        .unwrap();
        let nan = raster::Image::filled(64, 64, 1, f32::NAN);
        raster::write_image(p.join("nan.npy"), &nan).unwrap();
        raster::write_image(p.join("nan.pfm"), &nan).unwrap();
        // Cameras named after the raw images, one of them malformed.
        let cams = p.join("bad_cams");
        std::fs::create_dir(&cams).unwrap();
        std::fs::write(cams.join("WORLD_3_A.json"), b"{").unwrap();
        std::fs::copy(raw.join("rpc/WORLD_3_B.json"), cams.join("WORLD_3_B.json")).unwrap();
        std::fs::create_dir(p.join("empty_dir")).unwrap();
        Files { dir }
    }

    /// `name` under the temporary folder, as an argument; `$`-names are the worlds' files.
    fn arg(&self, name: &str) -> String {
        let p = self.dir.path();
        let path = match name {
            "$A" => p.join("raw_world/raw/WORLD_3_A.tif"),
            "$B" => p.join("raw_world/raw/WORLD_3_B.tif"),
            "$CA" => p.join("raw_world/rpc/WORLD_3_A.json"),
            "$CB" => p.join("raw_world/rpc/WORLD_3_B.json"),
            "$CAMS" => p.join("raw_world/rpc"),
            "$D" => p.join("world/disparity/WORLD_4_A-WORLD_4_B.iio"),
            "$H" => p.join("world/homography/WORLD_4_A-WORLD_4_B.npz"),
            "$WA" => p.join("world/rpc/WORLD_4_A.json"),
            "$WB" => p.join("world/rpc/WORLD_4_B.json"),
            "$TRUTH" => p.join("world/truth/WORLD_4_DSM.tif"),
            _ if p.join(name).exists()
                || name.starts_with("out/")
                || name.starts_with("missing") =>
            {
                p.join(name)
            }
            _ => return name.to_string(),
        };
        path.to_str().unwrap().to_string()
    }
}

/// One case: the command line, with file names resolved by [`Files::arg`].
const CASES: &[&[&str]] = &[
    // reconstruct
    &["reconstruct", "missing.tif", "$B", "-o", "out/r.tif"],
    &["reconstruct", "empty.tif", "$B", "-o", "out/r.tif"],
    &["reconstruct", "corrupt.tif", "$B", "-o", "out/r.tif"],
    &[
        "reconstruct",
        "$A",
        "$B",
        "--rpc-left",
        "bad.json",
        "-o",
        "out/r.tif",
    ],
    &[
        "reconstruct",
        "$A",
        "$B",
        "--rpc-left",
        "empty.json",
        "-o",
        "out/r.tif",
    ],
    &[
        "reconstruct",
        "$A",
        "$B",
        "--rpc-left",
        "bad.RPB",
        "-o",
        "out/r.tif",
    ],
    &[
        "reconstruct",
        "$A",
        "$A",
        "--rpc-left",
        "$CA",
        "--rpc-right",
        "$CA",
        "-o",
        "out/r.tif",
    ],
    &[
        "reconstruct",
        "$A",
        "$B",
        "--rpc-left",
        "$CA",
        "--rpc-right",
        "$CB",
        "--tile",
        "0",
        "-o",
        "out/r.tif",
    ],
    &[
        "reconstruct",
        "$A",
        "$B",
        "--rpc-left",
        "$CA",
        "--rpc-right",
        "$CB",
        "--roi",
        "0,0,0,0",
        "-o",
        "out/r.tif",
    ],
    &[
        "reconstruct",
        "$A",
        "$B",
        "--rpc-left",
        "$CA",
        "--rpc-right",
        "$CB",
        "--max-memory",
        "0",
        "-o",
        "out/r.tif",
    ],
    &[
        "reconstruct",
        "$A",
        "$B",
        "--rpc-left",
        "$CA",
        "--rpc-right",
        "$CB",
        "-o",
        "out/cloud.las",
    ],
    &[
        "reconstruct",
        "$A",
        "$B",
        "--rpc-left",
        "$CA",
        "--rpc-right",
        "$CB",
        "-o",
        "out/dsm.png",
    ],
    &[
        "reconstruct",
        "$A",
        "$B",
        "--rpc-left",
        "$CA",
        "--rpc-right",
        "$CB",
        "--alt-range",
        "nan:5",
        "-o",
        "out/r.tif",
    ],
    // reconstruct-many
    &[
        "reconstruct-many",
        "missing.tif",
        "$A",
        "$B",
        "-o",
        "out/m.tif",
    ],
    &[
        "reconstruct-many",
        "empty.tif",
        "$A",
        "$B",
        "-o",
        "out/m.tif",
    ],
    &[
        "reconstruct-many",
        "corrupt.tif",
        "$A",
        "$B",
        "-o",
        "out/m.tif",
    ],
    &[
        "reconstruct-many",
        "$A",
        "$B",
        "$A",
        "--rpc-dir",
        "$CAMS",
        "-o",
        "out/m.tif",
    ],
    &[
        "reconstruct-many",
        "$A",
        "$B",
        "--rpc-dir",
        "bad_cams",
        "-o",
        "out/m.tif",
    ],
    &[
        "reconstruct-many",
        "$A",
        "$B",
        "--rpc-dir",
        "empty_dir",
        "-o",
        "out/m.tif",
    ],
    &[
        "reconstruct-many",
        "$A",
        "$B",
        "--rpc-dir",
        "$CAMS",
        "--pairs",
        "0",
        "-o",
        "out/m.tif",
    ],
    &[
        "reconstruct-many",
        "$A",
        "$B",
        "--rpc-dir",
        "$CAMS",
        "--tile",
        "0",
        "-o",
        "out/m.tif",
    ],
    &[
        "reconstruct-many",
        "$A",
        "$B",
        "--rpc-dir",
        "$CAMS",
        "-o",
        "out/m.las",
    ],
    &[
        "reconstruct-many",
        "$A",
        "--rpc-dir",
        "$CAMS",
        "-o",
        "out/m.tif",
    ],
    // dsm
    &[
        "dsm",
        "nan.npy",
        "--homography",
        "$H",
        "--rpc-left",
        "$WA",
        "--rpc-right",
        "$WB",
        "-o",
        "out/d.tif",
    ],
    &[
        "dsm",
        "nan.pfm",
        "--homography",
        "$H",
        "--rpc-left",
        "$WA",
        "--rpc-right",
        "$WB",
        "-o",
        "out/d.tif",
    ],
    &[
        "dsm",
        "empty.tif",
        "--homography",
        "$H",
        "--rpc-left",
        "$WA",
        "--rpc-right",
        "$WB",
        "-o",
        "out/d.tif",
    ],
    &[
        "dsm",
        "$D",
        "--homography",
        "empty.npz",
        "--rpc-left",
        "$WA",
        "--rpc-right",
        "$WB",
        "-o",
        "out/d.tif",
    ],
    &[
        "dsm",
        "$D",
        "--homography",
        "corrupt.tif",
        "--rpc-left",
        "$WA",
        "--rpc-right",
        "$WB",
        "-o",
        "out/d.tif",
    ],
    &[
        "dsm",
        "$D",
        "--homography",
        "$H",
        "--rpc-left",
        "bad.json",
        "--rpc-right",
        "$WB",
        "-o",
        "out/d.tif",
    ],
    &[
        "dsm",
        "$D",
        "--homography",
        "$H",
        "--rpc-left",
        "$WA",
        "--rpc-right",
        "$WB",
        "-o",
        "out/d.las",
    ],
    &[
        "dsm",
        "$D",
        "--homography",
        "$H",
        "--rpc-left",
        "$WA",
        "--rpc-right",
        "$WB",
        "--resolution",
        "0",
        "-o",
        "out/d.tif",
    ],
    // the other subcommands
    &["rectify", "empty.tif", "$B", "-o", "out/rect"],
    &["rectify", "corrupt.tif", "$B", "-o", "out/rect"],
    &[
        "rectify",
        "$A",
        "$B",
        "--rpc-left",
        "bad.json",
        "-o",
        "out/rect",
    ],
    &["predict", "empty.tif", "corrupt.tif", "-o", "out/p.iio"],
    &["predict", "corrupt.tif", "corrupt.tif", "-o", "out/p.iio"],
    &["score", "empty.tif", "--truth", "$TRUTH"],
    &["score", "corrupt.tif", "--truth", "$TRUTH"],
    &["score", "$TRUTH", "--truth", "corrupt.tif"],
    &["eval", "--world", "empty.tif", "--output", "out/eval"],
    &["teacher", "--pairs", "empty.tif", "--output", "out/teacher"],
    &[
        "curate",
        "--pairs",
        "empty.tif",
        "--teacher",
        "corrupt.tif",
        "--output",
        "out/cur",
    ],
    &["masks", "--images", "empty.tif", "--output", "out/masks"],
    &[
        "masks-score",
        "--masks",
        "empty.tif",
        "--rpc-dir",
        "bad.json",
        "--truth",
        "corrupt.tif",
    ],
    &["synthesize", "--pairs", "empty.tif", "--raw", "corrupt.tif"],
    &[
        "dataset",
        "build",
        "--pairs",
        "empty.tif",
        "--teacher",
        "corrupt.tif",
        "--output",
        "out/ds",
    ],
    &[
        "train",
        "--config",
        "tiny",
        "--data",
        "empty.tif",
        "--output",
        "out/train",
    ],
    &[
        "train",
        "--config",
        "no-such-preset",
        "--data",
        "empty.tif",
        "--output",
        "out/train",
    ],
    &["world", "--size", "0", "-o", "out/w0"],
    &["jobs", "status", "--work", "empty_dir"],
    &["bench", "merge", "--cells", "0"],
    &["demo", "--steps", "5"],
    &["reconstruct", "--no-such-flag"],
];

#[test]
fn every_subcommand_refuses_bad_values_with_one_line_and_no_panic() {
    let files = Files::new();
    let mut failures = Vec::new();
    for case in CASES {
        let args: Vec<String> = case.iter().map(|a| files.arg(a)).collect();
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = seasonstereo(&args);
        let e = stderr(&o);
        let errors = e.lines().filter(|l| l.starts_with("error")).count();
        let panicked = e.contains("panicked") || e.contains("RUST_BACKTRACE");
        if code(&o) != 1 || errors != 1 || panicked {
            failures.push(format!("{case:?}: exit {}, stderr:\n{e}", code(&o)));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
    // Nothing was written under a DSM's name by a refused run.
    let out = files.dir.path().join("out");
    for name in [
        "r.tif",
        "m.tif",
        "d.tif",
        "cloud.las",
        "dsm.png",
        "m.las",
        "d.las",
    ] {
        assert!(!out.join(name).exists(), "{name} written");
    }
}

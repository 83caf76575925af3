//! The user guide's troubleshooting page (`docs/guide/src/troubleshooting.md`) quotes the
//! product's messages; this test keeps it honest. Under every heading that holds a ```` ```text ````
//! block, the block's first line is a message as the binary prints it, `…` standing for the
//! parts that name the user's files and numbers. Each such heading has a case here that triggers
//! the message with the binary, and the test checks the exit code and that one line of stderr
//! matches the quoted line (its start, its end and its pieces in order). A quoted message without
//! a case, or a case whose heading is gone, fails too: the page cannot drift from the product.

use std::collections::BTreeSet;
use std::path::Path;
use std::process::{Command, Output};

mod support;
use support::{code, damage_tiles, stderr};

/// The page, from the workspace's root.
const PAGE: &str = "docs/guide/src/troubleshooting.md";

/// The procedural scenes and files the cases use, made in the test's folder: a raw pair with
/// its cameras (`scene`), a view of another place (`other`), a rectified pair and a smaller one.
const SETUP: &[&str] = &[
    "world --size 384 --seed 3 --raw -o scene",
    "world --size 256 --seed 5 --raw -o other",
    "world --size 256 -o flat",
    "world --size 128 -o small",
    "reconstruct scene/raw/WORLD_3_A.tif scene/raw/WORLD_3_B.tif --rpc-left \
     scene/rpc/WORLD_3_A.json --rpc-right scene/rpc/WORLD_3_B.json -o out/dsm.tif",
    "predict --range 0:40 flat/L/WORLD_1_A-WORLD_1_B.iio flat/R/WORLD_1_A-WORLD_1_B.iio \
     -o out/disparity.tif",
];

/// `reconstruct` of the scene's pair with its own cameras; a case appends its flags.
const PAIR: &str = "reconstruct scene/raw/WORLD_3_A.tif scene/raw/WORLD_3_B.tif --rpc-left \
                    scene/rpc/WORLD_3_A.json --rpc-right scene/rpc/WORLD_3_B.json";

/// One case per quoted message: the page's heading, the exit code, and the command line
/// (`PAIR` is replaced by [`PAIR`]). `cameras/*.json` and the damaged files are made by
/// [`prepare`].
const CASES: &[(&str, i32, &str)] = &[
    (
        "No RPC camera",
        1,
        "reconstruct scene/raw/WORLD_3_A.tif scene/raw/WORLD_3_B.tif -o out/x.tif",
    ),
    // Each camera given to the other image; without min_alt/max_alt, so the pointing is
    // corrected and found not to fit.
    (
        "A camera that does not fit its image",
        1,
        "reconstruct scene/raw/WORLD_3_A.tif scene/raw/WORLD_3_B.tif --rpc-left cameras/B.json \
         --rpc-right cameras/A.json -o out/x.tif",
    ),
    (
        "Is this the RPC of another image?",
        1,
        "reconstruct scene/raw/WORLD_3_A.tif scene/raw/WORLD_3_B.tif --rpc-left \
         scene/rpc/WORLD_3_A.json --rpc-right cameras/far.json -o out/x.tif",
    ),
    (
        "The cameras look swapped",
        0,
        "reconstruct scene/raw/WORLD_3_A.tif scene/raw/WORLD_3_B.tif --rpc-left \
         scene/rpc/WORLD_3_B.json --rpc-right scene/rpc/WORLD_3_A.json -o out/swapped.tif",
    ),
    (
        "The altitudes could not be found from tie points",
        1,
        "reconstruct scene/raw/WORLD_3_A.tif other/raw/WORLD_5_B.tif --rpc-left cameras/A.json \
         --rpc-right cameras/other.json -o out/unmatched.tif",
    ),
    (
        "The pointing was not corrected",
        0,
        "reconstruct scene/raw/WORLD_3_A.tif other/raw/WORLD_5_B.tif --rpc-left cameras/A.json \
         --rpc-right cameras/other.json --alt-range -1:57 -o out/unmatched.tif",
    ),
    (
        "The altitude range misses the scene",
        1,
        "PAIR --alt-range 5000:6000 -o out/x.tif",
    ),
    (
        "The output would replace an input",
        1,
        "PAIR -o scene/raw/WORLD_3_A.tif",
    ),
    // The same command would resume; other finishing onto the same DSM is refused.
    (
        "The output already exists",
        1,
        "PAIR --median-filter 5 -o out/dsm.tif",
    ),
    (
        "The work folder holds another run",
        1,
        "PAIR --tile 256 --work out/dsm_work -o out/other.tif",
    ),
    ("A DSM must be a GeoTIFF", 1, "PAIR -o out/dsm.png"),
    (
        "The same image on both sides",
        1,
        "reconstruct scene/raw/WORLD_3_A.tif scene/raw/WORLD_3_A.tif --rpc-left \
         scene/rpc/WORLD_3_A.json --rpc-right scene/rpc/WORLD_3_B.json -o out/x.tif",
    ),
    (
        "A missing file",
        1,
        "reconstruct scene/raw/missing.tif scene/raw/WORLD_3_B.tif --rpc-left \
         scene/rpc/WORLD_3_A.json --rpc-right scene/rpc/WORLD_3_B.json -o out/x.tif",
    ),
    (
        "A damaged file",
        1,
        "reconstruct not-a-tiff.tif scene/raw/WORLD_3_B.tif --rpc-left scene/rpc/WORLD_3_A.json \
         --rpc-right scene/rpc/WORLD_3_B.json -o out/x.tif",
    ),
    (
        "A truncated array",
        1,
        "predict --range 0:40 truncated.iio flat/R/WORLD_1_A-WORLD_1_B.iio -o out/d.iio",
    ),
    (
        "The two images differ in size",
        1,
        "predict --range 0:40 flat/L/WORLD_1_A-WORLD_1_B.iio small/R/WORLD_1_A-WORLD_1_B.iio \
         -o out/d.iio",
    ),
    (
        "Not a ground-truth name",
        1,
        "score out/dsm.tif --truth out/dsm.tif",
    ),
    (
        "A DSM without a georeference",
        1,
        "score out/disparity.tif --truth scene/truth/WORLD_3_DSM.tif",
    ),
    ("Unknown EPSG code", 1, "PAIR --epsg 99999 -o out/x.tif"),
    (
        "One tile does not fit in --max-memory",
        1,
        "PAIR --max-memory 0.2 -o out/x.tif",
    ),
    (
        "The DSM does not fit in --max-memory",
        1,
        "PAIR --max-memory 0.01 -o out/y.tif",
    ),
    (
        "Images without a date",
        0,
        "reconstruct-many scene/raw/WORLD_3_A.tif scene/raw/WORLD_3_B.tif --rpc-dir scene/rpc \
         --dry-run -o out/many.tif",
    ),
    // Run with a PATH that holds no Slurm command ([`NO_SLURM`]).
    ("sinfo not found", 1, "jobs slurm PAIR -o out/slurm.tif"),
    (
        "Not a submission's work folder",
        1,
        "jobs status --work out/dsm_work",
    ),
    (
        "A flag that needs another",
        1,
        "PAIR --truth scene/truth/WORLD_3_DSM.tif -o out/x.tif",
    ),
    ("Tiles too small", 1, "PAIR --tile 32 -o out/x.tif"),
];

/// The case run with an empty `PATH` folder (no `sinfo`, no `sbatch`).
const NO_SLURM: &str = "sinfo not found";

/// The damaged tiles' cases: a 768² raw scene in 256-px tiles, its left image damaged in its
/// bottom-right TIFF tile (some tiles fail), then in every one (nothing produced).
const DAMAGED: &[(&str, i32, &str)] = &[
    ("Some tiles failed", 2, "BIG -o out/partial.tif"),
    ("Nothing was produced", 3, "BIG -o out/nothing.tif"),
];

const BIG: &str = "reconstruct big/raw/WORLD_3_A.tif big/raw/WORLD_3_B.tif --rpc-left \
                   big/rpc/WORLD_3_A.json --rpc-right big/rpc/WORLD_3_B.json --tile 256";

fn page() -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .join(PAGE);
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Each heading's title with the first line of the first ```` ```text ```` block under it
/// (headings without one are left out).
fn quoted(markdown: &str) -> Vec<(String, String)> {
    let mut found = Vec::new();
    let mut heading: Option<String> = None;
    let mut lines = markdown.lines();
    while let Some(line) = lines.next() {
        if let Some(title) = line.strip_prefix('#') {
            heading = Some(title.trim_start_matches('#').trim().to_string());
        } else if line.trim_end() == "```text" {
            let first = lines.next().unwrap_or("").trim_end().to_string();
            if let Some(title) = heading.take() {
                found.push((title, first));
            }
            for rest in lines.by_ref() {
                if rest.trim_end() == "```" {
                    break;
                }
            }
        }
    }
    found
}

/// Whether `line` is `pattern` with each `…` standing for any text.
fn matches(pattern: &str, line: &str) -> bool {
    let pieces: Vec<&str> = pattern.split('…').collect();
    let (first, last) = (pieces[0], pieces[pieces.len() - 1]);
    if pieces.len() == 1 {
        return line == pattern;
    }
    if !line.starts_with(first) || !line.ends_with(last) || line.len() < first.len() + last.len() {
        return false;
    }
    let mut rest = &line[first.len()..line.len() - last.len()];
    for piece in &pieces[1..pieces.len() - 1] {
        match rest.find(piece) {
            Some(i) => rest = &rest[i + piece.len()..],
            None => return false,
        }
    }
    true
}

/// The words of a case's command line, its `PAIR` and `BIG` spelt out.
fn words(line: &str) -> Vec<String> {
    line.split_whitespace()
        .flat_map(|w| match w {
            "PAIR" => PAIR.split_whitespace().collect(),
            "BIG" => BIG.split_whitespace().collect(),
            w => vec![w],
        })
        .map(String::from)
        .collect()
}

/// Runs the binary in `dir` (relative paths, as a user types them), with `path` as `PATH`.
fn run_in(dir: &Path, line: &str, path: Option<&Path>) -> Output {
    let mut command = Command::new(env!("CARGO_BIN_EXE_seasonstereo"));
    command.args(words(line)).current_dir(dir);
    if let Some(p) = path {
        command.env("PATH", p);
    }
    command.output().expect("the binary runs")
}

/// A JSON camera: `from`'s, its longitude offset moved by `lon_shift` degrees, and without
/// `min_alt`/`max_alt` unless `keep_altitudes` (a vendor's camera has none: its pointing is
/// then corrected and the altitudes found from tie points).
fn camera(from: &Path, to: &Path, lon_shift: f64, keep_altitudes: bool) {
    let text = std::fs::read_to_string(from).unwrap();
    let mut json: serde_json::Value = serde_json::from_str(&text).unwrap();
    let object = json.as_object_mut().unwrap();
    if !keep_altitudes {
        object.remove("min_alt");
        object.remove("max_alt");
    }
    let lon = &mut object.get_mut("rpc").unwrap()["lon_offset"];
    *lon = serde_json::json!(lon.as_f64().unwrap() + lon_shift);
    std::fs::write(to, json.to_string()).unwrap();
}

/// Makes what [`CASES`] use in `dir`.
fn prepare(dir: &Path) {
    for line in SETUP {
        let o = run_in(dir, line, None);
        assert_eq!(code(&o), 0, "{line}: {}", stderr(&o));
    }
    let cameras = dir.join("cameras");
    std::fs::create_dir_all(&cameras).unwrap();
    let rpc = |path: &str| dir.join(path);
    camera(
        &rpc("scene/rpc/WORLD_3_A.json"),
        &cameras.join("A.json"),
        0.0,
        false,
    );
    camera(
        &rpc("scene/rpc/WORLD_3_B.json"),
        &cameras.join("B.json"),
        0.0,
        false,
    );
    // Half a degree east: another place.
    camera(
        &rpc("scene/rpc/WORLD_3_B.json"),
        &cameras.join("far.json"),
        0.5,
        true,
    );
    camera(
        &rpc("other/rpc/WORLD_5_B.json"),
        &cameras.join("other.json"),
        0.0,
        false,
    );
    std::fs::write(dir.join("not-a-tiff.tif"), "hello\n").unwrap();
    let bytes = std::fs::read(dir.join("flat/L/WORLD_1_A-WORLD_1_B.iio")).unwrap();
    std::fs::write(dir.join("truncated.iio"), &bytes[..1000]).unwrap();
    std::fs::create_dir_all(dir.join("no-slurm")).unwrap();
}

/// Runs `cases` in `dir` and checks each against the page; one failure lists every mismatch.
fn check(dir: &Path, cases: &[(&str, i32, &str)]) {
    let quotes = quoted(&page());
    let mut failures = Vec::new();
    for &(heading, expected, line) in cases {
        let Some((_, message)) = quotes.iter().find(|(h, _)| h == heading) else {
            failures.push(format!(
                "{PAGE} has no heading \"{heading}\" with a text block"
            ));
            continue;
        };
        let path = (heading == NO_SLURM).then(|| dir.join("no-slurm"));
        let o = run_in(dir, line, path.as_deref());
        let err = stderr(&o);
        if code(&o) != expected {
            failures.push(format!(
                "{heading}: exit code {} (expected {expected}): {err}",
                code(&o)
            ));
        }
        if !err.lines().any(|l| matches(message, l.trim_end())) {
            failures.push(format!(
                "{heading}: the page quotes\n  {message}\nbut stderr is\n  {}",
                err.trim_end().replace('\n', "\n  ")
            ));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
}

#[test]
fn every_quoted_message_is_the_binary_s() {
    let dir = tempfile::tempdir().unwrap();
    prepare(dir.path());
    check(dir.path(), CASES);
}

#[test]
fn failed_tiles_are_reported_as_the_page_says() {
    let dir = tempfile::tempdir().unwrap();
    let o = run_in(dir.path(), "world --size 768 --seed 3 --raw -o big", None);
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    // The 768² image is 3 × 3 TIFF tiles of 256²: its bottom-right one, then all.
    let left = dir.path().join("big/raw/WORLD_3_A.tif");
    damage_tiles(&left, |r, c| r == 2 && c == 2);
    check(dir.path(), &DAMAGED[..1]);
    damage_tiles(&left, |_, _| true);
    check(dir.path(), &DAMAGED[1..]);
}

#[test]
fn every_quoted_message_has_a_case_and_every_case_a_quote() {
    let quoted: BTreeSet<String> = quoted(&page()).into_iter().map(|(h, _)| h).collect();
    let cased: Vec<String> = CASES
        .iter()
        .chain(DAMAGED)
        .map(|(h, _, _)| h.to_string())
        .collect();
    let unique: BTreeSet<String> = cased.iter().cloned().collect();
    assert_eq!(unique.len(), cased.len(), "one case per heading: {cased:?}");
    assert_eq!(
        quoted, unique,
        "{PAGE}'s quoted messages (left) against the cases of this test (right)"
    );
}

#[test]
fn patterns_match_whole_lines_with_ellipses_for_any_text() {
    assert!(matches(
        "error: -o … is the input …: done",
        "error: -o a.tif is the input /x/a.tif: done"
    ));
    assert!(!matches(
        "error: -o … is the input …: done",
        "warning: -o a is the input b: done"
    ));
    assert!(!matches("error: … failed", "error: 3 failed, retry"));
    assert!(matches("exact", "exact"));
    assert!(matches("error: …", "error: anything"));
    assert_eq!(
        quoted("# T\n\n## A\n\n```text\nerror: a\nmore\n```\n\n## B\n\ntext\n\n### C\n```text\nwarning: c\n```\n"),
        vec![
            ("A".to_string(), "error: a".to_string()),
            ("C".to_string(), "warning: c".to_string())
        ]
    );
    assert_eq!(
        words("PAIR -o x.tif")[..2],
        ["reconstruct", "scene/raw/WORLD_3_A.tif"]
    );
}

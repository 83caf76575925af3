//! Fault tests: a user's data is never lost and the exit code tells the truth (0 done, 1 error
//! before any work, 2 partial, 3 nothing produced). Each case checks the exit code, the message
//! and that every input file is byte-identical afterwards. The scene is a raw procedural pair
//! (`world --raw`): tiled, Deflate-compressed uint8 GeoTIFFs and their RPC JSONs, as satellite
//! imagery ships.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

mod support;
use support::{code, damage_tiles, seasonstereo, stderr};

/// A raw procedural pair: `(left, right, rpc_left, rpc_right)`.
struct Scene {
    left: PathBuf,
    right: PathBuf,
    rpc_left: PathBuf,
    rpc_right: PathBuf,
}

impl Scene {
    fn new(dir: &Path, size: usize) -> Scene {
        let root = dir.join("world");
        let o = seasonstereo(&[
            "world",
            "--size",
            &size.to_string(),
            "--seed",
            "3",
            "--raw",
            "-o",
            root.to_str().unwrap(),
        ]);
        assert_eq!(code(&o), 0, "{}", stderr(&o));
        Scene {
            left: root.join("raw/WORLD_3_A.tif"),
            right: root.join("raw/WORLD_3_B.tif"),
            rpc_left: root.join("rpc/WORLD_3_A.json"),
            rpc_right: root.join("rpc/WORLD_3_B.json"),
        }
    }

    fn inputs(&self) -> [&Path; 4] {
        [&self.left, &self.right, &self.rpc_left, &self.rpc_right]
    }

    /// `reconstruct` of this pair onto `output`, with `extra` flags.
    fn reconstruct(&self, output: &Path, extra: &[&str]) -> Output {
        self.reconstruct_with(
            (&self.left, &self.right),
            (&self.rpc_left, &self.rpc_right),
            output,
            extra,
        )
    }

    fn reconstruct_with(
        &self,
        (left, right): (&Path, &Path),
        (rpc_left, rpc_right): (&Path, &Path),
        output: &Path,
        extra: &[&str],
    ) -> Output {
        let mut args = vec![
            "reconstruct",
            left.to_str().unwrap(),
            right.to_str().unwrap(),
            "--rpc-left",
            rpc_left.to_str().unwrap(),
            "--rpc-right",
            rpc_right.to_str().unwrap(),
            "-o",
            output.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        seasonstereo(&args)
    }
}

/// The bytes of every file, to check that none changed.
fn snapshot(paths: &[&Path]) -> BTreeMap<PathBuf, Vec<u8>> {
    paths
        .iter()
        .map(|p| (p.to_path_buf(), std::fs::read(p).unwrap()))
        .collect()
}

fn assert_unchanged(before: &BTreeMap<PathBuf, Vec<u8>>) {
    for (path, bytes) in before {
        let now = std::fs::read(path).unwrap();
        assert!(&now == bytes, "{} changed", path.display());
    }
}

/// No debug forms in what a user reads.
fn assert_plain(message: &str) {
    for debug in ["Some(", "None)", "Err(", "Ok(", "{ ", "\\\""] {
        assert!(
            !message.contains(debug),
            "debug form {debug:?} in: {message}"
        );
    }
}

/// Defect 1: `-o` onto an input (the left image, an RPC JSON, the image through `..` and a
/// link) exits 1 before any work and leaves every input as it was.
#[test]
fn an_output_onto_an_input_is_refused_and_the_input_kept() {
    let dir = tempfile::tempdir().unwrap();
    let scene = Scene::new(dir.path(), 256);
    let before = snapshot(&scene.inputs());
    let dotted = scene.left.parent().unwrap().join("../raw/WORLD_3_A.tif");
    let link = dir.path().join("link.tif");
    std::os::unix::fs::symlink(&scene.left, &link).unwrap();
    for output in [&scene.left, &scene.rpc_right, &dotted, &link] {
        let o = scene.reconstruct(output, &[]);
        assert_eq!(code(&o), 1, "{}", stderr(&o));
        let e = stderr(&o);
        assert!(e.contains("is the input"), "{e}");
        assert_eq!(e.lines().count(), 1, "one line: {e}");
        assert_plain(&e);
    }
    assert_unchanged(&before);
    assert!(!dir.path().join("world/raw/WORLD_3_A_work").exists());
}

/// An existing DSM is replaced only with `--overwrite`; a rerun into the same work folder
/// (a resumed run) may rewrite its own DSM.
#[test]
fn an_existing_dsm_needs_overwrite() {
    let dir = tempfile::tempdir().unwrap();
    let scene = Scene::new(dir.path(), 256);
    let out = dir.path().join("dsm.tif");
    std::fs::write(&out, b"someone's DSM").unwrap();
    let o = scene.reconstruct(&out, &[]);
    assert_eq!(code(&o), 1, "{}", stderr(&o));
    assert!(stderr(&o).contains("--overwrite"), "{}", stderr(&o));
    assert_eq!(std::fs::read(&out).unwrap(), b"someone's DSM");
    let o = scene.reconstruct(&out, &["--overwrite"]);
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    assert_ne!(std::fs::read(&out).unwrap(), b"someone's DSM");
    // The same command again resumes its own work folder: allowed, nothing rerun.
    let o = scene.reconstruct(&out, &[]);
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    assert!(String::from_utf8_lossy(&o.stdout).contains("0 run now"));
}

/// Defect 2: an altitude range that misses the scene is refused before matching (exit 1), with
/// the range the RPCs' metadata suggest; no DSM is written.
#[test]
fn an_altitude_range_missing_the_scene_is_refused_before_work() {
    let dir = tempfile::tempdir().unwrap();
    let scene = Scene::new(dir.path(), 256);
    let out = dir.path().join("dsm.tif");
    let o = scene.reconstruct(&out, &["--alt-range", "5000:6000"]);
    assert_eq!(code(&o), 1, "{}", stderr(&o));
    let e = stderr(&o);
    assert!(
        e.contains("misses the scene") && e.contains("Use --alt-range"),
        "{e}"
    );
    assert_plain(&e);
    assert!(!out.exists());
}

/// Defect 3: the same file, or a copy of it, on both sides exits 1; an RPC of another place is
/// named as such, not reported as a memory estimate.
#[test]
fn wrong_pairs_and_foreign_rpcs_are_refused_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let scene = Scene::new(dir.path(), 256);
    let out = dir.path().join("dsm.tif");
    let cameras = (scene.rpc_left.as_path(), scene.rpc_right.as_path());
    let o = scene.reconstruct_with((&scene.left, &scene.left), cameras, &out, &[]);
    assert_eq!(code(&o), 1, "{}", stderr(&o));
    assert!(stderr(&o).contains("same file"), "{}", stderr(&o));

    let copy = dir.path().join("copy.tif");
    std::fs::copy(&scene.left, &copy).unwrap();
    let o = scene.reconstruct_with((&scene.left, &copy), cameras, &out, &[]);
    assert_eq!(code(&o), 1, "{}", stderr(&o));
    assert!(stderr(&o).contains("identical pixels"), "{}", stderr(&o));

    // The right camera moved 0.2° east: another place.
    let mut rpc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&scene.rpc_right).unwrap()).unwrap();
    let lon = rpc["rpc"]["lon_offset"].as_f64().unwrap();
    rpc["rpc"]["lon_offset"] = (lon + 0.2).into();
    let foreign = dir.path().join("foreign.json");
    std::fs::write(&foreign, rpc.to_string()).unwrap();
    let o = scene.reconstruct_with(
        (&scene.left, &scene.right),
        (&scene.rpc_left, &foreign),
        &out,
        &[],
    );
    assert_eq!(code(&o), 1, "{}", stderr(&o));
    let e = stderr(&o);
    assert!(
        e.contains("is this the RPC of another image?") && e.contains("foreign.json"),
        "{e}"
    );
    assert_plain(&e);
    assert!(!out.exists());
}

/// Defect 4: a missing input is named once, with one line, by every subcommand that reads files.
#[test]
fn every_subcommand_names_a_missing_input_once() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("missing_input.tif");
    let m = missing.to_str().unwrap();
    let other = dir.path().join("other.iio");
    raster::write_image(&other, &raster::Image::filled(16, 16, 1, 0.0)).unwrap();
    let x = other.to_str().unwrap();
    let out = dir.path().join("out");
    let o_ = out.to_str().unwrap();
    // DSMs are written under a GeoTIFF name only.
    let dsm_out = dir.path().join("out.tif");
    let d_ = dsm_out.to_str().unwrap();
    let cases: Vec<Vec<&str>> = vec![
        vec!["reconstruct", m, x, "-o", d_],
        vec!["predict", m, x, "-o", o_],
        vec!["rectify", m, x, "-o", o_],
        vec!["score", m, "--truth", x],
        vec![
            "dsm",
            m,
            "--homography",
            x,
            "--rpc-left",
            x,
            "--rpc-right",
            x,
            "-o",
            d_,
        ],
        vec!["eval", "--world", m, "--output", o_],
        vec!["teacher", "--pairs", m, "--output", o_],
        vec!["curate", "--pairs", m, "--teacher", x, "--output", o_],
        vec!["masks", "--images", m, "--output", o_],
        vec!["masks-score", "--masks", m, "--rpc-dir", x, "--truth", x],
        vec!["synthesize", "--pairs", m, "--raw", x],
        vec![
            "dataset",
            "build",
            "--pairs",
            m,
            "--teacher",
            x,
            "--output",
            o_,
        ],
        vec!["train", "--config", "tiny", "--data", m, "--output", o_],
    ];
    for args in cases {
        let o = seasonstereo(&args);
        let e = stderr(&o);
        assert_eq!(code(&o), 1, "{args:?}: {e}");
        assert_eq!(e.matches("missing_input").count(), 1, "{args:?}: {e}");
        let errors: Vec<&str> = e.lines().filter(|l| l.starts_with("error: ")).collect();
        assert_eq!(errors.len(), 1, "{args:?}: one error line: {e}");
        assert!(errors[0].contains("missing_input"), "{args:?}: {e}");
        assert_plain(&e);
    }
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Some tiles failing exits 2 naming them (the DSM holds the others; --allow-partial makes it 0
/// with a warning); all tiles failing exits 3 and writes nothing.
#[test]
fn failing_tiles_exit_2_when_some_and_3_when_all() {
    let dir = tempfile::tempdir().unwrap();
    let scene = Scene::new(dir.path(), 768);
    // The raw views are 768² in 256² TIFF tiles: damage the bottom-right one.
    damage_tiles(&scene.left, |r, c| r == 2 && c == 2);
    let out = dir.path().join("partial.tif");
    let o = scene.reconstruct(&out, &["--tile", "256"]);
    let e = stderr(&o);
    assert_eq!(code(&o), 2, "{e}\n{}", stdout(&o));
    assert!(
        e.contains("failed (r001_c001") || e.contains("failed (r00"),
        "{e}"
    );
    assert!(e.contains("r002_c002"), "{e}");
    assert!(out.is_file(), "the DSM of the other tiles is written");
    let o = scene.reconstruct(&out, &["--tile", "256", "--allow-partial"]);
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    assert!(stderr(&o).contains("warning:"), "{}", stderr(&o));

    damage_tiles(&scene.left, |_, _| true);
    let nothing = dir.path().join("nothing.tif");
    let o = scene.reconstruct(&nothing, &["--tile", "256"]);
    assert_eq!(code(&o), 3, "{}\n{}", stderr(&o), stdout(&o));
    assert!(stderr(&o).contains("no DSM written"), "{}", stderr(&o));
    assert!(!nothing.exists());
}

/// A write that fails (the disk full, here a file-size limit) never reports success and never
/// replaces the DSM it was to overwrite: the old one stays byte-identical, no temporary is left.
#[test]
fn a_failing_write_keeps_the_old_dsm() {
    use std::os::unix::process::CommandExt;
    let dir = tempfile::tempdir().unwrap();
    let scene = Scene::new(dir.path(), 256);
    let out_dir = dir.path().join("dsm");
    std::fs::create_dir(&out_dir).unwrap();
    let out = out_dir.join("dsm.tif");
    std::fs::write(&out, b"yesterday's DSM").unwrap();
    let mut command = Command::new(env!("CARGO_BIN_EXE_seasonstereo"));
    command.args([
        "reconstruct",
        scene.left.to_str().unwrap(),
        scene.right.to_str().unwrap(),
        "--rpc-left",
        scene.rpc_left.to_str().unwrap(),
        "--rpc-right",
        scene.rpc_right.to_str().unwrap(),
        "--overwrite",
        "-o",
        out.to_str().unwrap(),
    ]);
    // SAFETY: only async-signal-safe calls between fork and exec.
    unsafe {
        command.pre_exec(|| {
            // Writes past 2 KiB fail with EFBIG instead of killing the process.
            libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
            let limit = libc::rlimit {
                rlim_cur: 2048,
                rlim_max: 2048,
            };
            if libc::setrlimit(libc::RLIMIT_FSIZE, &limit) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    let o = command.output().unwrap();
    assert!(matches!(code(&o), 2 | 3), "{}\n{}", stderr(&o), stdout(&o));
    assert_eq!(std::fs::read(&out).unwrap(), b"yesterday's DSM");
    // Beside the old DSM only its work folder (kept for the rerun), no temporary.
    let mut left: Vec<_> = std::fs::read_dir(&out_dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    left.sort();
    assert_eq!(left, ["dsm.tif", "dsm_work"], "{left:?}");
    assert!(stderr(&o).contains("no DSM written"), "{}", stderr(&o));
    assert_plain(&stderr(&o));
}

/// A run killed midway resumes: the rerun redoes only the tiles that had not finished, and its
/// DSM is the one of an uninterrupted run.
#[test]
fn a_killed_run_resumes_and_matches_an_uninterrupted_one() {
    let dir = tempfile::tempdir().unwrap();
    let scene = Scene::new(dir.path(), 512);
    let whole = dir.path().join("whole.tif");
    let o = scene.reconstruct(&whole, &["--tile", "128"]);
    assert_eq!(code(&o), 0, "{}", stderr(&o));

    let out = dir.path().join("killed.tif");
    let mut child = Command::new(env!("CARGO_BIN_EXE_seasonstereo"))
        .args([
            "reconstruct",
            scene.left.to_str().unwrap(),
            scene.right.to_str().unwrap(),
            "--rpc-left",
            scene.rpc_left.to_str().unwrap(),
            "--rpc-right",
            scene.rpc_right.to_str().unwrap(),
            "--tile",
            "128",
            "-o",
            out.to_str().unwrap(),
        ])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let tiles = dir.path().join("killed_work/tiles");
    let records = || {
        std::fs::read_dir(&tiles).map_or(0, |d| {
            d.filter(|e| {
                e.as_ref()
                    .is_ok_and(|e| e.path().extension().is_some_and(|x| x == "json"))
            })
            .count()
        })
    };
    let start = std::time::Instant::now();
    while records() < 2 && start.elapsed().as_secs() < 120 {
        if child.try_wait().unwrap().is_some() {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let _ = child.kill();
    child.wait().unwrap();
    let finished = records();
    assert!(finished >= 1, "no tile finished before the kill");
    let o = scene.reconstruct(&out, &["--tile", "128"]);
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    let ran: usize = stdout(&o)
        .split(" run now")
        .next()
        .and_then(|s| s.rsplit(' ').next())
        .and_then(|n| n.parse().ok())
        .expect("the tiles line says how many ran");
    let total: usize = stdout(&o)
        .split("tiles: ")
        .nth(1)
        .and_then(|s| s.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap();
    assert!(
        ran + finished <= total,
        "{ran} rerun + {finished} kept > {total}"
    );
    let a = raster::read_image(&whole).unwrap();
    let b = raster::read_image(&out).unwrap();
    assert_eq!(a.size(), b.size());
    let same = a
        .data()
        .iter()
        .zip(b.data())
        .all(|(p, q)| p == q || (p.is_nan() && q.is_nan()));
    assert!(same, "the resumed DSM differs from the uninterrupted one");
}

/// A read-only output folder is refused before any work (exit 1), naming the folder. As root,
/// whom permissions do not stop, the run is made as the unprivileged user `nobody`.
#[test]
fn a_read_only_output_folder_is_refused_before_work() {
    use std::os::unix::fs::PermissionsExt;
    use std::os::unix::process::CommandExt;
    let dir = tempfile::tempdir().unwrap();
    std::fs::set_permissions(dir.path(), std::fs::Permissions::from_mode(0o755)).unwrap();
    let scene = Scene::new(dir.path(), 256);
    let before = snapshot(&scene.inputs());
    let locked = dir.path().join("locked");
    std::fs::create_dir(&locked).unwrap();
    std::fs::set_permissions(&locked, std::fs::Permissions::from_mode(0o555)).unwrap();
    let out = locked.join("dsm.tif");
    // SAFETY: getuid is a plain system call.
    let root = unsafe { libc::getuid() } == 0;
    let binary = if root {
        // A copy that `nobody` may run wherever the clone lives.
        let copy = dir.path().join("seasonstereo");
        std::fs::copy(env!("CARGO_BIN_EXE_seasonstereo"), &copy).unwrap();
        copy
    } else {
        PathBuf::from(env!("CARGO_BIN_EXE_seasonstereo"))
    };
    let mut command = Command::new(binary);
    command.args([
        "reconstruct",
        scene.left.to_str().unwrap(),
        scene.right.to_str().unwrap(),
        "--rpc-left",
        scene.rpc_left.to_str().unwrap(),
        "--rpc-right",
        scene.rpc_right.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    if root {
        command.uid(65534).gid(65534);
    }
    let o = command.output().unwrap();
    let e = stderr(&o);
    assert_eq!(code(&o), 1, "{e}");
    assert!(
        e.contains("cannot be written") && e.contains("locked"),
        "{e}"
    );
    assert_eq!(std::fs::read_dir(&locked).unwrap().count(), 0);
    assert_unchanged(&before);
}

/// Defect 3, swapped cameras: on real pairs (DFC2019 JAX_068, bundle-adjusted RPCs) each image
/// with its own camera runs without a camera warning; with the two cameras swapped the rectified
/// views disagree by rows (003–004), or, where too few patches match to measure that, matching
/// finds almost nothing (013–014): both warn naming the two cameras.
#[test]
fn swapped_cameras_are_warned_about() {
    let d = testdata::require!("data/dfc2019-jax068-dev");
    let dir = tempfile::tempdir().unwrap();
    let image = |id: &str| d.join(format!("images/JAX_068_{id}_RGB.tif"));
    let camera = |id: &str| d.join(format!("rpcs/ba/JAX_068_{id}_RGB.json"));
    let run = |(a, b): (&str, &str), (ca, cb): (&str, &str)| {
        let out = dir.path().join(format!("{a}-{b}-{ca}.tif"));
        let mut args = vec!["reconstruct".to_string()];
        for p in [image(a), image(b)] {
            args.push(p.to_string_lossy().into_owned());
        }
        for (flag, p) in [("--rpc-left", camera(ca)), ("--rpc-right", camera(cb))] {
            args.extend([flag.to_string(), p.to_string_lossy().into_owned()]);
        }
        args.extend(["-o".to_string(), out.to_string_lossy().into_owned()]);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = seasonstereo(&args);
        assert_eq!(code(&o), 0, "{}", stderr(&o));
        stderr(&o)
    };
    let own = run(("003", "004"), ("003", "004"));
    assert!(!own.contains("swapped?"), "{own}");
    let swapped = run(("003", "004"), ("004", "003"));
    assert!(
        swapped.contains("disagree by")
            && swapped.contains("JAX_068_004_RGB.json belongs to the left"),
        "{swapped}"
    );
    let unmatched = run(("013", "014"), ("014", "013"));
    assert!(
        unmatched.contains("matched along the rows") && unmatched.contains("swapped?"),
        "{unmatched}"
    );
}

/// Every file under `dir` with its bytes.
fn tree(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut files = BTreeMap::new();
    let mut todo = vec![dir.to_path_buf()];
    while let Some(d) = todo.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                todo.push(path);
            } else {
                files.insert(path.clone(), std::fs::read(&path).unwrap());
            }
        }
    }
    files
}

fn assert_same_tree(dir: &Path, before: &BTreeMap<PathBuf, Vec<u8>>) {
    let now = tree(dir);
    let names = |t: &BTreeMap<PathBuf, Vec<u8>>| t.keys().cloned().collect::<Vec<_>>();
    assert_eq!(names(&now), names(before), "files added or removed");
    for (path, bytes) in before {
        assert!(&now[path] == bytes, "{} changed", path.display());
    }
}

/// `reconstruct-many` of the scene's pair (one pair) onto `output`, with `extra` flags.
fn many(scene: &Scene, output: &Path, extra: &[&str]) -> Output {
    let rpc_dir = scene.rpc_left.parent().unwrap();
    let mut args = vec![
        "reconstruct-many",
        scene.left.to_str().unwrap(),
        scene.right.to_str().unwrap(),
        "--rpc-dir",
        rpc_dir.to_str().unwrap(),
        "--pairs",
        "1",
        "-o",
        output.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    seasonstereo(&args)
}

/// Issue 51, defect 1: `reconstruct-many` of three dates (the best 2 pairs) onto the DSM of a
/// `reconstruct` run, whose work folder it would take for its own, exits 1 before any work,
/// naming the DSM and the other command, and every existing file stays byte-identical. With
/// `--overwrite` the other run's work folder is cleared and no sidecar of the old DSM stays
/// beside the new one.
#[test]
fn another_command_onto_an_existing_dsm_is_refused_and_every_file_kept() {
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
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    let image = |k: usize| s(&world.join(format!("raw/WORLD_1_D{k}.tif")));
    let camera = |k: usize| s(&world.join(format!("rpc/WORLD_1_D{k}.json")));
    let out_dir = dir.path().join("out");
    let out = out_dir.join("dsm.tif");
    let o = seasonstereo(&[
        "reconstruct",
        &image(1),
        &image(2),
        "--rpc-left",
        &camera(1),
        "--rpc-right",
        &camera(2),
        "-o",
        &s(&out),
    ]);
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    assert!(out_dir.join("dsm_filled.tif").is_file());
    let before = tree(&out_dir);
    let rpc_dir = s(&world.join("rpc"));
    let (a, b, c) = (image(1), image(2), image(3));
    let out_arg = s(&out);
    let many = |extra: &[&str]| {
        let mut args: Vec<&str> = vec![
            "reconstruct-many",
            &a,
            &b,
            &c,
            "--rpc-dir",
            &rpc_dir,
            "--pairs",
            "2",
            "-o",
            &out_arg,
        ];
        args.extend_from_slice(extra);
        seasonstereo(&args)
    };
    let o = many(&[]);
    let e = stderr(&o);
    assert_eq!(code(&o), 1, "{e}\n{}", stdout(&o));
    assert!(
        e.contains("dsm.tif already exists")
            && e.contains("`reconstruct`")
            && e.contains("--overwrite"),
        "{e}"
    );
    assert_eq!(e.lines().count(), 1, "one line: {e}");
    assert_plain(&e);
    assert_same_tree(&out_dir, &before);

    let o = many(&["--overwrite"]);
    assert_eq!(code(&o), 0, "{}\n{}", stderr(&o), stdout(&o));
    assert!(
        !out_dir.join("dsm_filled.tif").exists(),
        "reconstruct's sidecar left beside the fused DSM"
    );
    for f in ["dsm_count.tif", "dsm_spread.tif", "dsm_report.json"] {
        assert!(out_dir.join(f).is_file(), "{f}");
    }
    assert!(
        !out_dir.join("dsm_work/tiles").exists(),
        "the other run's tiles are cleared"
    );
}

/// A path as an argument.
fn s(p: &Path) -> String {
    p.to_str().unwrap().to_string()
}

/// Issue 51, defect 3: a DSM path that is not a GeoTIFF is refused before any work by every
/// command that writes a DSM, naming the supported extensions; their case does not matter.
#[test]
fn a_dsm_is_written_under_a_geotiff_name_only() {
    let dir = tempfile::tempdir().unwrap();
    let scene = Scene::new(dir.path(), 256);
    for name in ["cloud.las", "dsm.png", "dsm"] {
        let out = dir.path().join(name);
        let dsm = seasonstereo(&[
            "dsm",
            &s(&scene.left),
            "--homography",
            &s(&scene.right),
            "--rpc-left",
            &s(&scene.rpc_left),
            "--rpc-right",
            &s(&scene.rpc_right),
            "-o",
            &s(&out),
        ]);
        for o in [scene.reconstruct(&out, &[]), many(&scene, &out, &[]), dsm] {
            let e = stderr(&o);
            assert_eq!(code(&o), 1, "{name}: {e}\n{}", stdout(&o));
            assert!(e.contains(".tif or .tiff"), "{name}: {e}");
            assert_eq!(e.lines().count(), 1, "one line: {e}");
        }
        assert!(!out.exists(), "{name} written");
        let stem = name.split('.').next().unwrap();
        assert!(!dir.path().join(format!("{stem}_work")).exists());
    }
    let upper = dir.path().join("DSM.TIFF");
    let o = scene.reconstruct(&upper, &[]);
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    assert!(upper.is_file() && dir.path().join("DSM_filled.tif").is_file());
}

/// Issue 51, defect 5: `-o` reused for another pair is refused naming the existing DSM (not the
/// work folder's tiles), and so is a rerun with other finishing options, every file kept. With
/// `--overwrite` the rerun reuses the tiles and rewrites the DSM; the same command then resumes.
#[test]
fn another_pair_or_other_finishing_onto_a_dsm_needs_overwrite() {
    let dir = tempfile::tempdir().unwrap();
    let scene = Scene::new(dir.path(), 256);
    let out_dir = dir.path().join("out");
    let out = out_dir.join("dsm.tif");
    let o = scene.reconstruct(&out, &[]);
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    let before = tree(&out_dir);
    let o = scene.reconstruct_with(
        (&scene.right, &scene.left),
        (&scene.rpc_right, &scene.rpc_left),
        &out,
        &[],
    );
    let e = stderr(&o);
    assert_eq!(code(&o), 1, "{e}");
    assert!(
        e.contains("dsm.tif already exists") && e.contains("--overwrite"),
        "{e}"
    );
    assert!(!e.contains("holds tiles computed"), "{e}");
    assert_same_tree(&out_dir, &before);

    let o = scene.reconstruct(&out, &["--median-filter", "5"]);
    let e = stderr(&o);
    assert_eq!(code(&o), 1, "{e}\n{}", stdout(&o));
    assert!(
        e.contains("dsm.tif already exists") && e.contains("median_filter"),
        "{e}"
    );
    assert_same_tree(&out_dir, &before);

    let o = scene.reconstruct(&out, &["--median-filter", "5", "--overwrite"]);
    assert_eq!(code(&o), 0, "{}", stderr(&o));
    assert!(stdout(&o).contains(" 0 run now"), "{}", stdout(&o));
    assert!(
        std::fs::read(&out).unwrap() != before[&out],
        "DSM not rewritten"
    );
    let o = scene.reconstruct(&out, &["--median-filter", "5"]);
    assert_eq!(code(&o), 0, "{}", stderr(&o));
}

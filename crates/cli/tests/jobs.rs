//! `seasonstereo jobs` against a fake Slurm: `sbatch`, `sinfo` written into a temp folder on
//! PATH; `sbatch` logs its arguments (one `[word]` each) and runs the job script at once, each
//! array index in turn, so a submission is a complete run. Checked: arguments and quoting (paths
//! with spaces, `--sbatch-args`), the array size, the `afterany` merge, the DSM byte-identical to
//! a local `reconstruct`, a failed tile named by `jobs status` (exit 2) and the merge refusing it
//! (exit 3), and `jobs resubmit` sending only the failed tasks. The fake honours dependencies:
//! a job `afterok` on a failed one is cancelled with `--kill-on-invalid-dep=yes` (and, like
//! Slurm 22.05, `sbatch --wait` on it exits 0) and logged as pending for ever without. `jobs slurm dataset`: the stages' arguments passed through (spaces,
//! quotes), arrays of --shards tasks, `afterany` checks, a failed teacher shard named by the
//! check step with the resubmit command and the rest of the chain cancelled, and `jobs resubmit`
//! sending exactly that shard, then the later stages, to the same training set.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const SBATCH: &str = r#"#!/bin/sh
log="$FAKE_SLURM_LOG"; n=$(( $(cat "$log.count" 2>/dev/null || echo 0) + 1 )); echo $n > "$log.count"
printf 'sbatch' >> "$log"; for a in "$@"; do printf ' [%s]' "$a" >> "$log"; done; echo >> "$log"
array=""; wait=0; dep=""; kill=0
for a in "$@"; do case "$a" in --array=*) array=${a#--array=};; --wait) wait=1;; --dependency=*) dep=${a#--dependency=};; --kill-on-invalid-dep=yes) kill=1;; esac; script=$a; done
case "$dep" in afterok:*)
  if [ "$(cat "$log.exit.${dep#afterok:}")" != 0 ]; then
    echo 1 > "$log.exit.$n"; echo "$n"
    if [ $kill = 1 ]; then echo "job $n cancelled (dependency never satisfied)" >> "$log"; exit 0; fi
    echo "job $n pending for ever (DependencyNeverSatisfied)" >> "$log"; exit 0
  fi;;
esac
rc=0; state=0
if [ -n "$array" ]; then
  for part in $(echo "$array" | tr ',' ' '); do
    lo=${part%-*}; hi=${part#*-}; i=$lo
    while [ $i -le $hi ]; do SLURM_ARRAY_TASK_ID=$i sh "$script" >> "$log.out" 2>&1 || { echo "task $i exit $?" >> "$log"; state=1; }; i=$((i+1)); done
  done
else
  sh "$script" >> "$log.out" 2>&1; rc=$?; state=$rc; echo "job $n exit $rc" >> "$log"
fi
echo $state > "$log.exit.$n"
echo "$n"
[ $wait = 1 ] && exit $rc; exit 0
"#;

struct Cluster {
    bin: PathBuf,
    log: PathBuf,
}

impl Cluster {
    fn new(dir: &Path) -> Cluster {
        let bin = dir.join("fake slurm");
        std::fs::create_dir_all(&bin).unwrap();
        std::fs::write(bin.join("sbatch"), SBATCH).unwrap();
        std::fs::write(bin.join("sinfo"), "#!/bin/sh\necho 2\n").unwrap();
        // The jobs still queued: those listed in `<log>.queue` (the fake runs every job at once).
        let squeue = "#!/bin/sh\ncat \"$FAKE_SLURM_LOG.queue\" 2>/dev/null; exit 0\n";
        std::fs::write(bin.join("squeue"), squeue).unwrap();
        for tool in ["sbatch", "sinfo", "squeue"] {
            let p = bin.join(tool);
            let mut perm = std::fs::metadata(&p).unwrap().permissions();
            std::os::unix::fs::PermissionsExt::set_mode(&mut perm, 0o755);
            std::fs::set_permissions(&p, perm).unwrap();
        }
        Cluster {
            log: dir.join("sbatch.log"),
            bin,
        }
    }

    fn run(&self, args: &[&str]) -> Output {
        let path = format!("{}:{}", self.bin.display(), std::env::var("PATH").unwrap());
        Command::new(env!("CARGO_BIN_EXE_seasonstereo"))
            .args(args)
            .env("PATH", path)
            .env("FAKE_SLURM_LOG", &self.log)
            .output()
            .unwrap()
    }

    fn log(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    /// Makes `squeue` list these job ids as still queued or running (none: an empty queue).
    fn queue(&self, ids: &[&str]) {
        let mut path = self.log.clone().into_os_string();
        path.push(".queue");
        std::fs::write(
            path,
            ids.iter().map(|i| format!("{i}\n")).collect::<String>(),
        )
        .unwrap();
    }
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// `reconstruct` arguments of the raw world in `root` onto `out`.
fn scene_args(root: &Path, out: &Path) -> Vec<String> {
    let p = |s: &str| root.join(s).display().to_string();
    let mut v = vec![p("raw/WORLD_3_A.tif"), p("raw/WORLD_3_B.tif")];
    for (flag, value) in [
        ("--rpc-left", p("rpc/WORLD_3_A.json")),
        ("--rpc-right", p("rpc/WORLD_3_B.json")),
    ] {
        v.extend([flag.to_string(), value]);
    }
    v.extend(["--tile", "256", "--median-filter", "5", "-o"].map(String::from));
    v.push(out.display().to_string());
    v
}

/// Overwrites the compressed data of the image's TIFF tile (row 2, col 2): reading a window that
/// touches it fails.
fn damage_last_tile(path: &Path) {
    use tiff::tags::Tag;
    let mut decoder = tiff::decoder::Decoder::new(std::fs::File::open(path).unwrap()).unwrap();
    let offsets = decoder.get_tag_u64_vec(Tag::TileOffsets).unwrap();
    let counts = decoder.get_tag_u64_vec(Tag::TileByteCounts).unwrap();
    let (o, c) = (
        *offsets.last().unwrap() as usize,
        *counts.last().unwrap() as usize,
    );
    let mut bytes = std::fs::read(path).unwrap();
    bytes[o..o + c].fill(0xA5);
    std::fs::write(path, bytes).unwrap();
}

fn submit(cluster: &Cluster, args: &[String], extra: &[&str]) -> Output {
    let mut all = vec!["jobs", "slurm", "reconstruct"];
    all.extend(args.iter().map(String::as_str));
    all.extend_from_slice(extra);
    cluster.run(&all)
}

#[test]
fn a_submission_gives_the_local_dsm_and_failed_tiles_are_named_and_resubmitted() {
    let dir = tempfile::tempdir().unwrap();
    let cluster = Cluster::new(dir.path());
    let root = dir.path().join("my world");
    let o = cluster.run(&[
        "world",
        "--size",
        "768",
        "--seed",
        "3",
        "--raw",
        "-o",
        root.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let local = dir.path().join("local.tif");
    let mut args = vec!["reconstruct".to_string()];
    args.extend(scene_args(&root, &local));
    let o = run_strings(&cluster, &args);
    assert!(o.status.success(), "{}", text(&o));

    let out = dir.path().join("out dir/slurm dsm.tif");
    let extra = [
        "--tiles-per-task",
        "2",
        "--sbatch-args",
        "-p debug --comment 'a b'",
        "--wait",
    ];
    let o = submit(&cluster, &scene_args(&root, &out), &extra);
    assert!(o.status.success(), "{}\n{}", text(&o), cluster.log());
    let log = cluster.log();
    // 9 tiles, 2 per task: 5 tasks; the user's options after ours, one word each.
    assert!(log.contains("[--array=0-4]"), "{log}");
    assert!(log.contains("[--dependency=afterany:1] [--wait]"), "{log}");
    assert!(log.contains("[-p] [debug] [--comment] [a b]"), "{log}");
    assert!(log.contains("[--cpus-per-task=2]"), "{log}");
    assert_eq!(std::fs::read(&out).unwrap(), std::fs::read(&local).unwrap());
    let work = dir.path().join("out dir/slurm dsm_work");
    let script = std::fs::read_to_string(work.join("jobs/reconstruct-tiles.sh")).unwrap();
    assert!(
        script.contains("'-o' ") || script.contains(" -o '"),
        "{script}"
    );
    assert!(script.contains("--median-filter 5"), "{script}");
    let o = cluster.run(&["jobs", "status", "--work", work.to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o));

    // A damaged image: the tiles touching its last TIFF tile fail, the merge refuses (3).
    let left = root.join("raw/WORLD_3_A.tif");
    let good = std::fs::read(&left).unwrap();
    damage_last_tile(&left);
    let failing = dir.path().join("failing/dsm.tif");
    let o = submit(
        &cluster,
        &scene_args(&root, &failing),
        &["--tiles-per-task", "1", "--wait"],
    );
    assert_eq!(o.status.code(), Some(3), "{}\n{}", text(&o), cluster.log());
    assert!(!failing.exists());
    let work = dir.path().join("failing/dsm_work");
    let o = cluster.run(&["jobs", "status", "--work", work.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(
        text(&o).contains("failed  r002_c002 (task 8)"),
        "{}",
        text(&o)
    );
    assert!(
        text(&o).contains("seasonstereo jobs resubmit --work"),
        "{}",
        text(&o)
    );

    std::fs::write(&left, good).unwrap();
    // While the tile array is still queued, resubmitting would run its tiles twice: refused.
    cluster.queue(&["1", "2", "3", "4"]);
    let before = cluster.log().len();
    let resubmit = [
        "jobs",
        "resubmit",
        "--work",
        work.to_str().unwrap(),
        "--wait",
    ];
    let o = cluster.run(&resubmit);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(
        text(&o).contains("job(s) 3, 4 of this work folder are still queued"),
        "{}",
        text(&o)
    );
    assert!(text(&o).contains("scancel 3 4"), "{}", text(&o));
    assert_eq!(cluster.log().len(), before, "nothing submitted");
    cluster.queue(&[]);
    let o = cluster.run(&resubmit);
    assert!(o.status.success(), "{}\n{}", text(&o), cluster.log());
    let resubmitted = cluster.log()[before..].to_string();
    assert!(resubmitted.contains("[--array=4,5,7,8]"), "{resubmitted}");
    assert_eq!(
        std::fs::read(&failing).unwrap(),
        std::fs::read(&local).unwrap()
    );
}

/// `jobs slurm dataset` arguments of the world sources in `src` onto `work` and `out`.
fn dataset_args(src: &Path, work: &Path, out: &Path) -> Vec<String> {
    let p = |p: &Path| p.display().to_string();
    let mut v: Vec<String> = ["jobs", "slurm", "dataset", "--pairs"]
        .map(String::from)
        .to_vec();
    v.extend([p(&src.join("pairs")), "--raw".into(), p(&src.join("raw"))]);
    v.extend(["--work".into(), p(work), "-o".into(), p(out)]);
    v.extend(
        [
            "--shards",
            "2",
            "--curate-args",
            "--keep 100%",
            "--build-args",
            "--teacher-name 'sgm x' --seed 3",
            "--sbatch-args",
            "-p debug --comment 'a b'",
            "--stage-sbatch-args",
            "teacher=--gres=gpu:1 --comment 'on a gpu'",
            "--wait",
        ]
        .map(String::from),
    );
    v
}

fn run_strings(cluster: &Cluster, args: &[String]) -> Output {
    cluster.run(&args.iter().map(String::as_str).collect::<Vec<_>>())
}

#[test]
fn dataset_stages_chain_with_checks_and_a_failed_shard_is_resubmitted_alone() {
    let dir = tempfile::tempdir().unwrap();
    let cluster = Cluster::new(dir.path());
    let world = dir.path().join("world set");
    let o = cluster.run(&[
        "dataset",
        "world",
        "--size",
        "128",
        "--worlds",
        "3",
        "-o",
        world.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let src = world.join("sources/train");

    // A typo in a stage's options fails before anything is submitted.
    let mut bad = dataset_args(&src, &dir.path().join("w0"), &dir.path().join("s0"));
    let at = bad.iter().position(|a| a == "--keep 100%").unwrap();
    bad[at] = "--kepp 3".into();
    let o = run_strings(&cluster, &bad);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(text(&o).contains("fix --curate-args"), "{}", text(&o));
    assert!(cluster.log().is_empty(), "{}", cluster.log());
    // So does a stage that does not exist.
    let mut bad = dataset_args(&src, &dir.path().join("w0"), &dir.path().join("s0"));
    let at = bad.iter().position(|a| a.starts_with("teacher=")).unwrap();
    bad[at] = "teachr=--gres=gpu:1".into();
    let o = run_strings(&cluster, &bad);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(
        text(&o).contains("no stage teachr (the stages: teacher,"),
        "{}",
        text(&o)
    );
    assert!(cluster.log().is_empty(), "{}", cluster.log());

    // The whole chain: 5 arrays of 2 tasks, a check after each, the finalize.
    let (work, out) = (dir.path().join("my work"), dir.path().join("my set"));
    let o = run_strings(&cluster, &dataset_args(&src, &work, &out));
    assert!(o.status.success(), "{}\n{}", text(&o), cluster.log());
    let log = cluster.log();
    assert_eq!(log.matches("[--array=0-1]").count(), 5, "{log}");
    for (stage, check, next) in [(1, 2, 3), (3, 4, 5), (5, 6, 7), (7, 8, 9), (9, 10, 11)] {
        assert!(
            log.contains(&format!("[--dependency=afterany:{stage}]")),
            "{log}"
        );
        let after = format!("[--dependency=afterok:{check}] [--kill-on-invalid-dep=yes]");
        assert!(log.contains(&after), "{next}: {log}");
    }
    assert!(log.contains("[-p] [debug] [--comment] [a b]"), "{log}");
    // The teacher's array alone gets its own options, after the chain's.
    let gpu: Vec<&str> = log
        .lines()
        .filter(|l| l.contains("[--gres=gpu:1]"))
        .collect();
    assert_eq!(gpu.len(), 1, "{log}");
    assert!(gpu[0].contains("[--job-name=ss-teacher]"), "{log}");
    assert!(
        gpu[0].contains("[a b] [--gres=gpu:1] [--comment] [on a gpu]"),
        "{log}"
    );
    assert!(!log.lines().any(|l| l.starts_with("task ")), "{log}");
    assert!(
        !log.lines()
            .any(|l| l.starts_with("job ") && !l.ends_with("exit 0")),
        "{log}"
    );
    assert!(out.join("manifest.json").is_file());
    assert!(out.join("disparity_maps/sgm x").is_dir());
    let script = std::fs::read_to_string(work.join("jobs/build.sh")).unwrap();
    assert!(
        script.contains("--teacher-name 'sgm x' --seed 3"),
        "{script}"
    );
    assert!(script.contains("--shard \"$i/2\""), "{script}");
    let o = cluster.run(&["jobs", "status", "--work", work.to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(
        text(&o).contains("teacher    2 shards: 2 done"),
        "{}",
        text(&o)
    );

    // Teacher shard 0 fails (its first pair's output path is taken by a folder): the check
    // names it and the resubmit command, the rest of the chain is cancelled, not left pending.
    let mut stems: Vec<String> = std::fs::read_dir(src.join("pairs/L"))
        .unwrap()
        .map(|e| {
            e.unwrap()
                .path()
                .file_stem()
                .unwrap()
                .to_string_lossy()
                .into()
        })
        .collect();
    stems.sort();
    let (work, out) = (
        dir.path().join("failing work"),
        dir.path().join("failing set"),
    );
    let blocker = work.join("teacher").join(format!("{}.iio", stems[0]));
    std::fs::create_dir_all(blocker.join("x")).unwrap();
    let before = cluster.log().len();
    let o = run_strings(&cluster, &dataset_args(&src, &work, &out));
    assert_eq!(o.status.code(), Some(2), "{}\n{}", text(&o), cluster.log());
    let log = cluster.log()[before..].to_string();
    assert!(log.contains("task 0 exit"), "{log}");
    assert!(!log.contains("task 1 exit"), "{log}");
    assert_eq!(log.matches("cancelled").count(), 5, "{log}");
    assert!(!log.contains("pending for ever"), "{log}");
    assert!(!out.join("manifest.json").exists());
    let checks = std::fs::read_to_string(format!("{}.out", cluster.log.display())).unwrap();
    assert!(
        checks.contains("failed  teacher shard 0/2 (task 0): exit code 2"),
        "{checks}"
    );
    assert!(
        checks.contains("seasonstereo jobs resubmit --work"),
        "{checks}"
    );
    let o = cluster.run(&["jobs", "status", "--work", work.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(
        text(&o).contains("teacher    2 shards: 1 done, 1 failed"),
        "{}",
        text(&o)
    );
    assert!(
        text(&o).contains("missing curate shard 1/2 (task 1)"),
        "{}",
        text(&o)
    );

    std::fs::remove_dir_all(&blocker).unwrap();
    let before = cluster.log().len();
    let o = cluster.run(&[
        "jobs",
        "resubmit",
        "--work",
        work.to_str().unwrap(),
        "--wait",
    ]);
    assert!(o.status.success(), "{}\n{}", text(&o), cluster.log());
    let log = cluster.log()[before..].to_string();
    let first = log.lines().next().unwrap();
    assert!(
        first.contains("[--array=0]") && first.contains("teacher.sh"),
        "{log}"
    );
    assert_eq!(log.matches("[--array=0-1]").count(), 4, "{log}");
    for list in [
        "experiments/sub1_synchronic.csv",
        "experiments/sub5_syndiach.csv",
    ] {
        let a = std::fs::read(dir.path().join("my set").join(list)).unwrap();
        assert_eq!(a, std::fs::read(out.join(list)).unwrap(), "{list}");
    }
    let o = cluster.run(&["jobs", "status", "--work", work.to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o));
}

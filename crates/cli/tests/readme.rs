//! The README's command blocks run as written: every command of every `sh` block is listed in
//! [`PLANS`], as run here or skipped with the reason, and the cheap ones run with the built
//! binary on `PATH`, block after block in one folder (later blocks read what earlier ones wrote).
//! A variable set to `../shared/<set>/…` points at that data set where the tests find it
//! (`testdata`); a block whose data set is absent is skipped like any test that needs it.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

/// What this test does with a README command.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Plan {
    Run,
    Skip(&'static str),
}

use Plan::{Run, Skip};

/// Every README command by the start of its text (whitespace collapsed), and what is done with
/// it. A command that matches no entry, or an entry that matches no command, fails the test.
const PLANS: &[(&str, Plan)] = &[
    (
        "cargo run --release -- demo",
        Skip("the release build; the demo runs in cli.rs"),
    ),
    (
        "cargo test --workspace",
        Skip("the command running this test"),
    ),
    (
        "seasonstereo reconstruct $D/vendor/JAX_068_006_RGB.TIF",
        Run,
    ),
    (
        "pip install ./python",
        Skip("builds the Python package; .ci/run installs it and runs python/tests"),
    ),
    ("seasonstereo score out/jax/006-020.tif", Run),
    (
        "seasonstereo reconstruct-many $D/vendor/*.TIF",
        Skip("12 pairs, about a minute; tests/reconstruct_many.rs runs 4 images, 3 pairs, and \
              the vendor delivery of ten"),
    ),
    ("seasonstereo world --dates --size 384", Run),
    (
        "seasonstereo reconstruct-many out/world-dates/raw/*.tif",
        Run,
    ),
    (
        "seasonstereo jobs slurm reconstruct left.tif",
        Skip("needs a Slurm cluster: tests/jobs.rs runs it against a fake sbatch"),
    ),
    (
        "bash docs/jobs/reconstruct-many-slurm.sh",
        Skip("needs a Slurm cluster: reconstruct_many.rs runs its shards and fusion directly"),
    ),
    (
        "seasonstereo jobs status --work dsm_work",
        Skip("follows the Slurm submission above"),
    ),
    (
        "seasonstereo jobs resubmit --work dsm_work",
        Skip("follows the Slurm submission above"),
    ),
    (
        "seasonstereo jobs slurm dataset --pairs data/synchronic_only",
        Skip("needs a Slurm cluster and the release's pairs: tests/jobs.rs runs the chain on worlds against a fake sbatch"),
    ),
    (
        "seasonstereo jobs status --work work",
        Skip("follows the Slurm dataset submission above"),
    ),
    (
        "seasonstereo jobs resubmit --work work",
        Skip("follows the Slurm dataset submission above"),
    ),
    ("seasonstereo world --size 512 --seed 1 -o out/world", Run),
    (
        "seasonstereo world --size 4096",
        Skip("a 4096² raw scene: minutes in a test build"),
    ),
    (
        "seasonstereo reconstruct out/w4096/",
        Skip("the 4096² scene (73 s in release)"),
    ),
    ("seasonstereo predict --method sgm --range 0:48", Run),
    (
        "seasonstereo demo --size 1024",
        Skip("four times the default demo, which cli.rs runs"),
    ),
    ("seasonstereo demo --ablation", Skip("11–12 min on 2 cores")),
    ("seasonstereo dsm out/world/", Run),
    ("seasonstereo eval --world out/world", Run),
    (
        "seasonstereo eval --split",
        Skip("DATA/ stands for the SeasonStereo benchmark release"),
    ),
    ("seasonstereo rectify $D/input_pair/", Run),
    ("seasonstereo predict --range 1:153", Run),
    ("seasonstereo dsm out/s2p/", Run),
    (
        "seasonstereo predict --model monsterpp --weights Mix_all_large.pth",
        Skip("LEFT/RIGHT and the released checkpoint are the user's"),
    ),
    (
        "seasonstereo teacher --pairs P",
        Skip("P and RAW are the user's pairs"),
    ),
    (
        "seasonstereo curate --pairs P",
        Skip("P is the user's pairs"),
    ),
    (
        "seasonstereo synthesize --pairs P",
        Skip("P and RAW are the user's pairs"),
    ),
    (
        "seasonstereo masks --images work/synthetic",
        Skip("the synthesize step above"),
    ),
    (
        "seasonstereo dataset build --pairs P",
        Skip("P is the user's pairs"),
    ),
    ("seasonstereo dataset world --size 256 --worlds 4", Run),
    (
        "seasonstereo train --config tiny",
        Skip("about 4 min on 2 cores"),
    ),
    (
        "seasonstereo train --config d-full",
        Skip("a real training set and the released checkpoint"),
    ),
    (
        "seasonstereo train --resume runs/d-full",
        Skip("the d-full run above"),
    ),
];

/// The README's default data root, which the tests' own root replaces.
const README_DATA_ROOT: &str = "../shared/";

/// One `sh` block: its variable assignments and its commands, continuation lines joined.
#[derive(Debug, Default)]
struct Block {
    assignments: Vec<(String, String)>,
    commands: Vec<String>,
}

fn readme() -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../README.md");
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The `sh` blocks of `markdown`, in order.
fn sh_blocks(markdown: &str) -> Vec<Block> {
    let mut blocks = Vec::new();
    let mut current: Option<Vec<&str>> = None;
    for line in markdown.lines() {
        match (&mut current, line.trim_end()) {
            (None, "```sh") => current = Some(Vec::new()),
            (Some(lines), "```") => {
                blocks.push(parse_block(lines));
                current = None;
            }
            (Some(lines), _) => lines.push(line),
            (None, _) => {}
        }
    }
    assert!(current.is_none(), "README: a ```sh block is not closed");
    blocks
}

fn parse_block(lines: &[&str]) -> Block {
    let mut block = Block::default();
    let mut logical = String::new();
    for line in lines {
        let line = line.trim();
        if logical.is_empty() && (line.is_empty() || line.starts_with('#')) {
            continue;
        }
        match line.strip_suffix('\\') {
            Some(head) => logical.push_str(head),
            None => {
                logical.push_str(line);
                let text = std::mem::take(&mut logical);
                match assignment(&text) {
                    Some(pair) => block.assignments.push(pair),
                    None => block.commands.push(text),
                }
            }
        }
    }
    assert!(logical.is_empty(), "README: a block ends in a continuation");
    block
}

/// `NAME=value  # comment` as (NAME, value).
fn assignment(line: &str) -> Option<(String, String)> {
    let (name, rest) = line.split_once('=')?;
    let valid = !name.is_empty() && name.chars().all(|c| c.is_ascii_uppercase() || c == '_');
    let value = rest.split_whitespace().next().unwrap_or("");
    valid.then(|| (name.to_string(), value.to_string()))
}

/// `command` with its whitespace collapsed and its trailing comment dropped.
fn normalised(command: &str) -> String {
    let code = command.split(" #").next().unwrap_or(command);
    code.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// The plan of `command`: exactly one entry of [`PLANS`] must match it.
fn plan_of(command: &str) -> Plan {
    let text = normalised(command);
    let matches: Vec<&(&str, Plan)> = PLANS.iter().filter(|(k, _)| text.starts_with(k)).collect();
    match matches[..] {
        [(_, plan)] => *plan,
        [] => panic!("README command without a plan in readme.rs's PLANS: {text}"),
        _ => panic!("README command with several plans: {text}"),
    }
}

/// The value of an assignment where the tests find it: a `../shared/<set>/…` path becomes the
/// set's folder (None when the set is absent: the test then skips the block).
fn resolved(value: &str) -> Option<String> {
    let Some(rest) = value.strip_prefix(README_DATA_ROOT) else {
        return Some(value.to_string());
    };
    let set = testdata::SETS
        .iter()
        .find(|s| rest == s.name || rest.starts_with(&format!("{}/", s.name)))
        .unwrap_or_else(|| panic!("README: {value} is in no data set of testdata"));
    let dir = testdata::dataset(set.name)?;
    let below = rest[set.name.len()..].trim_start_matches('/');
    Some(dir.join(below).display().to_string())
}

/// The folder of the binary under test, to put first on `PATH`.
fn binary_dir() -> PathBuf {
    Path::new(env!("CARGO_BIN_EXE_seasonstereo"))
        .parent()
        .unwrap()
        .to_path_buf()
}

/// Runs `command` with bash in `dir`, after the block's assignments, and fails on a non-zero
/// exit or a missing `-o` output.
fn run(command: &str, assignments: &[(String, String)], dir: &Path) {
    let mut script = String::from("set -euo pipefail\n");
    for (name, value) in assignments {
        script.push_str(&format!("{name}='{value}'\n"));
    }
    script.push_str(command);
    let path = format!(
        "{}:{}",
        binary_dir().display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let start = Instant::now();
    let out = Command::new("bash")
        .arg("-c")
        .arg(&script)
        .current_dir(dir)
        .env("PATH", path)
        .output()
        .expect("bash runs");
    println!("ran in {:.1?}: {}", start.elapsed(), normalised(command));
    assert!(
        out.status.success(),
        "README command failed: {command}\nstdout: {}\nstderr: {}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    let words: Vec<&str> = command.split_whitespace().collect();
    if let Some(i) = words.iter().position(|w| *w == "-o") {
        let output = dir.join(words[i + 1]);
        assert!(output.exists(), "{command}: no {}", output.display());
    }
}

#[test]
fn every_readme_command_has_a_plan_and_every_plan_a_command() {
    let blocks = sh_blocks(&readme());
    let commands: Vec<String> = blocks.iter().flat_map(|b| b.commands.clone()).collect();
    assert!(commands.len() >= PLANS.len(), "{commands:#?}");
    for command in &commands {
        plan_of(command);
    }
    for (key, _) in PLANS {
        assert!(
            commands.iter().any(|c| normalised(c).starts_with(key)),
            "PLANS entry {key:?} matches no README command"
        );
    }
}

#[test]
fn the_cheap_readme_commands_run_as_written() {
    let dir = tempfile::tempdir().unwrap();
    for block in sh_blocks(&readme()) {
        let assignments: Option<Vec<(String, String)>> = block
            .assignments
            .iter()
            .map(|(name, value)| resolved(value).map(|v| (name.clone(), v)))
            .collect();
        for command in &block.commands {
            match (plan_of(command), &assignments) {
                (Run, Some(assignments)) => run(command, assignments, dir.path()),
                (Run, None) => println!("skipped (data set absent): {}", normalised(command)),
                (Skip(why), _) => println!("not run ({why}): {}", normalised(command)),
            }
        }
    }
}

#[test]
fn blocks_are_parsed_into_assignments_and_joined_commands() {
    let blocks = sh_blocks(
        "text\n```sh\n# a comment\nD=../shared/x   # where\nseasonstereo a \\\n    --b c\n\n\
         seasonstereo d  # note\n```\n```text\nnot a command\n```\n",
    );
    assert_eq!(blocks.len(), 1);
    assert_eq!(
        blocks[0].assignments,
        vec![("D".to_string(), "../shared/x".to_string())]
    );
    assert_eq!(blocks[0].commands.len(), 2);
    assert_eq!(normalised(&blocks[0].commands[0]), "seasonstereo a --b c");
    assert_eq!(normalised(&blocks[0].commands[1]), "seasonstereo d");
}

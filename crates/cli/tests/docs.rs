//! The documents' shell blocks run as written: the README's and every page of the user guide
//! (`docs/guide`). A block is a ```` ```sh ```` fence; its `NAME=value` lines are assignments,
//! its other lines commands (continuation lines joined). Each document runs in a folder of its
//! own, block after block (later blocks read what earlier ones wrote), with the built binary
//! first on `PATH`. A block is not run when the line above its fence says why
//! (`<!-- not run: why -->`, invisible once rendered), nor a `cargo` command (it builds the
//! binary under test). A variable set to `../shared/<set>/…` points at that data set where the
//! tests find it (`testdata`); a block whose data set is absent is skipped like any test that
//! needs it.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

/// The user guide's source folder, from the workspace's root.
const GUIDE: &str = "docs/guide/src";

/// The documents' default data root, which the tests' own root replaces.
const DATA_ROOT: &str = "../shared/";

/// The marker, on the line just above a fence, of a block the tests do not run
/// (`<!-- not run: why -->`, invisible once rendered).
const NOT_RUN: &str = "<!-- not run:";

/// One `sh` block: its variable assignments and its commands, continuation lines joined.
#[derive(Debug, Default)]
struct Block {
    assignments: Vec<(String, String)>,
    commands: Vec<String>,
    /// Why the block is not run, when a `<!-- not run: … -->` line precedes it.
    not_run: Option<String>,
}

/// The document at `relative` (from the workspace's root).
fn document(relative: &str) -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .join(relative);
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The `sh` blocks of `markdown`, in order.
fn sh_blocks(markdown: &str) -> Vec<Block> {
    let mut blocks = Vec::new();
    let mut current: Option<Vec<&str>> = None;
    let mut previous = "";
    let mut not_run = None;
    for line in markdown.lines() {
        match (&mut current, line.trim_end()) {
            (None, "```sh") => {
                current = Some(Vec::new());
                not_run = not_run_reason(previous);
            }
            (Some(lines), "```") => {
                blocks.push(Block {
                    not_run: not_run.take(),
                    ..parse_block(lines)
                });
                current = None;
            }
            (Some(lines), _) => lines.push(line),
            (None, _) => {}
        }
        previous = line;
    }
    assert!(current.is_none(), "a ```sh block is not closed");
    blocks
}

/// The reason of a `<!-- not run: why -->` line; an empty reason fails.
fn not_run_reason(line: &str) -> Option<String> {
    let rest = line.trim().strip_prefix(NOT_RUN)?;
    let reason = rest
        .trim()
        .strip_suffix("-->")
        .expect("<!-- not run: … --> on one line");
    assert!(
        !reason.trim().is_empty(),
        "a not-run block says why: {line}"
    );
    Some(reason.trim().to_string())
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
    assert!(logical.is_empty(), "a block ends in a continuation");
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

/// The block's assignments where the tests find their data (None when a data set is absent).
fn resolved_assignments(block: &Block) -> Option<Vec<(String, String)>> {
    block
        .assignments
        .iter()
        .map(|(name, value)| resolved(value).map(|v| (name.clone(), v)))
        .collect()
}

/// The value of an assignment where the tests find it: a `../shared/<set>/…` path becomes the
/// set's folder (None when the set is absent).
fn resolved(value: &str) -> Option<String> {
    let Some(rest) = value.strip_prefix(DATA_ROOT) else {
        return Some(value.to_string());
    };
    let set = testdata::SETS
        .iter()
        .find(|s| rest == s.name || rest.starts_with(&format!("{}/", s.name)))
        .unwrap_or_else(|| panic!("{value} is in no data set of testdata"));
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
        "command failed: {command}\nstdout: {}\nstderr: {}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    let words: Vec<&str> = command.split_whitespace().collect();
    if let Some(i) = words.iter().position(|w| *w == "-o") {
        let output = dir.join(words[i + 1]);
        assert!(output.exists(), "{command}: no {}", output.display());
    }
}

/// Runs every block of the document at `relative` that is to run, in a fresh folder.
fn run_document(relative: &str) {
    let dir = tempfile::tempdir().unwrap();
    for block in sh_blocks(&document(relative)) {
        let assignments = resolved_assignments(&block);
        for command in &block.commands {
            let text = normalised(command);
            match (&block.not_run, &assignments) {
                (Some(why), _) => println!("not run ({why}): {text}"),
                _ if text.starts_with("cargo ") => println!("not run (cargo): {text}"),
                (None, Some(assignments)) => run(command, assignments, dir.path()),
                (None, None) => println!("skipped (data set absent): {text}"),
            }
        }
    }
}

#[test]
fn readme() {
    run_document("README.md");
}

/// One test per page of the guide, so that they run side by side.
macro_rules! guide_pages {
    ($($test:ident => $page:literal,)*) => {
        /// The guide's pages, as the tests know them.
        const PAGES: &[&str] = &[$($page),*];
        $(
            #[test]
            fn $test() {
                run_document(&format!("{GUIDE}/{}", $page));
            }
        )*
    };
}

guide_pages! {
    guide_introduction => "introduction.md",
    guide_install => "install.md",
    guide_vendor_delivery => "vendor-delivery.md",
    guide_many_dates => "many-dates.md",
    guide_cameras => "cameras.md",
    guide_whole_scenes => "whole-scenes.md",
    guide_outputs => "outputs.md",
    guide_clusters => "clusters.md",
    guide_python => "python.md",
    guide_evaluation => "evaluation.md",
    guide_training => "training.md",
    guide_matchers => "matchers.md",
    guide_troubleshooting => "troubleshooting.md",
}

#[test]
fn the_tests_know_every_page_of_the_guide_and_only_those() {
    let summary = document(&format!("{GUIDE}/SUMMARY.md"));
    let linked: Vec<&str> = summary
        .split("](")
        .skip(1)
        .filter_map(|rest| rest.split(')').next())
        .collect();
    assert_eq!(linked, PAGES, "SUMMARY.md's pages against the tests' PAGES");
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .join(GUIDE);
    let mut on_disk: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".md") && n != "SUMMARY.md")
        .collect();
    on_disk.sort();
    let mut pages: Vec<String> = PAGES.iter().map(|p| p.to_string()).collect();
    pages.sort();
    assert_eq!(
        on_disk, pages,
        "the .md files of {GUIDE} against SUMMARY.md"
    );
}

#[test]
fn the_readme_opens_with_the_two_fresh_machine_commands() {
    let readme = document("README.md");
    let blocks = sh_blocks(&readme);
    assert_eq!(
        blocks[0].commands,
        ["cargo run --release -- demo", "cargo test --workspace"]
    );
    let lines = readme.lines().count();
    assert!(lines <= 200, "README.md is a front page: {lines} lines");
}

#[test]
fn no_paragraph_runs_over_120_words() {
    let mut documents = vec!["README.md".to_string()];
    documents.extend(PAGES.iter().map(|p| format!("{GUIDE}/{p}")));
    for relative in documents {
        for paragraph in prose_paragraphs(&document(&relative)) {
            let words = paragraph.split_whitespace().count();
            assert!(
                words <= 120,
                "{relative}: a paragraph of {words} words: {paragraph}"
            );
        }
    }
}

/// The prose paragraphs of `markdown`: its lines outside fences, tables and headings, split at
/// blank lines and list items.
fn prose_paragraphs(markdown: &str) -> Vec<String> {
    let mut paragraphs = vec![String::new()];
    let mut in_fence = false;
    for line in markdown.lines().map(str::trim) {
        if line.starts_with("```") {
            in_fence = !in_fence;
        }
        let numbered = line
            .split_once(". ")
            .is_some_and(|(n, _)| !n.is_empty() && n.chars().all(|c| c.is_ascii_digit()));
        let item = line.starts_with("- ") || line.starts_with("* ") || numbered;
        let prose = !(in_fence
            || line.starts_with("```")
            || line.starts_with('|')
            || line.starts_with('#'));
        if !prose || line.is_empty() || item {
            paragraphs.push(String::new());
        }
        if prose && !line.is_empty() {
            let last = paragraphs.last_mut().unwrap();
            last.push_str(line);
            last.push(' ');
        }
    }
    paragraphs.retain(|p| !p.trim().is_empty());
    paragraphs
}

#[test]
fn blocks_are_parsed_into_assignments_commands_and_reasons() {
    let blocks = sh_blocks(
        "text\n```sh\n# a comment\nD=../shared/x   # where\nseasonstereo a \\\n    --b c\n\n\
         seasonstereo d  # note\n```\n```text\nnot a command\n```\n\
         <!-- not run: needs a cluster -->\n```sh\nsbatch x\n```\n",
    );
    assert_eq!(blocks.len(), 2);
    assert_eq!(
        blocks[0].assignments,
        vec![("D".to_string(), "../shared/x".to_string())]
    );
    assert_eq!(blocks[0].commands.len(), 2);
    assert_eq!(normalised(&blocks[0].commands[0]), "seasonstereo a --b c");
    assert_eq!(normalised(&blocks[0].commands[1]), "seasonstereo d");
    assert_eq!(blocks[0].not_run, None);
    assert_eq!(blocks[1].not_run.as_deref(), Some("needs a cluster"));
}

#[test]
fn paragraphs_leave_out_code_tables_and_headings() {
    let text =
        "# Title\n\none two\nthree\n\n```sh\nfour five\n\nsix\n```\n| a | b |\n- seven\n- eight\n1. nine\n2. ten\n";
    assert_eq!(
        prose_paragraphs(text),
        [
            "one two three ",
            "- seven ",
            "- eight ",
            "1. nine ",
            "2. ten "
        ]
    );
}

//! Where the tests find the public data sets they read (the DFC2019 development imagery, s2p's
//! and rpcm's test data, the networks' parity fixtures), and what a test does when one is absent.
//!
//! The data root is `SEASONSTEREO_DATA` when it is set (a relative path is taken from the
//! repository root), else `../shared` beside the repository. A set is the folder
//! `<root>/<name>`, named as in [`SETS`]. A test that reads one starts with
//!
//! ```no_run
//! # fn a_test() {
//! let dir = testdata::require!("data/dfc2019-jax068-dev");
//! let truth = dir.join("truth/JAX_068_DSM.tif");
//! # }
//! ```
//!
//! which, when the set is absent, prints one line
//! `skipped: needs <set> (<what it is, where it comes from>; set SEASONSTEREO_DATA)` (once per
//! set and test binary, past the test harness's capture, so the skipped sets show in the output)
//! and returns: a clone on its own passes its tests. With `SEASONSTEREO_REQUIRE_DATA=1`, as CI
//! sets it, an absent set fails the test instead, so a run with the data never skips silently.

mod sets;

use std::collections::BTreeSet;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

pub use sets::{DataSet, SETS};

/// The variable naming the data root.
pub const DATA_VAR: &str = "SEASONSTEREO_DATA";
/// The variable that turns an absent set into a failure.
pub const REQUIRE_VAR: &str = "SEASONSTEREO_REQUIRE_DATA";

/// The folder of set `name`, or `return` from the calling test when it is absent (after the
/// skip line; a failure instead under `SEASONSTEREO_REQUIRE_DATA=1`). See [`dataset`].
#[macro_export]
macro_rules! require {
    ($name:expr) => {
        match $crate::dataset($name) {
            Some(dir) => dir,
            None => return,
        }
    };
}

/// The folder of set `name` when it is present. When it is absent: a panic naming the set under
/// `SEASONSTEREO_REQUIRE_DATA=1`, else the skip line (once per set in this process) and `None`.
/// An unknown name panics: it is a mistake in the test.
#[track_caller]
pub fn dataset(name: &str) -> Option<PathBuf> {
    let set = sets::find(name);
    let dir = data_root().join(set.name);
    if dir.is_dir() {
        return Some(dir);
    }
    if data_required() {
        panic!(
            "missing data set {} at {} ({}, from {}): {REQUIRE_VAR} is set, so an absent set \
             fails; set {DATA_VAR} to the folder that holds it",
            set.name,
            dir.display(),
            set.what,
            set.source
        );
    }
    report_skip(set);
    None
}

/// The folder of set `name`, for helpers called below a test's [`require!`]: an absent set
/// panics, since a test that reads it must have checked it first.
#[track_caller]
pub fn checked(name: &str) -> PathBuf {
    dataset(name).unwrap_or_else(|| {
        panic!("data set {name} is absent: the test must start with testdata::require!({name:?})")
    })
}

/// The DFC2019 JAX_068 development data, which most real-data tests read.
pub const JAX_DEV: &str = "data/dfc2019-jax068-dev";

/// A file of the DFC2019 JAX_068 development data, read in place, for a test that started with
/// `testdata::require!(testdata::JAX_DEV)`.
#[track_caller]
pub fn jax(relative: &str) -> PathBuf {
    checked(JAX_DEV).join(relative)
}

/// `SEASONSTEREO_DATA` (relative to the repository root) when set and not empty, else
/// `../shared` beside the repository.
pub fn data_root() -> PathBuf {
    root_from(std::env::var_os(DATA_VAR).as_deref().map(Path::new))
}

fn root_from(var: Option<&Path>) -> PathBuf {
    match var {
        Some(dir) if !dir.as_os_str().is_empty() => repository_root().join(dir),
        _ => repository_root().join("../shared"),
    }
}

/// The workspace root: this crate sits at `crates/testdata`.
fn repository_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// Whether `SEASONSTEREO_REQUIRE_DATA` asks for every set (any value but empty or `0`).
fn data_required() -> bool {
    std::env::var_os(REQUIRE_VAR).is_some_and(|v| !v.is_empty() && v != "0")
}

/// The sets this process has already reported as skipped.
static SKIPPED: Mutex<BTreeSet<&'static str>> = Mutex::new(BTreeSet::new());

/// Prints the skip line of `set` the first time this process skips it. It is written to the
/// process's stderr directly: the test harness captures `print!`/`eprint!` of passing tests,
/// not writes to the stream itself.
fn report_skip(set: &'static DataSet) {
    if record_skip(set) {
        let _ = std::io::stderr()
            .lock()
            .write_all(skip_line(set).as_bytes());
    }
}

/// Records `set` as skipped; true the first time.
fn record_skip(set: &'static DataSet) -> bool {
    SKIPPED
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .insert(set.name)
}

fn skip_line(set: &DataSet) -> String {
    format!(
        "skipped: needs {} ({}, from {}; set {DATA_VAR})\n",
        set.name, set.what, set.source
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sets::find;

    #[test]
    fn the_root_defaults_to_shared_beside_the_repository() {
        let root = root_from(None);
        assert!(root.ends_with("../shared"), "{}", root.display());
        assert_eq!(root_from(Some(Path::new(""))), root);
        assert!(repository_root().join("Cargo.toml").is_file());
        assert!(repository_root().join("crates/testdata").is_dir());
    }

    #[test]
    fn the_variable_overrides_the_root_relative_to_the_repository() {
        assert_eq!(
            root_from(Some(Path::new("/data/seasonstereo"))),
            PathBuf::from("/data/seasonstereo")
        );
        assert_eq!(
            root_from(Some(Path::new("elsewhere"))),
            repository_root().join("elsewhere")
        );
    }

    #[test]
    fn every_set_is_described_once() {
        let names: BTreeSet<&str> = SETS.iter().map(|s| s.name).collect();
        assert_eq!(names.len(), SETS.len());
        for set in SETS {
            assert!(
                !set.what.is_empty() && !set.source.is_empty(),
                "{}",
                set.name
            );
            assert!(!set.name.starts_with('/') && !set.name.contains(".."));
            assert_eq!(find(set.name), set);
        }
    }

    #[test]
    #[should_panic(expected = "no data set \"fixtures/nothing\"")]
    fn an_unknown_set_is_a_mistake() {
        find("fixtures/nothing");
    }

    #[test]
    fn the_skip_line_names_the_set_its_origin_and_the_variable() {
        let set = find("anchors/data/rpcm");
        let line = skip_line(set);
        assert!(line.starts_with("skipped: needs anchors/data/rpcm ("));
        assert!(line.contains("centreborelli/rpcm"));
        assert!(line.ends_with("; set SEASONSTEREO_DATA)\n"));
        assert_eq!(line.lines().count(), 1);
    }

    #[test]
    fn a_skip_is_reported_once_per_set() {
        static FIRST: DataSet = DataSet {
            name: "test/first",
            what: "a set no test reads",
            source: "nowhere",
        };
        static SECOND: DataSet = DataSet {
            name: "test/second",
            ..FIRST
        };
        assert!(record_skip(&FIRST));
        assert!(!record_skip(&FIRST));
        assert!(record_skip(&SECOND));
    }
}

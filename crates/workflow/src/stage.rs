//! What every stage shares: the item loop (the items of one `--shard`, finished ones skipped,
//! the others processed one by one with progress), its summary, atomic JSON and text outputs, and
//! the claim of an output folder by one producer.
//!
//! Each item's outputs must be written atomically and its "finished" test must look at the
//! output written last, so a killed run redoes at most the item it was on.

use std::path::Path;

use anyhow::{bail, Context, Result};
use dataset::shard::Shard;
use raster::formats::write_atomically;
use serde::de::DeserializeOwned;
use serde::Serialize;

use crate::outputs::Incomplete;
use crate::progress::Progress;

/// What a stage did with its share of the items.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct BatchSummary {
    /// Items of every shard.
    pub total: usize,
    /// Items of this shard.
    pub in_shard: usize,
    /// Items of this shard processed now.
    pub done: usize,
    /// Items of this shard already finished (skipped).
    pub skipped: usize,
}

/// Processes the items of `shard` (positions in `items`, which must be sorted the same way by
/// every shard) for which `finished` is false. A failing item does not stop the others: the
/// run ends with [`Incomplete::Partial`] naming the failed items (the first one's error
/// included; a rerun retries them), or [`Incomplete::Nothing`] when no item of the shard is
/// finished. Errors name the item (`name`).
pub fn run_items<T>(
    items: &[T],
    shard: &Shard,
    label: &str,
    progress: &dyn Progress,
    finished: impl Fn(&T) -> bool,
    mut process: impl FnMut(&T) -> Result<()>,
    name: impl Fn(&T) -> String,
) -> Result<BatchSummary> {
    let mine: Vec<&T> = items
        .iter()
        .enumerate()
        .filter(|(i, _)| shard.contains(*i))
        .map(|(_, t)| t)
        .collect();
    let mut summary = BatchSummary {
        total: items.len(),
        in_shard: mine.len(),
        ..Default::default()
    };
    let mut failed: Vec<(String, anyhow::Error)> = Vec::new();
    progress.begin(label, mine.len());
    for (k, item) in mine.iter().enumerate() {
        if finished(item) {
            summary.skipped += 1;
        } else {
            match process(item) {
                Ok(()) => summary.done += 1,
                Err(e) => failed.push((name(item), e)),
            }
        }
        progress.advance(k + 1);
    }
    progress.end();
    match failed.first() {
        None => Ok(summary),
        Some((first, e)) => Err(failed_items(&summary, first, e, &failed).into()),
    }
}

/// The outcome of a loop some of whose items failed.
fn failed_items(
    summary: &BatchSummary,
    first: &str,
    error: &anyhow::Error,
    failed: &[(String, anyhow::Error)],
) -> Incomplete {
    let cause = format!("item {first}: {}", crate::outputs::one_line(error));
    if summary.done + summary.skipped == 0 {
        return Incomplete::Nothing {
            message: format!("no item finished ({} failed); {cause}", failed.len()),
        };
    }
    let names: Vec<String> = failed.iter().map(|(n, _)| n.clone()).collect();
    Incomplete::Partial {
        message: format!(
            "{} of {} items failed ({}); {cause}; the others are written: fix the cause and \
             rerun the same command to retry them",
            failed.len(),
            summary.in_shard,
            crate::outputs::first_names(&names)
        ),
        failed: names,
    }
}

/// Writes `value` as pretty JSON, atomically (a killed run leaves the old file or the new one).
pub fn write_json<T: Serialize + ?Sized>(path: &Path, value: &T) -> Result<()> {
    let text = serde_json::to_string_pretty(value)
        .with_context(|| format!("serialising {}", path.display()))?;
    write_text(path, &text)
}

/// Writes `text`, atomically.
pub fn write_text(path: &Path, text: &str) -> Result<()> {
    write_atomically(path, |f| std::io::Write::write_all(f, text.as_bytes()))
        .with_context(|| format!("writing {}", path.display()))
}

/// Reads a JSON record, `None` when the file does not exist; a malformed one is an error naming
/// the file.
pub fn read_json<T: DeserializeOwned>(path: &Path) -> Result<Option<T>> {
    if !path.is_file() {
        return Ok(None);
    }
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    serde_json::from_str(&text).map(Some).with_context(|| {
        format!(
            "{} is malformed (delete it if its folder holds nothing yet)",
            path.display()
        )
    })
}

/// Claims an output folder for one producer (a teacher, a generator, a segmenter) through its
/// record at `path`: the record is written when absent; a different record refuses the run with
/// `conflict(old record)`, so outputs of two producers are never mixed in one folder.
pub fn claim_folder<T: Serialize + DeserializeOwned + PartialEq>(
    path: &Path,
    record: &T,
    conflict: impl FnOnce(&T) -> String,
) -> Result<()> {
    match read_json::<T>(path)? {
        Some(old) if old == *record => Ok(()),
        Some(old) => bail!("{}", conflict(&old)),
        None => write_json(path, record),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Silent;

    fn run(items: &[u32], fails: impl Fn(u32) -> bool, done: &[u32]) -> Result<BatchSummary> {
        run_items(
            items,
            &Shard::default(),
            "items",
            &Silent,
            |i| done.contains(i),
            |&i| if fails(i) { bail!("no {i}") } else { Ok(()) },
            |i| format!("#{i}"),
        )
    }

    #[test]
    fn a_failing_item_does_not_stop_the_others() {
        let items = [1, 2, 3, 4];
        let s = run(&items, |_| false, &[2]).unwrap();
        assert_eq!((s.done, s.skipped, s.in_shard), (3, 1, 4));

        let e = run(&items, |i| i == 2 || i == 4, &[]).unwrap_err();
        let partial = e.downcast_ref::<Incomplete>().expect("an outcome");
        assert_eq!(partial.exit_code(), 2);
        let Incomplete::Partial { failed, message } = partial else {
            panic!("{partial:?}")
        };
        assert_eq!(failed, &["#2", "#4"]);
        assert!(
            message.contains("2 of 4 items failed (#2, #4); item #2: no 2"),
            "{message}"
        );

        let e = run(&items, |_| true, &[]).unwrap_err();
        assert_eq!(e.downcast_ref::<Incomplete>().unwrap().exit_code(), 3);
        // Finished before counts as produced.
        let e = run(&items, |i| i != 1, &[1]).unwrap_err();
        assert_eq!(e.downcast_ref::<Incomplete>().unwrap().exit_code(), 2);
    }
}

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
/// every shard) for which `finished` is false. Errors name the item (`name`).
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
    progress.begin(label, mine.len());
    for (k, item) in mine.iter().enumerate() {
        if finished(item) {
            summary.skipped += 1;
        } else {
            let r = process(item).with_context(|| format!("item {}", name(item)));
            if let Err(e) = r {
                progress.end();
                return Err(e);
            }
            summary.done += 1;
        }
        progress.advance(k + 1);
    }
    progress.end();
    Ok(summary)
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

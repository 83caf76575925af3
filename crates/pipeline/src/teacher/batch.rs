//! The loop every data stage shares: the items of one shard, finished ones skipped, the others
//! processed one by one with progress. Each item's outputs must be written atomically and its
//! "finished" test must look at the output written last, so a killed run redoes at most the item
//! it was on.

use anyhow::{Context, Result};
pub use dataset::shard::Shard;

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

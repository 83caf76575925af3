//! Shards of a stage's work list, for array jobs (Slurm `--array`, Kubernetes indexed jobs).
//!
//! `--shard i/n` (0 ≤ i < n) takes the items whose position in the SORTED work list is ≡ i mod n:
//! every machine computes the same list, the shards are disjoint, cover everything and are balanced
//! to one item, and nothing needs coordinating.

use std::fmt;
use std::str::FromStr;

use crate::{DatasetError, Result};

/// Shard `index` of `count` (0-based index, as `SLURM_ARRAY_TASK_ID` from 0 and
/// `JOB_COMPLETION_INDEX`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    pub index: usize,
    pub count: usize,
}

impl Shard {
    /// Everything (shard 0/1).
    pub const ALL: Shard = Shard { index: 0, count: 1 };

    pub fn new(index: usize, count: usize) -> Result<Self> {
        if count == 0 || index >= count {
            return Err(DatasetError::Invalid(format!(
                "shard {index}/{count}: need 0 ≤ i < n (shards are numbered from 0, e.g. 0/4 … 3/4)"
            )));
        }
        Ok(Shard { index, count })
    }

    /// Parses `i/n`.
    pub fn parse(s: &str) -> Result<Self> {
        let bad = || {
            DatasetError::Invalid(format!(
                "shard {s:?}: expected i/n with 0 ≤ i < n, e.g. 0/4 (from $SLURM_ARRAY_TASK_ID/$N)"
            ))
        };
        let (i, n) = s.split_once('/').ok_or_else(bad)?;
        let i = i.trim().parse().map_err(|_| bad())?;
        let n = n.trim().parse().map_err(|_| bad())?;
        Shard::new(i, n)
    }

    /// True when position `i` of the sorted work list belongs to this shard.
    pub fn contains(&self, i: usize) -> bool {
        i % self.count == self.index
    }

    /// This shard's items of a (sorted) work list, in order.
    pub fn select<'a, T>(&self, items: &'a [T]) -> Vec<&'a T> {
        items
            .iter()
            .enumerate()
            .filter(|(i, _)| self.contains(*i))
            .map(|(_, t)| t)
            .collect()
    }

    /// True for the whole list.
    pub fn is_all(&self) -> bool {
        self.count == 1
    }
}

impl Default for Shard {
    fn default() -> Self {
        Shard::ALL
    }
}

impl fmt::Display for Shard {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl FromStr for Shard {
    type Err = DatasetError;
    fn from_str(s: &str) -> Result<Self> {
        Shard::parse(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn partitions_exactly() {
        let items: Vec<usize> = (0..103).collect();
        let mut all = Vec::new();
        for i in 0..4 {
            let s = Shard::parse(&format!("{i}/4")).unwrap();
            let part = s.select(&items);
            assert!((25..=26).contains(&part.len()));
            all.extend(part.into_iter().copied());
        }
        all.sort();
        assert_eq!(all, items);
    }

    #[test]
    fn validates() {
        for bad in ["4/4", "1/0", "x/2", "1", "-1/3", ""] {
            assert!(Shard::parse(bad).is_err(), "{bad}");
        }
        assert_eq!(Shard::parse(" 2/3 ").unwrap(), Shard { index: 2, count: 3 });
        assert_eq!(Shard::ALL.to_string(), "0/1");
    }
}

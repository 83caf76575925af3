//! The paper's data subsets (Sec. 4, ablation) as experiment lists:
//!
//! - **S1**: the real synchronic pairs only;
//! - **S2**: S1 + the synchronic synthetic pairs (both views in the same generated season);
//! - **S3**: S1 + synchronic and diachronic synthetic pairs in EQUAL proportion, with the same
//!   augmentation budget as S2 (per pair: as many synthetic pairs as S2 adds, half of them
//!   synchronic, half diachronic, drawn at random with a seed);
//! - **All**: every combination (the full set of the paper's main runs).
//!
//! File names are the release's (`sub1_synchronic`, `sub2_synchronic`, `sub5_syndiach`,
//! `sub3_diachronic`), so its training configs find them.

use std::collections::BTreeMap;

use crate::experiment::ExperimentRow;
use crate::rng::SplitMix64;
use crate::stem::{PairKind, PairStem};

/// A training subset.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Subset {
    S1,
    S2,
    S3,
    All,
}

impl Subset {
    pub const ALL: [Subset; 4] = [Subset::S1, Subset::S2, Subset::S3, Subset::All];

    /// Name of the experiment list (`experiments/<name>.csv`), as in the release's configs.
    pub fn csv_name(self) -> &'static str {
        match self {
            Subset::S1 => "sub1_synchronic",
            Subset::S2 => "sub2_synchronic",
            Subset::S3 => "sub5_syndiach",
            Subset::All => "sub3_diachronic",
        }
    }

    /// Short label (`S1`, `S2`, `S3`, `all`).
    pub fn label(self) -> &'static str {
        match self {
            Subset::S1 => "S1",
            Subset::S2 => "S2",
            Subset::S3 => "S3",
            Subset::All => "all",
        }
    }

    /// Parses `S1`/`s1`/`sub1_synchronic`, …, `all`.
    pub fn parse(s: &str) -> Option<Subset> {
        let l = s.trim().to_ascii_lowercase();
        Subset::ALL
            .into_iter()
            .find(|x| l == x.label().to_ascii_lowercase() || l == x.csv_name())
    }
}

/// The synthetic variants available for one real pair (those that passed the fidelity check).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PairVariants {
    /// The real pair.
    pub pair: PairStem,
    /// Tags of the left image's variants.
    pub left_tags: Vec<String>,
    /// Tags of the right image's variants.
    pub right_tags: Vec<String>,
}

impl PairVariants {
    /// Every combination of the real images and their variants, real pair first (25 with 4
    /// seasons on both sides).
    pub fn combinations(&self) -> Vec<PairStem> {
        let side = |tags: &[String]| -> Vec<Option<String>> {
            std::iter::once(None)
                .chain(tags.iter().cloned().map(Some))
                .collect()
        };
        let (l, r) = (side(&self.left_tags), side(&self.right_tags));
        let mut out = Vec::with_capacity(l.len() * r.len());
        for a in &l {
            for b in &r {
                out.push(self.pair.with_tags(a.as_deref(), b.as_deref()));
            }
        }
        out.sort_by_key(|s| (!s.is_real(), s.clone()));
        out
    }
}

/// The experiment lists of every subset, deterministic given `seed` (and independent of the
/// order of `pairs`). Rows are sorted by stem.
pub fn build_subsets(pairs: &[PairVariants], seed: u64) -> BTreeMap<Subset, Vec<ExperimentRow>> {
    let mut out: BTreeMap<Subset, Vec<PairStem>> =
        Subset::ALL.into_iter().map(|s| (s, Vec::new())).collect();
    for p in pairs {
        let all = p.combinations();
        let of = |k| -> Vec<PairStem> { all.iter().filter(|s| s.kind() == k).cloned().collect() };
        let (real, sync, mut diach) = (
            of(PairKind::Real),
            of(PairKind::SynchronicSynthetic),
            of(PairKind::Diachronic),
        );
        let budget = sync.len();
        let mut rng = SplitMix64::for_key(seed, &p.pair.base_name());
        // Half synchronic, half diachronic; an odd budget gives the extra one at random.
        let mut n_sync = budget / 2;
        if budget % 2 == 1 && rng.next_u64() & 1 == 1 {
            n_sync += 1;
        }
        let n_diach = (budget - n_sync).min(diach.len());
        let mut sync_drawn = sync.clone();
        rng.shuffle(&mut sync_drawn);
        rng.shuffle(&mut diach);
        let subsets = [
            (Subset::S1, real.clone()),
            (Subset::S2, [real.clone(), sync.clone()].concat()),
            (
                Subset::S3,
                [
                    real.clone(),
                    sync_drawn[..n_sync].to_vec(),
                    diach[..n_diach].to_vec(),
                ]
                .concat(),
            ),
            (Subset::All, all.clone()),
        ];
        for (s, stems) in subsets {
            out.get_mut(&s).expect("every subset").extend(stems);
        }
    }
    out.into_iter()
        .map(|(s, mut stems)| {
            stems.sort();
            (s, stems.into_iter().map(ExperimentRow::of).collect())
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pairs(n: usize) -> Vec<PairVariants> {
        let seasons: Vec<String> = ["summer", "autumn", "winter", "spring"]
            .map(String::from)
            .to_vec();
        (0..n)
            .map(|i| PairVariants {
                pair: PairStem::real(format!("P{i}_A"), format!("P{i}_B")),
                left_tags: seasons.clone(),
                right_tags: seasons.clone(),
            })
            .collect()
    }

    fn count(rows: &[ExperimentRow], k: PairKind) -> usize {
        rows.iter().filter(|r| r.stem.kind() == k).count()
    }

    #[test]
    fn subsets_have_the_paper_composition() {
        let s = build_subsets(&pairs(10), 3);
        let (s1, s2, s3, all) = (
            &s[&Subset::S1],
            &s[&Subset::S2],
            &s[&Subset::S3],
            &s[&Subset::All],
        );
        assert_eq!(s1.len(), 10);
        assert!(s1.iter().all(|r| r.stem.is_real()));
        assert_eq!(count(s2, PairKind::Real), 10);
        assert_eq!(count(s2, PairKind::SynchronicSynthetic), 40);
        assert_eq!(count(s2, PairKind::Diachronic), 0);
        // Same total budget as S2, half synchronic, half diachronic.
        assert_eq!(s3.len(), s2.len());
        assert_eq!(count(s3, PairKind::SynchronicSynthetic), 20);
        assert_eq!(count(s3, PairKind::Diachronic), 20);
        assert_eq!(all.len(), 250);
        assert_eq!(count(all, PairKind::Diachronic), 200);
        // Every row's flag matches its tags.
        assert!(s3
            .iter()
            .all(|r| r.diachronic == Some(r.stem.is_diachronic())));
    }

    #[test]
    fn deterministic_and_seed_dependent() {
        let mut p = pairs(6);
        let a = build_subsets(&p, 1);
        p.reverse();
        assert_eq!(
            build_subsets(&p, 1),
            a,
            "order of the pairs must not matter"
        );
        assert_ne!(build_subsets(&p, 2)[&Subset::S3], a[&Subset::S3]);
    }

    #[test]
    fn missing_variants_shrink_the_combinations() {
        let mut p = pairs(1);
        p[0].right_tags.retain(|t| t != "winter");
        assert_eq!(p[0].combinations().len(), 20);
        let s = build_subsets(&p, 0);
        assert_eq!(count(&s[&Subset::S2], PairKind::SynchronicSynthetic), 3);
        assert_eq!(s[&Subset::S3].len(), s[&Subset::S2].len());
    }
}

//! `manifest.json`: what a training set contains and how it was made.

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::experiment::ExperimentRow;
use crate::stem::PairKind;
use crate::{DatasetError, Result};

/// Format tag written in every manifest.
pub const FORMAT: &str = "seasonstereo-dataset/1";

/// Rows of one list by kind.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct KindCounts {
    pub real: usize,
    pub synchronic_synthetic: usize,
    pub diachronic: usize,
    pub total: usize,
}

impl KindCounts {
    /// Counts of an experiment list.
    pub fn of(rows: &[ExperimentRow]) -> Self {
        let mut c = KindCounts::default();
        for r in rows {
            match r.stem.kind() {
                PairKind::Real => c.real += 1,
                PairKind::SynchronicSynthetic => c.synchronic_synthetic += 1,
                PairKind::Diachronic => c.diachronic += 1,
            }
            c.total += 1;
        }
        c
    }
}

/// One subset's list and counts.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct SubsetEntry {
    /// `experiments/<csv>` relative to the dataset folder.
    pub csv: String,
    pub counts: KindCounts,
}

/// One split (`train`, `val`) of the set.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SplitManifest {
    /// Real pairs.
    pub pairs: usize,
    /// Every combination written (real + synthetic).
    pub combinations: KindCounts,
    /// Subset lists by label (`S1`, `S2`, `S3`, `all`, `val`).
    pub subsets: BTreeMap<String, SubsetEntry>,
    /// Synthetic variants rejected by the fidelity check (not in any combination).
    pub rejected_variants: usize,
    /// Segmentation masks that were absent and replaced by the release's defaults.
    pub missing_masks: usize,
    /// Folder of the supervising disparities, relative to the dataset folder.
    pub teacher_dir: String,
    /// Folder of the LiDAR / exact disparities, when present.
    pub lidar_dir: Option<String>,
}

/// The whole manifest.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    pub format: String,
    /// Seasonal generator of the synthetic variants (`builtin-seasons/…`, an API model name, or
    /// `none`).
    pub generator: String,
    /// Teacher of the disparities (`sgm`, `monster++ (vitl)`, …).
    pub teacher: String,
    /// Segmenter of the water/tree/building masks (`segformer …`, `builtin`, `world classes`,
    /// `none (release defaults)`).
    pub segmenter: String,
    /// Seed of the subset draws.
    pub seed: u64,
    /// Splits by name.
    pub splits: BTreeMap<String, SplitManifest>,
    /// Free-form notes (e.g. what was measured on a procedural world).
    #[serde(default)]
    pub notes: Vec<String>,
}

impl Manifest {
    pub fn new(generator: &str, teacher: &str, segmenter: &str, seed: u64) -> Self {
        Manifest {
            format: FORMAT.to_string(),
            generator: generator.to_string(),
            teacher: teacher.to_string(),
            segmenter: segmenter.to_string(),
            seed,
            splits: BTreeMap::new(),
            notes: Vec::new(),
        }
    }

    /// Reads a manifest.
    pub fn read(path: &Path) -> Result<Self> {
        let text = crate::experiment::read_text(path, "written by `seasonstereo dataset build`")?;
        serde_json::from_str(&text).map_err(|e| DatasetError::format(path, e.to_string()))
    }

    /// Reads the manifest at `path`, or None when there is none yet.
    pub fn read_optional(path: &Path) -> Result<Option<Self>> {
        if path.exists() {
            Manifest::read(path).map(Some)
        } else {
            Ok(None)
        }
    }

    /// Writes the manifest atomically (pretty JSON).
    pub fn write(&self, path: &Path) -> Result<()> {
        let text = serde_json::to_string_pretty(self)
            .map_err(|e| DatasetError::format(path, e.to_string()))?;
        raster::formats::write_atomically(path, |w| {
            use std::io::Write;
            w.write_all(text.as_bytes())?;
            w.write_all(b"\n")
        })?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stem::PairStem;

    #[test]
    fn counts_and_round_trip() {
        let rows: Vec<ExperimentRow> = ["A-B", "A__summer-B__summer", "A-B__winter"]
            .iter()
            .map(|s| ExperimentRow::of(PairStem::parse(s).unwrap()))
            .collect();
        let c = KindCounts::of(&rows);
        assert_eq!(
            (c.real, c.synchronic_synthetic, c.diachronic, c.total),
            (1, 1, 1, 3)
        );
        let mut m = Manifest::new("builtin", "sgm", "world classes", 7);
        m.splits.insert(
            "train".into(),
            SplitManifest {
                pairs: 1,
                combinations: c,
                ..Default::default()
            },
        );
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("manifest.json");
        m.write(&p).unwrap();
        assert_eq!(Manifest::read(&p).unwrap(), m);
        assert!(Manifest::read_optional(&dir.path().join("x"))
            .unwrap()
            .is_none());
    }
}

//! The per-pair CSV: one row per (method, split, pair), rewritten atomically after every pair so
//! a killed run keeps every finished row and a rerun skips them.

use std::collections::HashSet;
use std::path::Path;

use anyhow::{Context, Result};
use raster::formats::write_atomically;
use serde::{Deserialize, Serialize};

/// Row status: the pair was scored (its MAEs may still be empty when nothing overlapped).
pub const STATUS_SCORED: &str = "scored";
/// Row status: the prediction and the ground truth share no cell.
pub const STATUS_NO_OVERLAP: &str = "no_overlap";
/// Row status: an Omaha pair whose ground-truth disparity exceeds the limit (not aggregated).
pub const STATUS_DROPPED: &str = "dropped_disparity_limit";

/// One row of the per-pair CSV. Empty fields are `None`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PairRecord {
    pub split: String,
    pub stem: String,
    pub aoi: String,
    pub method: String,
    pub status: String,
    pub mae_raw: Option<f64>,
    pub mae_no_water: Option<f64>,
    pub mae_filtered: Option<f64>,
    /// Share of the truth's finite cells with an aligned prediction (not computed by the release).
    pub coverage: Option<f64>,
    /// Registration of `mae_filtered`: shift applied to the prediction (cells;
    /// `aligned(x, y) = pred(x − dx, y − dy) + offset`, the release's `compute_shift` returns
    /// `(−dx, −dy)`) and vertical offset (metres).
    pub dx: Option<i32>,
    pub dy: Option<i32>,
    pub offset: Option<f64>,
    /// Registration of `mae_raw` (the release registers each score on its own masked truth).
    #[serde(default)]
    pub dx_raw: Option<i32>,
    #[serde(default)]
    pub dy_raw: Option<i32>,
    #[serde(default)]
    pub offset_raw: Option<f64>,
    /// Registration of `mae_no_water`.
    #[serde(default)]
    pub dx_no_water: Option<i32>,
    #[serde(default)]
    pub dy_no_water: Option<i32>,
    #[serde(default)]
    pub offset_no_water: Option<f64>,
    /// Pixels of the evaluation mask that were triangulated.
    pub pixels: usize,
    /// DSM cells of the filtered MAE.
    pub cells: usize,
    /// Largest d of the ground-truth disparity, when there is one.
    pub max_gt_disparity: Option<f64>,
}

impl PairRecord {
    /// A row of `split`, `stem`, `aoi`, `method` with `status` and no score yet (every score and
    /// registration `None`, no pixel or cell counted).
    pub fn unscored(split: &str, stem: &str, aoi: &str, method: &str, status: &str) -> Self {
        PairRecord {
            split: split.to_string(),
            stem: stem.to_string(),
            aoi: aoi.to_string(),
            method: method.to_string(),
            status: status.to_string(),
            mae_raw: None,
            mae_no_water: None,
            mae_filtered: None,
            coverage: None,
            dx: None,
            dy: None,
            offset: None,
            dx_raw: None,
            dy_raw: None,
            offset_raw: None,
            dx_no_water: None,
            dy_no_water: None,
            offset_no_water: None,
            pixels: 0,
            cells: 0,
            max_gt_disparity: None,
        }
    }

    /// The identity a rerun matches on.
    pub fn key(&self) -> (String, String, String) {
        (self.method.clone(), self.split.clone(), self.stem.clone())
    }
}

/// The rows of `path`; none when it does not exist. A file that is not such a CSV is an error
/// naming it (it is never overwritten).
pub fn read_records(path: &Path) -> Result<Vec<PairRecord>> {
    if !path.exists() {
        return Ok(Vec::new());
    }
    let mut reader = csv::Reader::from_path(path)
        .with_context(|| format!("reading the per-pair results {}", path.display()))?;
    let mut rows = Vec::new();
    for (i, r) in reader.deserialize().enumerate() {
        let row: PairRecord = r.with_context(|| {
            format!(
                "{}: row {} is not a per-pair result of `seasonstereo eval`",
                path.display(),
                i + 1
            )
        })?;
        rows.push(row);
    }
    Ok(rows)
}

/// Writes every row to `path` atomically (header first).
pub fn write_records(path: &Path, rows: &[PairRecord]) -> Result<()> {
    let mut w = csv::Writer::from_writer(Vec::new());
    for r in rows {
        w.serialize(r)?;
    }
    if rows.is_empty() {
        return Ok(());
    }
    let bytes = w.into_inner().context("serialising the per-pair results")?;
    write_atomically(path, |f| std::io::Write::write_all(f, &bytes))
        .with_context(|| format!("writing {}", path.display()))
}

/// The per-pair CSV being filled: rows already there are kept and skipped.
pub struct RecordFile {
    path: std::path::PathBuf,
    rows: Vec<PairRecord>,
    done: HashSet<(String, String, String)>,
}

impl RecordFile {
    /// Opens (or starts) the CSV at `path`; duplicate rows of an older file keep their first copy.
    pub fn open(path: &Path) -> Result<Self> {
        let mut rows = Vec::new();
        let mut done = HashSet::new();
        for r in read_records(path)? {
            if done.insert(r.key()) {
                rows.push(r);
            }
        }
        Ok(RecordFile {
            path: path.to_path_buf(),
            rows,
            done,
        })
    }

    /// True when the pair already has a row for this method.
    pub fn contains(&self, method: &str, split: &str, stem: &str) -> bool {
        self.done
            .contains(&(method.to_string(), split.to_string(), stem.to_string()))
    }

    /// Appends a row and rewrites the file atomically.
    pub fn push(&mut self, row: PairRecord) -> Result<()> {
        if !self.done.insert(row.key()) {
            return Ok(());
        }
        self.rows.push(row);
        write_records(&self.path, &self.rows)
    }

    pub fn rows(&self) -> &[PairRecord] {
        &self.rows
    }

    pub fn path(&self) -> &Path {
        &self.path
    }
}

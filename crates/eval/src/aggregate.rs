//! From per-pair MAEs to Table 1: the median of the pair MAEs of each AOI, then per split the mean
//! and SAMPLE standard deviation (n − 1) over its AOIs, then the average of the split means.
//! Only rows with status `scored` and a filtered MAE count; Omaha pairs over the disparity limit
//! are dropped before (see [`exceeds_disparity_limit`]). This is `generate_table.py`'s
//! aggregation (`np.median` per AOI, `np.mean` and `np.std(ddof=1)` over the AOI medians, NaN std
//! for a single AOI); the average over the splits is the paper's, which that script does not
//! print. The release rounds each pair's MAE to 6 decimals in its CSV before aggregating; the
//! table here uses the full values (a difference below 1e-6 m).

use std::collections::BTreeMap;

use raster::Image;

use super::layout::{canonical_split, TABLE_SPLITS};
use super::records::{PairRecord, STATUS_SCORED};

/// The benchmark's Omaha rule: pairs whose ground-truth disparity exceeds this are dropped.
pub const OMAHA_MAX_DISPARITY: f64 = 192.0;

/// Largest d over the non-NaN samples (every channel) of a ground-truth disparity (`None` when
/// every sample is NaN), and whether the pair is dropped at `limit`: `generate_table.py` keeps a
/// pair only when `np.nanmax(disparity) <= 192` (signed, infinities included), so a disparity
/// that is NaN everywhere drops its pair too. A pair without a disparity file is kept.
pub fn exceeds_disparity_limit(disparity: &Image, limit: f64) -> (bool, Option<f64>) {
    let max = disparity
        .data()
        .iter()
        .filter(|v| !v.is_nan())
        .map(|&v| v as f64)
        .fold(None, |m: Option<f64>, v| Some(m.map_or(v, |m| m.max(v))));
    (!max.is_some_and(|m| m <= limit), max)
}

/// Median of the values (mean of the two middle ones for an even count); `None` when empty.
pub fn median(values: &[f64]) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    let mut v = values.to_vec();
    v.sort_by(|a, b| a.total_cmp(b));
    let n = v.len();
    Some(if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    })
}

/// Mean and sample standard deviation (n − 1); the deviation is `None` for a single value, both
/// are `None` for none.
pub fn mean_std(values: &[f64]) -> (Option<f64>, Option<f64>) {
    let n = values.len();
    if n == 0 {
        return (None, None);
    }
    let mean = values.iter().sum::<f64>() / n as f64;
    if n < 2 {
        return (Some(mean), None);
    }
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
    (Some(mean), Some(var.sqrt()))
}

/// One cell of the table: a split's statistics for one method.
#[derive(Clone, Debug, PartialEq)]
pub struct SplitStat {
    /// Mean over the AOIs of the per-AOI median MAE, metres.
    pub mean: f64,
    /// Sample standard deviation over the AOIs (`None` with one AOI).
    pub std: Option<f64>,
    /// (AOI, median pair MAE, pairs) in AOI order.
    pub aois: Vec<(String, f64, usize)>,
    pub pairs: usize,
    /// Mean coverage of the split's scored pairs (share of the truth's cells with a height),
    /// when the records carry it: an MAE alone rewards holes.
    pub coverage: Option<f64>,
}

impl SplitStat {
    /// Statistics of the filtered MAEs `(aoi, mae)` of one split; `None` when there is none.
    pub fn from_pairs(pairs: &[(String, f64)]) -> Option<SplitStat> {
        let mut by_aoi: BTreeMap<&str, Vec<f64>> = BTreeMap::new();
        for (aoi, mae) in pairs {
            by_aoi.entry(aoi).or_default().push(*mae);
        }
        let aois: Vec<(String, f64, usize)> = by_aoi
            .into_iter()
            .filter_map(|(a, v)| median(&v).map(|m| (a.to_string(), m, v.len())))
            .collect();
        let medians: Vec<f64> = aois.iter().map(|a| a.1).collect();
        let (mean, std) = mean_std(&medians);
        Some(SplitStat {
            mean: mean?,
            std,
            aois,
            pairs: pairs.len(),
            coverage: None,
        })
    }
}

/// A column of the table.
#[derive(Clone, Debug, PartialEq)]
pub struct Column {
    /// The split names of the CSV that feed this column.
    pub key: String,
    pub title: String,
}

/// A row of the table: one method.
#[derive(Clone, Debug, PartialEq)]
pub struct MethodRow {
    pub method: String,
    /// One entry per column; `None` when the method has no scored pair there.
    pub splits: Vec<Option<SplitStat>>,
    /// Mean of the split means present.
    pub average: Option<f64>,
}

/// Table 1: rows = methods, columns = splits (+ average).
#[derive(Clone, Debug, PartialEq)]
pub struct Table {
    pub columns: Vec<Column>,
    pub rows: Vec<MethodRow>,
}

fn column_key(split: &str) -> String {
    canonical_split(split)
        .map(str::to_string)
        .unwrap_or_else(|| split.to_string())
}

/// Aggregates per-pair rows. The columns are the four Table 1 splits, always, then any other
/// split in order of first appearance; the rows are the methods in order of first appearance.
pub fn aggregate(records: &[PairRecord]) -> Table {
    let mut columns: Vec<Column> = TABLE_SPLITS
        .iter()
        .map(|(k, t)| Column {
            key: k.to_string(),
            title: t.to_string(),
        })
        .collect();
    let mut methods: Vec<String> = Vec::new();
    for r in records {
        let key = column_key(&r.split);
        if !columns.iter().any(|c| c.key == key) {
            columns.push(Column {
                key,
                title: r.split.clone(),
            });
        }
        if !methods.contains(&r.method) {
            methods.push(r.method.clone());
        }
    }
    let rows = methods
        .into_iter()
        .map(|method| {
            let splits: Vec<Option<SplitStat>> = columns
                .iter()
                .map(|c| {
                    let scored: Vec<&PairRecord> = records
                        .iter()
                        .filter(|r| {
                            r.method == method
                                && r.status == STATUS_SCORED
                                && column_key(&r.split) == c.key
                        })
                        .collect();
                    let pairs: Vec<(String, f64)> = scored
                        .iter()
                        .filter_map(|r| r.mae_filtered.map(|m| (r.aoi.clone(), m)))
                        .collect();
                    let coverages: Vec<f64> = scored.iter().filter_map(|r| r.coverage).collect();
                    SplitStat::from_pairs(&pairs).map(|mut s| {
                        s.coverage = mean_std(&coverages).0;
                        s
                    })
                })
                .collect();
            let means: Vec<f64> = splits.iter().flatten().map(|s| s.mean).collect();
            MethodRow {
                method,
                average: mean_std(&means).0,
                splits,
            }
        })
        .collect();
    Table { columns, rows }
}

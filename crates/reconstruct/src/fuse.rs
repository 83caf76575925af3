//! Fusion of the DSMs of several pairs on one grid, cell by cell, over the measured cells only.
//!
//! A cell's heights (one per pair that measured it) are sorted and cut into clusters wherever two
//! neighbouring heights differ by more than the tolerance (single linkage). Each height weighs
//! its pair's weight times the matcher's confidence in it (the pair's `_confidence.tif`; 1 when
//! the matcher gives none). The strongest cluster (the largest sum of weights; a tie goes to the
//! higher cluster, since a DSM is the top surface and the classic failure of a pair near a
//! building is the ground seen where the roof is) gives the cell its height, the weighted median
//! of its members, and its spread, their weighted median absolute deviation. A cell whose
//! strongest cluster has fewer members than `min_support`, or whose members' confidences sum to
//! less than `min_confidence`, stays empty, like a cell no pair measured, and is left to the
//! hole filling. With equal weights and no confidence the strongest cluster is the one with most
//! members and the medians are the plain ones.
//!
//! Why the confidence: on every one of the 12 dev pairs, a cell is far more often within 1 m of
//! the truth where the winner's margin over its rival is large than where it is small, so two
//! confident pairs that agree deserve more trust than three hesitant ones (BENCHMARKS.md, "Many
//! dates, one DSM", "Confidence-weighted fusion").
//!
//! Pair weights, when asked for, come from a first fusion with equal weights
//! ([`Fused::agreement`]): the share of a pair's measured cells within the tolerance of the fused
//! height, turned into a weight by [`pair_weight`]. Agreement is not correctness: pairs that
//! share an image share its mismatches and agree with each other, and a narrow-baseline pair is
//! noisy without being wrong, so the weights help on some sets and hurt on others
//! (BENCHMARKS.md, "Many dates, one DSM", "Pair weights") and are off by default.
//!
//! Before fusing, each pair's DSM can be co-registered on a reference pair's ([`Shift`]: an
//! integer shift by NCC and a vertical offset, the benchmark's registration between two DSMs,
//! no truth involved).
//!
//! Memory: the pairs' DSMs are read by windows of `rows_per_block` rows ([`fuse_files`]); only
//! one block of every pair and the fused grid are held at once.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use camera::DsmGrid;
use raster::formats::TiffReader;
use rayon::prelude::*;
use serde::Serialize;

use workflow::progress::Progress;

/// How heights of one cell become one.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct FusionParams {
    /// Two sorted heights further apart than this, metres, belong to different clusters (default
    /// 0.5 m: on the dev set wider clusters were worse and tighter ones traded coverage for MAE;
    /// on the procedural six-date world, whose baselines are narrower and pairs noisier, 0.5 m
    /// beat tighter ones. BENCHMARKS.md, "Many dates, one DSM" and "The procedural world on six
    /// dates").
    pub tolerance: f32,
    /// Fewest members of the kept cluster for the cell to be trusted.
    pub min_support: usize,
    /// Least sum of the kept cluster's confidences for the cell to be trusted; `None`: no such
    /// rule (the pairs have no confidence).
    pub min_confidence: Option<f32>,
}

impl Default for FusionParams {
    fn default() -> Self {
        FusionParams {
            tolerance: 0.5,
            min_support: 1,
            min_confidence: None,
        }
    }
}

/// One pair's measurement of a cell.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    /// Metres.
    pub height: f32,
    /// The pair's weight.
    pub weight: f32,
    /// The matcher's confidence in it, `[0, 1]` (1 when it gives none).
    pub confidence: f32,
}

impl Sample {
    /// A pair's height with its weight and confidence (a NaN confidence counts as 0).
    pub fn new(height: f32, weight: f32, confidence: f32) -> Self {
        let confidence = if confidence.is_finite() {
            confidence.clamp(0.0, 1.0)
        } else {
            0.0
        };
        Sample {
            height,
            weight,
            confidence,
        }
    }

    /// What the sample weighs in its cluster: never zero, so that a cell measured only with no
    /// confidence still has a strongest cluster.
    fn mass(&self) -> f32 {
        self.weight * (self.confidence + CONFIDENCE_FLOOR)
    }
}

/// Added to every confidence before it weighs a height.
const CONFIDENCE_FLOOR: f32 = 1e-6;

/// One cell's fused height.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CellFusion {
    /// Median of the kept cluster, metres.
    pub height: f32,
    /// Median absolute deviation of the kept cluster, metres.
    pub spread: f32,
    /// Members of the kept cluster.
    pub support: usize,
    /// Sum of the kept cluster's confidences.
    pub confidence: f32,
}

/// The weighted median of `v` (sorted by value, weights > 0, non-empty): the first value at
/// which the running weight reaches half the total, or the mean of it and the next one when the
/// running weight is exactly half (so equal weights give the plain median).
fn weighted_median(v: &[(f32, f32)]) -> f32 {
    let half = 0.5 * v.iter().map(|&(_, w)| w).sum::<f32>();
    let mut run = 0.0;
    for (i, &(h, w)) in v.iter().enumerate() {
        run += w;
        if run >= half {
            return match v.get(i + 1) {
                Some(&(next, _)) if run == half => 0.5 * (h + next),
                _ => h,
            };
        }
    }
    v[v.len() - 1].0
}

/// Fuses the finite heights of `values` (others ignored; the slice is reordered), `None` when
/// no cluster has `min_support` members and `min_confidence` of confidence.
pub fn fuse_cell(values: &mut [Sample], p: &FusionParams) -> Option<CellFusion> {
    let mut n = 0;
    for i in 0..values.len() {
        if values[i].height.is_finite() {
            values.swap(n, i);
            n += 1;
        }
    }
    let v = &mut values[..n];
    if v.is_empty() {
        return None;
    }
    v.sort_unstable_by(|a, b| a.height.total_cmp(&b.height));
    // The strongest cluster: the largest weight, the later (higher) one on a tie.
    let (mut best, mut best_weight, mut start, mut weight) = ((0, 0), f32::MIN, 0, 0.0);
    for i in 0..=v.len() {
        if i == v.len() || (i > start && v[i].height - v[i - 1].height > p.tolerance) {
            if weight >= best_weight {
                (best, best_weight) = ((start, i), weight);
            }
            (start, weight) = (i, 0.0);
        }
        if i < v.len() {
            weight += v[i].mass();
        }
    }
    let cluster = &v[best.0..best.1];
    let confidence: f32 = cluster.iter().map(|s| s.confidence).sum();
    if cluster.len() < p.min_support.max(1) || p.min_confidence.is_some_and(|m| confidence < m) {
        return None;
    }
    let weighted: Vec<(f32, f32)> = cluster.iter().map(|s| (s.height, s.mass())).collect();
    let height = weighted_median(&weighted);
    let mut dev: Vec<(f32, f32)> = weighted
        .iter()
        .map(|&(h, w)| ((h - height).abs(), w))
        .collect();
    dev.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    Some(CellFusion {
        height,
        spread: weighted_median(&dev),
        support: cluster.len(),
        confidence,
    })
}

/// How often one pair agrees with a fusion: of the cells where both have a height, those within
/// the tolerance of the fused one.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Agreement {
    pub compared: usize,
    pub agreeing: usize,
}

impl Agreement {
    /// The agreeing share, 0 when no cell was compared.
    pub fn share(&self) -> f64 {
        if self.compared == 0 {
            0.0
        } else {
            self.agreeing as f64 / self.compared as f64
        }
    }
}

/// The power of a pair's agreement that gives its weight. On the ten dev images (12 pairs,
/// 0.5 m clusters) every power tried beat equal weights and the higher powers did best
/// (BENCHMARKS.md, "Many dates, one DSM", "Pair weights").
pub const AGREEMENT_POWER: i32 = 8;

/// A pair's weight from its agreement with the equal-weight fusion: `share^8`, never below
/// 1e-6 so that a cell seen only by poor pairs still has a strongest cluster.
pub fn pair_weight(a: &Agreement) -> f32 {
    (a.share().powi(AGREEMENT_POWER) as f32).max(1e-6)
}

/// The fused grid (or a block of its rows).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Fused {
    /// Fused heights, NaN where no cluster was kept.
    pub heights: Vec<f32>,
    /// Pairs that measured each cell.
    pub counts: Vec<u16>,
    /// Spread of the kept cluster, NaN where none.
    pub spreads: Vec<f32>,
    /// Summed confidence of the kept cluster, NaN where none.
    pub confidences: Vec<f32>,
    /// Per layer, how often it agrees with the fused heights ([`fuse_files`] only).
    pub agreement: Vec<Agreement>,
}

impl Fused {
    fn with_capacity(n: usize) -> Self {
        Fused {
            heights: Vec::with_capacity(n),
            counts: Vec::with_capacity(n),
            spreads: Vec::with_capacity(n),
            confidences: Vec::with_capacity(n),
            agreement: Vec::new(),
        }
    }

    fn extend(&mut self, other: Fused) {
        self.heights.extend(other.heights);
        self.counts.extend(other.counts);
        self.spreads.extend(other.spreads);
        self.confidences.extend(other.confidences);
    }

    /// Cells with a fused height.
    pub fn measured(&self) -> usize {
        self.heights.iter().filter(|h| h.is_finite()).count()
    }
}

/// Fuses the same `cells` cells of every layer (one layer per pair, NaN = not measured), each
/// layer's heights weighted by `weights[layer]` and by their confidence (`confidences[layer]`,
/// the same cells; 1 everywhere when `None`).
pub fn fuse_block(
    layers: &[Vec<f32>],
    confidences: Option<&[Vec<f32>]>,
    weights: &[f32],
    cells: usize,
    p: &FusionParams,
) -> Fused {
    assert_eq!(layers.len(), weights.len(), "one weight per layer");
    if let Some(c) = confidences {
        assert_eq!(c.len(), layers.len(), "one confidence layer per layer");
    }
    let results: Vec<(f32, u16, f32, f32)> = (0..cells)
        .into_par_iter()
        .map_init(
            || Vec::with_capacity(layers.len()),
            |values: &mut Vec<Sample>, i| {
                values.clear();
                for (k, (l, &w)) in layers.iter().zip(weights).enumerate() {
                    if l[i].is_finite() {
                        let c = confidences.map_or(1.0, |c| c[k][i]);
                        values.push(Sample::new(l[i], w, c));
                    }
                }
                let count = values.len().min(u16::MAX as usize) as u16;
                match fuse_cell(values, p) {
                    Some(c) => (c.height, count, c.spread, c.confidence),
                    None => (f32::NAN, count, f32::NAN, f32::NAN),
                }
            },
        )
        .collect();
    let mut out = Fused::with_capacity(cells);
    for (h, n, s, c) in results {
        out.heights.push(h);
        out.counts.push(n);
        out.spreads.push(s);
        out.confidences.push(c);
    }
    out
}

/// Adds to `agreement` (one per layer) how the layers' cells compare with the fused `heights`.
fn count_agreement(layers: &[Vec<f32>], heights: &[f32], tol: f32, agreement: &mut [Agreement]) {
    for (layer, a) in layers.iter().zip(agreement.iter_mut()) {
        for (&v, &h) in layer.iter().zip(heights) {
            if v.is_finite() && h.is_finite() {
                a.compared += 1;
                a.agreeing += usize::from((v - h).abs() <= tol);
            }
        }
    }
}

/// How a pair's DSM is moved onto the reference: `out(x, y) = dsm(x − dx, y − dy) + offset`
/// (as [`eval::align::apply`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Shift {
    pub dx: i32,
    pub dy: i32,
    pub offset: f32,
}

/// Rows `y0..y0 + n` of the `w`-wide DSM of `reader` moved by `s`, NaN where they fall outside.
fn read_shifted(
    reader: &mut TiffReader,
    (w, h): (usize, usize),
    y0: usize,
    n: usize,
    s: Shift,
) -> Result<Vec<f32>> {
    let mut out = vec![f32::NAN; w * n];
    let (dx, dy) = (s.dx as i64, s.dy as i64);
    let rows = (y0 as i64 - dy).max(0)..(y0 as i64 + n as i64 - dy).min(h as i64);
    let cols = (-dx).max(0)..(w as i64 - dx).min(w as i64);
    if rows.is_empty() || cols.is_empty() {
        return Ok(out);
    }
    let (sw, sh) = (
        (cols.end - cols.start) as usize,
        (rows.end - rows.start) as usize,
    );
    let window = reader.read_window(cols.start as usize, rows.start as usize, sw, sh)?;
    let src = window.data();
    for r in 0..sh {
        let y = (rows.start + r as i64 + dy) as usize - y0;
        let x = (cols.start + dx) as usize;
        let dst = &mut out[y * w + x..y * w + x + sw];
        for (d, v) in dst.iter_mut().zip(&src[r * sw..(r + 1) * sw]) {
            *d = v + s.offset;
        }
    }
    Ok(out)
}

/// One pair's DSM to fuse: its file, its confidence sidecar when the fusion uses them, and how
/// it is moved onto the reference.
#[derive(Clone, Debug, PartialEq)]
pub struct Layer {
    pub dsm: PathBuf,
    pub confidence: Option<PathBuf>,
    pub shift: Shift,
}

/// Opens a single-band raster of the fused grid, or says how to get a good one.
fn open_layer(path: &Path, (w, h): (usize, usize)) -> Result<TiffReader> {
    let r = TiffReader::open(path).with_context(|| format!("opening {}", path.display()))?;
    if r.size() != (w, h) || r.bands() != 1 {
        bail!(
            "{}: {}x{}x{} cells, expected one band of {w}x{h} (the fused grid): delete it so \
             that its pair is reconstructed again",
            path.display(),
            r.size().0,
            r.size().1,
            r.bands()
        );
    }
    Ok(r)
}

/// Fuses the single-band DSMs of `layers`, all on `grid`, each moved by its shift and weighted
/// by its weight and (when every layer has one) its confidence, reading `rows_per_block` rows of
/// each at a time; the result also says how often each DSM agrees with it.
pub fn fuse_files(
    layers: &[Layer],
    weights: &[f32],
    grid: &DsmGrid,
    rows_per_block: usize,
    p: &FusionParams,
    progress: &dyn Progress,
) -> Result<Fused> {
    let (w, h) = (grid.width, grid.height);
    let with_confidence = !layers.is_empty() && layers.iter().all(|l| l.confidence.is_some());
    let mut readers = Vec::with_capacity(layers.len());
    let mut confidence_readers = Vec::with_capacity(layers.len());
    for layer in layers {
        readers.push(open_layer(&layer.dsm, (w, h))?);
        if let (true, Some(c)) = (with_confidence, &layer.confidence) {
            confidence_readers.push(open_layer(c, (w, h))?);
        }
    }
    let rows = rows_per_block.max(1);
    let blocks = h.div_ceil(rows);
    let mut out = Fused::with_capacity(w * h);
    out.agreement = vec![Agreement::default(); layers.len()];
    progress.begin("fusing", blocks);
    for b in 0..blocks {
        let (y0, n) = (b * rows, rows.min(h - b * rows));
        let read = |r: &mut TiffReader, path: &Path, shift: Shift| {
            read_shifted(r, (w, h), y0, n, shift)
                .with_context(|| format!("reading rows {y0}.. of {}", path.display()))
        };
        let heights: Vec<Vec<f32>> = readers
            .iter_mut()
            .zip(layers)
            .map(|(r, l)| read(r, &l.dsm, l.shift))
            .collect::<Result<_>>()?;
        let confidences: Option<Vec<Vec<f32>>> = if with_confidence {
            // The confidence moves with its DSM, without the vertical offset.
            let moved = |s: Shift| Shift { offset: 0.0, ..s };
            Some(
                confidence_readers
                    .iter_mut()
                    .zip(layers)
                    .map(|(r, l)| read(r, l.confidence.as_deref().expect("all"), moved(l.shift)))
                    .collect::<Result<_>>()?,
            )
        } else {
            None
        };
        let block = fuse_block(&heights, confidences.as_deref(), weights, w * n, p);
        count_agreement(&heights, &block.heights, p.tolerance, &mut out.agreement);
        out.extend(block);
        progress.advance(b + 1);
    }
    progress.end();
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use raster::Image;

    const NAN: f32 = f32::NAN;

    fn fuse(v: &[f32], p: &FusionParams) -> Option<CellFusion> {
        fuse_weighted(v, &vec![1.0; v.len()], p)
    }

    fn fuse_weighted(v: &[f32], w: &[f32], p: &FusionParams) -> Option<CellFusion> {
        fuse_confident(v, w, &vec![1.0; v.len()], p)
    }

    fn fuse_confident(v: &[f32], w: &[f32], c: &[f32], p: &FusionParams) -> Option<CellFusion> {
        let mut values: Vec<Sample> = (0..v.len())
            .map(|i| Sample::new(v[i], w[i], c[i]))
            .collect();
        fuse_cell(&mut values, p)
    }

    #[test]
    fn a_bimodal_cell_keeps_the_stronger_mode() {
        let p = FusionParams {
            tolerance: 1.0,
            min_support: 1,
            min_confidence: None,
        };
        // Three pairs see the roof near 20 m, two the ground near 10 m.
        let c = fuse(&[10.0, 20.2, 19.9, 10.3, 20.0], &p).unwrap();
        assert_eq!((c.height, c.support), (20.0, 3));
        assert!((c.spread - 0.1).abs() < 1e-5, "{c:?}");
        // The ground wins when more pairs see it.
        let c = fuse(&[10.0, 20.2, 10.1, 10.3, 20.0], &p).unwrap();
        assert_eq!((c.height, c.support), (10.1, 3));
        // A tie goes to the higher cluster.
        let c = fuse(&[10.0, 20.0, 10.4, 20.6], &p).unwrap();
        assert!((c.height - 20.3).abs() < 1e-5 && c.support == 2, "{c:?}");
        // NaNs are not measurements.
        let c = fuse(&[NAN, 5.0, NAN, 5.5, 30.0], &p).unwrap();
        assert_eq!((c.height, c.support), (5.25, 2));
        assert_eq!(fuse(&[NAN, NAN], &p), None);
        // Nothing agrees enough: no height.
        let strict = FusionParams {
            min_support: 2,
            ..p
        };
        assert_eq!(fuse(&[1.0, 5.0, 9.0], &strict), None);
        assert_eq!(fuse(&[1.0, 5.0, 5.5], &strict).unwrap().height, 5.25);
    }

    #[test]
    fn weights_choose_the_mode_and_the_median() {
        let p = FusionParams {
            tolerance: 1.0,
            min_support: 1,
            min_confidence: None,
        };
        let v = [10.0, 20.2, 19.9, 10.3, 20.0];
        // Two trusted pairs on the ground outweigh three poor ones on the roof.
        let c = fuse_weighted(&v, &[1.0, 0.1, 0.1, 1.0, 0.1], &p).unwrap();
        assert_eq!(c.support, 2);
        assert!((c.height - 10.15).abs() < 1e-5, "{c:?}");
        // Within the kept cluster the weighted median follows the heavy pair.
        let c = fuse_weighted(&v, &[1.0, 0.2, 3.0, 1.0, 0.2], &p).unwrap();
        assert_eq!((c.height, c.support), (19.9, 3));
        assert!((c.spread - 0.0).abs() < 1e-6, "{c:?}");
        // Support still counts pairs, not weight.
        let strict = FusionParams {
            min_support: 3,
            ..p
        };
        assert_eq!(
            fuse_weighted(&v, &[1.0, 0.1, 0.1, 1.0, 0.1], &strict).map(|c| c.height),
            None
        );
        // Equal weights of any size are the plain fusion.
        for w in [0.3f32, 1.0, 7.0] {
            assert_eq!(fuse_weighted(&v, &[w; 5], &p), fuse(&v, &p), "weight {w}");
        }
    }

    #[test]
    fn confidence_weighs_the_heights_and_its_sum_decides_the_trust() {
        let p = FusionParams {
            tolerance: 1.0,
            min_support: 1,
            min_confidence: Some(1.25),
        };
        let v = [10.0, 20.2, 19.9, 10.3, 20.0];
        let ones = [1.0; 5];
        // Two confident pairs on the ground outweigh three hesitant ones on the roof.
        let c = fuse_confident(&v, &ones, &[0.9, 0.1, 0.2, 0.8, 0.1], &p).unwrap();
        assert_eq!(c.support, 2);
        assert!((c.confidence - 1.7).abs() < 1e-6, "{c:?}");
        assert!(
            (c.height - 10.0).abs() < 1e-6,
            "the more confident of the two: {c:?}"
        );
        // Three hesitant pairs that agree are not enough; two confident ones are.
        let roof = [20.2, 19.9, 20.0];
        assert_eq!(fuse_confident(&roof, &[1.0; 3], &[0.3, 0.4, 0.5], &p), None);
        let two = fuse_confident(&roof[..2], &[1.0; 2], &[0.7, 0.6], &p).unwrap();
        assert_eq!(two.support, 2);
        // A NaN confidence counts as none; without the rule the cell keeps its height.
        let nan = fuse_confident(&[5.0], &[1.0], &[NAN], &FusionParams::default()).unwrap();
        assert_eq!((nan.height, nan.confidence), (5.0, 0.0));
        // A confidence of 1 everywhere is the plain fusion, its sum the support.
        let plain = FusionParams {
            min_confidence: None,
            ..p
        };
        let c = fuse_confident(&v, &ones, &ones, &plain).unwrap();
        assert_eq!(Some(c), fuse(&v, &plain));
        assert_eq!(c.confidence, 3.0);
    }

    #[test]
    fn agreement_counts_the_cells_within_the_tolerance() {
        let layers = vec![vec![1.0, 2.0, NAN, 4.0], vec![1.2, 9.0, 3.0, NAN]];
        let mut a = vec![Agreement::default(); 2];
        count_agreement(&layers, &[1.1, 2.2, NAN, 4.6], 0.5, &mut a);
        assert_eq!(
            a,
            vec![
                Agreement {
                    compared: 3,
                    agreeing: 2
                },
                Agreement {
                    compared: 2,
                    agreeing: 1
                }
            ]
        );
        assert_eq!(a[1].share(), 0.5);
        assert_eq!(Agreement::default().share(), 0.0);
        assert_eq!(pair_weight(&Agreement::default()), 1e-6);
        assert!((pair_weight(&a[1]) - 0.5f32.powi(8)).abs() < 1e-9);
    }

    #[test]
    fn blocks_count_and_spread() {
        let layers = vec![
            vec![1.0, NAN, 3.0, NAN],
            vec![1.5, NAN, 9.0, 4.0],
            vec![NAN, NAN, 3.4, NAN],
        ];
        let p = FusionParams {
            tolerance: 1.0,
            min_support: 1,
            min_confidence: None,
        };
        let f = fuse_block(&layers, None, &[1.0; 3], 4, &p);
        assert_eq!(f.counts, vec![2, 0, 3, 1]);
        assert_eq!(f.heights[0], 1.25);
        assert!(f.heights[1].is_nan() && f.spreads[1].is_nan());
        assert!((f.heights[2] - 3.2).abs() < 1e-6);
        assert!((f.spreads[2] - 0.2).abs() < 1e-6);
        assert_eq!((f.heights[3], f.spreads[3]), (4.0, 0.0));
        assert_eq!(f.measured(), 3);
    }

    #[test]
    fn row_blocks_give_the_one_pass_result() {
        let dir = tempfile::tempdir().unwrap();
        let grid = DsmGrid::new(1000.0, 2000.0, 0.5, 7, 9, 32617).unwrap();
        let mut paths = Vec::new();
        let mut layers = Vec::new();
        for k in 0..4u32 {
            let data: Vec<f32> = (0..63u32)
                .map(|i| {
                    let v = ((i * 7 + k * 13) % 11) as f32 * 0.37 + (k % 2) as f32 * 5.0;
                    if (i + k) % 5 == 0 {
                        NAN
                    } else {
                        v
                    }
                })
                .collect();
            let path = dir.path().join(format!("p{k}.tif"));
            camera::write_dsm(&path, &Image::new(7, 9, 1, data.clone()).unwrap(), &grid).unwrap();
            paths.push(path);
            layers.push(data);
        }
        let p = FusionParams::default();
        let whole = fuse_block(&layers, None, &[1.0; 4], 63, &p);
        let paths: Vec<Layer> = paths
            .into_iter()
            .map(|p| Layer {
                dsm: p,
                confidence: None,
                shift: Shift::default(),
            })
            .collect();
        let mut agreement = vec![Agreement::default(); 4];
        count_agreement(&layers, &whole.heights, p.tolerance, &mut agreement);
        assert!(agreement.iter().all(|a| a.compared > 0));
        for rows in [1, 2, 4, 9, 100] {
            let f = fuse_files(&paths, &[1.0; 4], &grid, rows, &p, &workflow::Silent).unwrap();
            assert_eq!(f.counts, whole.counts, "{rows} rows");
            assert_eq!(f.agreement, agreement, "{rows} rows");
            let same = |a: &[f32], b: &[f32]| {
                a.iter()
                    .zip(b)
                    .all(|(x, y)| x == y || (x.is_nan() && y.is_nan()))
            };
            assert!(same(&f.heights, &whole.heights), "{rows} rows");
            assert!(same(&f.spreads, &whole.spreads), "{rows} rows");
        }
        assert!(whole.measured() > 50);
        // A DSM on another grid is refused, naming the file.
        let other = DsmGrid::new(1000.0, 2000.0, 0.5, 8, 9, 32617).unwrap();
        let e = fuse_files(&paths, &[1.0; 4], &other, 4, &p, &workflow::Silent).unwrap_err();
        assert!(format!("{e:#}").contains("p0.tif"), "{e:#}");
    }

    /// Three good pairs (the surface ± 0.1 m, holes) and two poor ones (every third cell the same
    /// mismatch 3 m above it): where a good pair has a hole, two good heights face two wrong ones
    /// and the equal-weight fusion takes the higher, wrong, cluster. It also measures how often
    /// each pair agrees, and the fusion weighted by that keeps the surface.
    #[test]
    fn agreement_weights_favour_the_pairs_that_agree() {
        let dir = tempfile::tempdir().unwrap();
        let (w, h) = (40, 30);
        let grid = DsmGrid::new(1000.0, 2000.0, 0.5, w, h, 32617).unwrap();
        let surface = |i: usize| {
            if ((i % w) / 10).is_multiple_of(2) {
                10.0
            } else {
                14.0
            }
        };
        let mut paths = Vec::new();
        for k in 0..5usize {
            let data: Vec<f32> = (0..w * h)
                .map(|i| {
                    let noise = ((i * 7 + k * 3) % 5) as f32 * 0.05 - 0.1;
                    match k {
                        _ if (i + 2 * k) % 7 == 0 => NAN,
                        3 | 4 if i % 3 == 0 => surface(i) + 3.0 + 0.01 * k as f32,
                        _ => surface(i) + noise,
                    }
                })
                .collect();
            let path = dir.path().join(format!("p{k}.tif"));
            camera::write_dsm(&path, &Image::new(w, h, 1, data).unwrap(), &grid).unwrap();
            paths.push(Layer {
                dsm: path,
                confidence: None,
                shift: Shift::default(),
            });
        }
        let p = FusionParams {
            tolerance: 0.4,
            min_support: 2,
            min_confidence: None,
        };
        let error = |f: &Fused| {
            let e: Vec<f32> = (0..w * h)
                .filter(|&i| f.heights[i].is_finite())
                .map(|i| (f.heights[i] - surface(i)).abs())
                .collect();
            e.iter().sum::<f32>() / e.len() as f32
        };
        let equal = fuse_files(&paths, &[1.0; 5], &grid, 7, &p, &workflow::Silent).unwrap();
        let shares: Vec<f64> = equal.agreement.iter().map(Agreement::share).collect();
        let worst_good = shares[..3].iter().copied().fold(1.0, f64::min);
        let best_poor = shares[3..].iter().copied().fold(0.0, f64::max);
        assert!(worst_good > best_poor + 0.03, "{shares:?}");
        let weights: Vec<f32> = equal.agreement.iter().map(pair_weight).collect();
        let weighted = fuse_files(&paths, &weights, &grid, 7, &p, &workflow::Silent).unwrap();
        assert!(
            error(&weighted) < 0.5 * error(&equal),
            "weighted {} vs equal {}",
            error(&weighted),
            error(&equal)
        );
        assert_eq!(weighted.counts, equal.counts);
    }

    #[test]
    fn shifted_blocks_are_the_benchmarks_shift() {
        let dir = tempfile::tempdir().unwrap();
        let grid = DsmGrid::new(1000.0, 2000.0, 0.5, 6, 5, 32617).unwrap();
        let data: Vec<f32> = (0..30).map(|i| i as f32).collect();
        let img = Image::new(6, 5, 1, data).unwrap();
        let path = dir.path().join("d.tif");
        camera::write_dsm(&path, &img, &grid).unwrap();
        for (dx, dy) in [(0, 0), (2, -1), (-3, 2), (7, 0), (0, -6), (-1, 1)] {
            let s = Shift {
                dx,
                dy,
                offset: 0.5,
            };
            let expected = eval::align::apply(&img, dx, dy, 0.5);
            for rows in [1, 2, 5] {
                let mut r = TiffReader::open(&path).unwrap();
                let mut got = Vec::new();
                for y0 in (0..5).step_by(rows) {
                    let n = rows.min(5 - y0);
                    got.extend(read_shifted(&mut r, (6, 5), y0, n, s).unwrap());
                }
                let same = got
                    .iter()
                    .zip(expected.data())
                    .all(|(a, b)| a == b || (a.is_nan() && b.is_nan()));
                assert!(
                    same,
                    "{dx},{dy} by {rows} rows: {got:?} vs {:?}",
                    expected.data()
                );
            }
        }
    }
}

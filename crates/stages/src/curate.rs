//! `curate`: which real synchronic pairs are consistent enough to supervise training (paper
//! Sec. 3.1, release `preprocessing/similarity/`).
//!
//! Per pair (resumable, shardable, cached in `<out>/scores/<stem>.json`): the right image is
//! warped into the left view by the teacher's disparity (x_R = x_L − d, the release's `grid_sample`
//! warp: `raster::geometry::warp_by_disparity_grid_sample`);
//! over the valid pixels (finite disparity, inside the right image) come the colour distance
//! statistics, the SSIM ([`raster::ssim::ssim_uniform_masked`]: scikit-image defaults, 7×7
//! uniform window) and `S_feat`, the cosine similarity of image features ([`features`]: DINOv3
//! with weights, else the offline [`features::HistogramDescriptor`]).
//!
//! Over all cached pairs (run when every pair has a score; with `--shard` the last shard to
//! finish does it, and a plain rerun always can):
//! * `d_color` = the mean per-pixel RGB distance (paper, SPEC; the release's column is
//!   `0.5·mean + 0.5·p95`, available as [`ColourStatistic::ReleaseMeanP95`]);
//! * `d_max` = the 95th percentile of `d_color` over all scored pairs, numpy's linear
//!   interpolation ([`select::percentile_linear`]), 1 when not positive;
//! * `S_color = 1 − min(d_color, d_max)/d_max`;
//! * `S_SSIM`: the release uses the raw mean SSIM (in [−1, 1], in practice ≥ 0) with no
//!   normalisation; the paper says "normalised to [0, 1]". Default [`SsimScale::Clamp`] keeps the
//!   release's value and clips negatives to 0; [`SsimScale::Affine`] uses (1 + SSIM)/2;
//! * `S_comb = 0.5 (S_color + S_SSIM)`;
//! * ranks by `S_comb` and by `S_feat` (descending, ties by stem), K from a count or a share, and
//!   the selection = the intersection of both top-K (a pair is in it for every K ≥ its joint rank
//!   `max(rank_comb, rank_feat)`). The release also drops pairs whose EPE against LiDAR exceeds
//!   3 px; with no LiDAR here that filter is not applied.
//!
//! Outputs: `scores.csv` (every score, both ranks, the joint rank, the selected flag),
//! `selected.txt` (stems), `selected.csv` (`id,left,right,…`, ordered as the release's
//! intersection: by S_feat, then S_comb, then stem), `curate.json` (settings, d_max, counts) and
//! `report.html` (scores against rank).

pub mod features;
pub mod score;
pub mod select;

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use dataset::shard::Shard;
use serde::{Deserialize, Serialize};
use serde_json::json;

use crate::teacher::{self, TeacherRecord};
use features::FeatureSimilarity;
use select::{colour_normaliser, colour_score, joint_rank, rank_desc, Keep};
use workflow::pairs::{PairFolder, PairPaths};
use workflow::progress::Progress;
use workflow::report::Report;
use workflow::stage::{run_items, write_json, write_text, BatchSummary};

/// The percentile of `d_color` that sets `d_max`.
pub const D_MAX_PERCENTILE: f64 = 95.0;

/// Which statistic of the per-pixel colour distances is `d_color`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum ColourStatistic {
    /// The mean (paper, SPEC).
    Mean,
    /// `0.5·mean + 0.5·p95`, the release's `color_distance_rgb`.
    ReleaseMeanP95,
}

/// How the mean SSIM becomes `S_SSIM` in [0, 1].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum SsimScale {
    /// `clamp(SSIM, 0, 1)`: the release's raw value where it is non-negative.
    Clamp,
    /// `(1 + SSIM)/2`.
    Affine,
}

/// What `curate` does.
pub struct CurateOptions {
    pub pairs_dir: PathBuf,
    /// The teacher folder (`<stem>.iio`, `teacher.json`).
    pub teacher_dir: PathBuf,
    pub out_dir: PathBuf,
    pub keep: Keep,
    pub colour: ColourStatistic,
    pub ssim_scale: SsimScale,
    pub shard: Shard,
    /// `S_feat`'s extractor (DINOv3, or [`features::HistogramDescriptor`]).
    pub features: Box<dyn FeatureSimilarity>,
}

/// The cached per-pair statistics (`<out>/scores/<stem>.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PairScore {
    pub stem: String,
    /// `ok`, or why the pair has no scores (`no valid pixels`).
    pub status: String,
    pub valid_ratio: f64,
    pub valid_pixels: usize,
    pub d_color_mean: Option<f64>,
    pub d_color_p95: Option<f64>,
    pub ssim: Option<f64>,
    pub s_feat: Option<f64>,
    /// The extractor behind `s_feat`.
    pub feature: String,
    /// The teacher record the disparity came from.
    pub teacher: serde_json::Value,
}

/// One row of `scores.csv`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RankedPair {
    pub stem: String,
    pub status: String,
    pub valid_ratio: f64,
    pub d_color_mean: Option<f64>,
    pub d_color_p95: Option<f64>,
    pub d_color: Option<f64>,
    pub s_color: Option<f64>,
    pub ssim: Option<f64>,
    pub s_ssim: Option<f64>,
    pub s_comb: Option<f64>,
    pub s_feat: Option<f64>,
    pub rank_comb: Option<usize>,
    pub rank_feat: Option<usize>,
    pub joint_rank: Option<usize>,
    pub selected: bool,
    pub feature: String,
}

/// What a run did.
#[derive(Clone, Debug)]
pub struct CurateSummary {
    pub scoring: BatchSummary,
    /// `None` while some pairs have no score yet (other shards still running).
    pub ranking: Option<Ranking>,
    pub missing: usize,
}

/// The outcome of the ranking step.
#[derive(Clone, Debug)]
pub struct Ranking {
    pub rows: Vec<RankedPair>,
    pub d_max: f64,
    pub k: usize,
    pub selected: Vec<String>,
    pub scores_csv: PathBuf,
    pub selected_txt: PathBuf,
    pub report: PathBuf,
}

fn score_path(out_dir: &Path, stem: &str) -> PathBuf {
    out_dir.join("scores").join(format!("{stem}.json"))
}

/// The teacher's record (`teacher.json`) as scores store it, `null` when the folder has none
/// (disparities from elsewhere).
fn teacher_record(teacher_dir: &Path) -> Result<serde_json::Value> {
    Ok(serde_json::to_value(TeacherRecord::read(teacher_dir)?)?)
}

fn read_score(path: &Path) -> Result<Option<PairScore>> {
    if !path.is_file() {
        return Ok(None);
    }
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    Ok(serde_json::from_str(&text).ok())
}

/// Scores one pair (no caching).
pub fn score_pair(
    pair: &PairPaths,
    disparity_path: &Path,
    features: &dyn FeatureSimilarity,
    teacher: &serde_json::Value,
) -> Result<PairScore> {
    let (left, right) = workflow::predict::read_pair(&pair.left, &pair.right)?;
    if !disparity_path.is_file() {
        bail!(
            "no teacher disparity {} for pair {}: run `seasonstereo teacher` first",
            disparity_path.display(),
            pair.stem
        );
    }
    let mut disparity = raster::read_image(disparity_path)
        .with_context(|| format!("reading the teacher disparity {}", disparity_path.display()))?;
    if disparity.channels() > 1 {
        disparity = disparity.channel(0);
    }
    let warped = score::WarpedPair::new(&left, &right, &disparity)
        .with_context(|| format!("warping pair {} by {}", pair.stem, disparity_path.display()))?;
    let stats = score::photometric(&warped)?;
    let mut s = PairScore {
        stem: pair.stem.clone(),
        status: "no valid pixels".into(),
        valid_ratio: 0.0,
        valid_pixels: 0,
        d_color_mean: None,
        d_color_p95: None,
        ssim: None,
        s_feat: None,
        feature: features.name(),
        teacher: teacher.clone(),
    };
    if let Some(p) = stats {
        let (l, lh) = warped.masked_u8();
        s.status = "ok".into();
        s.valid_ratio = p.valid_ratio;
        s.valid_pixels = p.valid_pixels;
        s.d_color_mean = Some(p.d_color_mean);
        s.d_color_p95 = Some(p.d_color_p95);
        s.ssim = Some(p.ssim).filter(|v| v.is_finite());
        s.s_feat = Some(features.similarity(&l, &lh, &warped.valid)?).filter(|v| v.is_finite());
    }
    Ok(s)
}

/// Runs `curate`: scores the shard's pairs that have no valid cached score, then ranks when every
/// pair is scored.
pub fn run_curate(opts: &CurateOptions, progress: &dyn Progress) -> Result<CurateSummary> {
    let pairs = PairFolder::new(&opts.pairs_dir).list()?;
    if pairs.is_empty() {
        bail!("no pairs in {}/L", opts.pairs_dir.display());
    }
    let teacher = teacher_record(&opts.teacher_dir)?;
    let feature = opts.features.name();
    let is_current = |s: &PairScore| s.feature == feature && s.teacher == teacher;
    let scoring = run_items(
        &pairs,
        &opts.shard,
        "curate: scoring pairs",
        progress,
        |p| matches!(read_score(&score_path(&opts.out_dir, &p.stem)), Ok(Some(s)) if is_current(&s)),
        |p| {
            let d = teacher::disparity_path(&opts.teacher_dir, &p.stem);
            let s = score_pair(p, &d, opts.features.as_ref(), &teacher)?;
            write_json(&score_path(&opts.out_dir, &p.stem), &s)
        },
        |p| p.stem.clone(),
    )?;
    let mut scores = Vec::with_capacity(pairs.len());
    let mut missing = 0;
    for p in &pairs {
        match read_score(&score_path(&opts.out_dir, &p.stem))? {
            Some(s) if is_current(&s) => scores.push(s),
            _ => missing += 1,
        }
    }
    let ranking = if missing == 0 {
        Some(rank_and_write(opts, &pairs, &scores)?)
    } else {
        None
    };
    Ok(CurateSummary {
        scoring,
        ranking,
        missing,
    })
}

/// The dataset-wide scores and ranks of cached per-pair statistics (pure; no files).
pub fn rank(
    scores: &[PairScore],
    colour: ColourStatistic,
    ssim_scale: SsimScale,
    keep: Keep,
) -> (Vec<RankedPair>, f64, usize) {
    let d_color: Vec<Option<f64>> = scores
        .iter()
        .map(|s| match colour {
            ColourStatistic::Mean => s.d_color_mean,
            ColourStatistic::ReleaseMeanP95 => Some(0.5 * s.d_color_mean? + 0.5 * s.d_color_p95?),
        })
        .collect();
    let finite: Vec<f64> = d_color.iter().flatten().copied().collect();
    let d_max = colour_normaliser(&finite, D_MAX_PERCENTILE).unwrap_or(1.0);
    let mut rows: Vec<RankedPair> = scores
        .iter()
        .zip(&d_color)
        .map(|(s, &d)| {
            let s_color = d.map(|d| colour_score(d, d_max));
            let s_ssim = s.ssim.map(|v| match ssim_scale {
                SsimScale::Clamp => v.clamp(0.0, 1.0),
                SsimScale::Affine => (1.0 + v.clamp(-1.0, 1.0)) / 2.0,
            });
            let s_comb = match (s_color, s_ssim) {
                (Some(c), Some(x)) => Some(0.5 * (c + x)),
                _ => None,
            };
            RankedPair {
                stem: s.stem.clone(),
                status: s.status.clone(),
                valid_ratio: s.valid_ratio,
                d_color_mean: s.d_color_mean,
                d_color_p95: s.d_color_p95,
                d_color: d,
                s_color,
                ssim: s.ssim,
                s_ssim,
                s_comb,
                s_feat: s.s_feat,
                rank_comb: None,
                rank_feat: None,
                joint_rank: None,
                selected: false,
                feature: s.feature.clone(),
            }
        })
        .collect();
    let names: Vec<&str> = scores.iter().map(|s| s.stem.as_str()).collect();
    let nan = f64::NAN;
    let comb: Vec<f64> = rows.iter().map(|r| r.s_comb.unwrap_or(nan)).collect();
    let feat: Vec<f64> = rows.iter().map(|r| r.s_feat.unwrap_or(nan)).collect();
    let (rc, rf) = (rank_desc(&comb, &names), rank_desc(&feat, &names));
    let k_comb = keep.k(rc.iter().flatten().count());
    let k_feat = keep.k(rf.iter().flatten().count());
    for (i, r) in rows.iter_mut().enumerate() {
        r.rank_comb = rc[i];
        r.rank_feat = rf[i];
        r.joint_rank = joint_rank(rc[i], rf[i]);
        r.selected = matches!((rc[i], rf[i]), (Some(a), Some(b)) if a <= k_comb && b <= k_feat);
    }
    (rows, d_max, k_comb.min(k_feat))
}

fn fmt(v: Option<f64>) -> String {
    v.map_or(String::new(), |v| format!("{v:.6}"))
}

/// Ranks the scored pairs, selects the intersection and writes the stage's outputs:
/// `scores.csv`, `selected.txt`, `selected.csv`, `curate.json` and the report.
fn rank_and_write(
    opts: &CurateOptions,
    pairs: &[PairPaths],
    scores: &[PairScore],
) -> Result<Ranking> {
    let (rows, d_max, k) = rank(scores, opts.colour, opts.ssim_scale, opts.keep);
    let out = &opts.out_dir;
    let scores_csv = out.join("scores.csv");
    write_scores_csv(&scores_csv, &rows, d_max)?;
    let sel = selection_order(&rows);
    let selected: Vec<String> = sel.iter().map(|r| r.stem.clone()).collect();
    let selected_txt = out.join("selected.txt");
    write_text(
        &selected_txt,
        &selected
            .iter()
            .map(|s| format!("{s}\n"))
            .collect::<String>(),
    )?;
    write_selected_csv(&out.join("selected.csv"), &sel, pairs)?;
    let feature = rows.first().map(|r| r.feature.clone()).unwrap_or_default();
    write_curate_json(opts, &rows, k, d_max, selected.len(), &feature)?;
    let report = out.join("report.html");
    write_report(&report, &rows, k, d_max, &feature, opts)?;
    Ok(Ranking {
        rows,
        d_max,
        k,
        selected,
        scores_csv,
        selected_txt,
        report,
    })
}

/// `scores.csv`: one row per pair in stem order, every score and rank.
fn write_scores_csv(path: &Path, rows: &[RankedPair], d_max: f64) -> Result<()> {
    let header = [
        "stem",
        "status",
        "valid_ratio",
        "d_color_mean",
        "d_color_p95",
        "d_color",
        "d_max",
        "s_color",
        "ssim",
        "s_ssim",
        "s_comb",
        "s_feat",
        "rank_comb",
        "rank_feat",
        "joint_rank",
        "selected",
        "feature",
    ];
    let mut text = header.join(",") + "\n";
    for r in rows {
        let rank = |v: Option<usize>| v.map_or(String::new(), |v| v.to_string());
        let cells = [
            r.stem.clone(),
            r.status.clone(),
            format!("{:.6}", r.valid_ratio),
            fmt(r.d_color_mean),
            fmt(r.d_color_p95),
            fmt(r.d_color),
            format!("{d_max:.6}"),
            fmt(r.s_color),
            fmt(r.ssim),
            fmt(r.s_ssim),
            fmt(r.s_comb),
            fmt(r.s_feat),
            rank(r.rank_comb),
            rank(r.rank_feat),
            rank(r.joint_rank),
            (r.selected as u8).to_string(),
            csv_quote(&r.feature),
        ];
        text += &(cells.join(",") + "\n");
    }
    write_text(path, &text)
}

/// The intersection, in the release's order: S_feat, then S_comb, descending, then stem.
fn selection_order(rows: &[RankedPair]) -> Vec<&RankedPair> {
    let mut sel: Vec<&RankedPair> = rows.iter().filter(|r| r.selected).collect();
    sel.sort_by(|a, b| {
        let key = |r: &RankedPair| (r.s_feat.unwrap_or(f64::NAN), r.s_comb.unwrap_or(f64::NAN));
        let (fa, ca) = key(a);
        let (fb, cb) = key(b);
        fb.total_cmp(&fa)
            .then(cb.total_cmp(&ca))
            .then(a.stem.cmp(&b.stem))
    });
    sel
}

/// `selected.csv`: the selected pairs' images and scores, in selection order.
fn write_selected_csv(path: &Path, sel: &[&RankedPair], pairs: &[PairPaths]) -> Result<()> {
    let by_stem: std::collections::HashMap<&str, &PairPaths> =
        pairs.iter().map(|p| (p.stem.as_str(), p)).collect();
    let mut csv = String::from("id,left,right,s_feat,s_comb,rank_feat,rank_comb\n");
    for r in sel {
        let p = by_stem[r.stem.as_str()];
        csv += &format!(
            "{},{},{},{},{},{},{}\n",
            r.stem,
            csv_quote(&p.left.display().to_string()),
            csv_quote(&p.right.display().to_string()),
            fmt(r.s_feat),
            fmt(r.s_comb),
            r.rank_feat.unwrap_or(0),
            r.rank_comb.unwrap_or(0)
        );
    }
    write_text(path, &csv)
}

/// `curate.json`: the counts and the definition of every score, for whoever reads the
/// selection later.
fn write_curate_json(
    opts: &CurateOptions,
    rows: &[RankedPair],
    k: usize,
    d_max: f64,
    selected: usize,
    feature: &str,
) -> Result<()> {
    let ranked = rows.iter().filter(|r| r.joint_rank.is_some()).count();
    write_json(
        &opts.out_dir.join("curate.json"),
        &json!({
            "pairs": rows.len(),
            "ranked": ranked,
            "unscored": rows.len() - ranked,
            "keep": opts.keep.describe(),
            "k": k,
            "selected": selected,
            "d_max": d_max,
            "d_max_definition": "95th percentile of d_color over all scored pairs, numpy 'linear' interpolation; 1 if not positive",
            "d_color": match opts.colour {
                ColourStatistic::Mean => "mean per-pixel RGB L2 distance over valid pixels",
                ColourStatistic::ReleaseMeanP95 => "0.5 mean + 0.5 p95 of the per-pixel RGB L2 distance (release's color_distance_rgb)",
            },
            "ssim": "scikit-image structural_similarity defaults (7x7 uniform window, sample covariance, K1 0.01, K2 0.03, data_range 255), full map averaged over valid pixels and channels",
            "s_ssim": match opts.ssim_scale {
                SsimScale::Clamp => "clamp(ssim, 0, 1)",
                SsimScale::Affine => "(1 + ssim) / 2",
            },
            "s_comb": "0.5 (s_color + s_ssim)",
            "feature_extractor": feature,
            "teacher": teacher_record(&opts.teacher_dir)?,
            "epe_filter": "not applied (no LiDAR disparity)",
        }),
    )
}

fn csv_quote(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

fn write_report(
    path: &Path,
    rows: &[RankedPair],
    k: usize,
    d_max: f64,
    feature: &str,
    opts: &CurateOptions,
) -> Result<()> {
    let sorted = |f: &dyn Fn(&RankedPair) -> Option<f64>| -> Vec<f64> {
        let mut v: Vec<f64> = rows
            .iter()
            .filter_map(f)
            .filter(|v| v.is_finite())
            .collect();
        v.sort_by(|a, b| b.total_cmp(a));
        v
    };
    let comb = sorted(&|r| r.s_comb);
    let feat = sorted(&|r| r.s_feat);
    let selected = rows.iter().filter(|r| r.selected).count();
    let mut rep = Report::new("Pair curation");
    rep.paragraph(&format!(
        "{} pairs, {} ranked; {} kept per ranking (K = {k}); {selected} pairs in the intersection. \
         d_max = {d_max:.3} (95th percentile of d_color). Features: {feature}.",
        rows.len(),
        comb.len().max(feat.len()),
        opts.keep.describe(),
    ))
    .heading("Scores against rank")
    .line_plot(
        &[("S_comb", &comb), ("S_feat", &feat)],
        "rank (1 = most consistent)",
        "score",
        Some(k as f64),
    );
    let mut best: Vec<&RankedPair> = rows.iter().filter(|r| r.joint_rank.is_some()).collect();
    best.sort_by_key(|r| (r.joint_rank, r.stem.clone()));
    let table_rows = |list: &[&RankedPair]| -> Vec<Vec<String>> {
        list.iter()
            .map(|r| {
                vec![
                    r.stem.clone(),
                    fmt(r.s_comb),
                    fmt(r.s_feat),
                    r.joint_rank.map_or(String::new(), |v| v.to_string()),
                    if r.selected {
                        "yes".into()
                    } else {
                        "no".into()
                    },
                ]
            })
            .collect()
    };
    let header = ["pair", "S_comb", "S_feat", "joint rank", "selected"];
    let n = best.len().min(10);
    rep.heading("Most consistent pairs")
        .table(&header, &table_rows(&best[..n]))
        .heading("Least consistent pairs")
        .table(&header, &table_rows(&best[best.len() - n..]));
    rep.write(path)
}

//! `teacher`: zero-shot disparities of the frozen teacher for every real synchronic pair (paper
//! Sec. 3.3); they supervise every synthetic combination of that pair and drive `curate`'s warp.
//!
//! Reads the pair layout of [`pairs`] and writes `<out>/<stem>.iio` (NPY float32, NaN = no
//! disparity) plus `<out>/teacher.json`, the record of which teacher made them. The stage is
//! resumable (an existing `<stem>.iio` is never recomputed; outputs are atomic, so a killed run
//! leaves only complete files) and shardable (`--shard i/n` takes a deterministic share of the
//! sorted stems, so an array job covers every pair exactly once). A folder holds one teacher
//! only: running another teacher into it is refused, so disparities are never silently mixed.

pub mod batch;
pub mod pairs;

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use dataset::shard::Shard;
use matching::SgmParams;
use serde_json::json;

use crate::predict::{predict_monster, predict_sgm, read_pair, write_disparity, MonsterOptions};
use crate::progress::{Progress, Silent};
use crate::world_io::write_json;
use batch::{run_items, BatchSummary};
pub use pairs::{list_pairs, SynchronicPair};

/// File name of the teacher record beside the disparities.
pub const RECORD_FILE: &str = "teacher.json";

/// Which teacher makes the disparities.
#[derive(Clone, Debug)]
pub enum Teacher {
    /// Census + SGM (the offline default). `range`: one disparity range for every pair; `None`
    /// takes each pair's `rectify/<stem>.json` range when present, else estimates it from the
    /// images (as `seasonstereo predict --method sgm` without `--range`).
    Sgm {
        params: SgmParams,
        range: Option<(i32, i32)>,
    },
    /// MonSter++ with the given weights (the paper's teacher).
    Monster(MonsterOptions),
}

impl Teacher {
    /// The record written to `teacher.json`: enough to tell two teachers apart and to rerun one.
    pub fn record(&self) -> serde_json::Value {
        match self {
            Teacher::Sgm { params, range } => json!({
                "teacher": "sgm",
                "description": "census 9x7 + semi-global matching (offline default teacher)",
                "range": match range {
                    Some((lo, hi)) => json!([lo, hi]),
                    None => json!("per pair: rectify/<stem>.json, else estimated from the images"),
                },
                "p1": params.p1,
                "p2": params.p2,
                "p2_adaptive": params.p2_adaptive,
                "paths": format!("{:?}", params.paths),
                "lr_tolerance": params.lr_tolerance,
                "uniqueness": params.uniqueness,
                "subpixel": params.subpixel,
                "median": params.median,
            }),
            Teacher::Monster(o) => json!({
                "teacher": "monsterpp",
                "description": "MonSter++ (zero-shot, frozen)",
                "weights": o.weights.display().to_string(),
                "preset": o.preset,
                "iters": o.iters,
                "max_disp": o.max_disp,
                "normalisation": format!("{:?}", o.normalisation),
            }),
        }
    }
}

/// What `teacher` does.
#[derive(Clone, Debug)]
pub struct TeacherOptions {
    /// The pair folder (`L/`, `R/`).
    pub pairs_dir: PathBuf,
    /// Where `<stem>.iio` and `teacher.json` go.
    pub out_dir: PathBuf,
    pub teacher: Teacher,
    pub shard: Shard,
}

/// The disparity file of pair `stem` in a teacher folder.
pub fn disparity_path(teacher_dir: &Path, stem: &str) -> PathBuf {
    teacher_dir.join(format!("{stem}.iio"))
}

/// Checks `teacher.json` in `out_dir` against `record`, writing it when absent. A different
/// teacher already recorded there is an error: its disparities would be mixed with these.
pub fn claim_folder(out_dir: &Path, record: &serde_json::Value) -> Result<()> {
    let path = out_dir.join(RECORD_FILE);
    if path.is_file() {
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("reading {}", path.display()))?;
        let old: serde_json::Value = serde_json::from_str(&text).with_context(|| {
            format!(
                "{} is not valid JSON (delete it if the folder holds no disparities)",
                path.display()
            )
        })?;
        if &old != record {
            bail!(
                "{} holds disparities of another teacher ({}); write this teacher ({}) to another folder, \
                 or empty the folder to redo it",
                out_dir.display(),
                old.get("teacher").and_then(|t| t.as_str()).unwrap_or("?"),
                record.get("teacher").and_then(|t| t.as_str()).unwrap_or("?"),
            );
        }
        return Ok(());
    }
    write_json(&path, record)
}

/// Runs the teacher over the pairs of the shard that have no disparity yet.
pub fn run_teacher(opts: &TeacherOptions, progress: &dyn Progress) -> Result<BatchSummary> {
    let pairs = list_pairs(&opts.pairs_dir)?;
    if pairs.is_empty() {
        bail!("no pairs in {}/L", opts.pairs_dir.display());
    }
    claim_folder(&opts.out_dir, &opts.teacher.record())?;
    let predictor = match &opts.teacher {
        Teacher::Monster(o) => Some(o.load().with_context(|| {
            format!("loading the MonSter++ teacher from {}", o.weights.display())
        })?),
        Teacher::Sgm { .. } => None,
    };
    let label = match &opts.teacher {
        Teacher::Sgm { .. } => "teacher (census + SGM)",
        Teacher::Monster(_) => "teacher (MonSter++)",
    };
    run_items(
        &pairs,
        &opts.shard,
        label,
        progress,
        |p| disparity_path(&opts.out_dir, &p.stem).is_file(),
        |p| {
            let (left, right) = read_pair(&p.left, &p.right)?;
            let disparity = match (&opts.teacher, &predictor) {
                (_, Some(net)) => predict_monster(net, &left, &right, &Silent)?,
                (Teacher::Sgm { params, range }, None) => {
                    let range = match range {
                        Some(r) => Some(*r),
                        None => pairs::rectify_range(&opts.pairs_dir, &p.stem)?,
                    };
                    predict_sgm(&left, &right, range, params, &Silent)?.0
                }
                (Teacher::Monster(_), None) => unreachable!("the network is loaded above"),
            };
            write_disparity(&disparity_path(&opts.out_dir, &p.stem), &disparity)
        },
        |p| p.stem.clone(),
    )
}

//! `teacher`: zero-shot disparities of the frozen teacher for every real synchronic pair (paper
//! Sec. 3.3); they supervise every synthetic combination of that pair and drive `curate`'s warp.
//!
//! Reads the pair layout of [`workflow::pairs`] and writes `<out>/<stem>.iio` (NPY float32, NaN = no
//! disparity) plus `<out>/teacher.json`, the record of which teacher made them. The stage is
//! resumable (an existing `<stem>.iio` is never recomputed; outputs are atomic, so a killed run
//! leaves only complete files) and shardable (`--shard i/n` takes a deterministic share of the
//! sorted stems, so an array job covers every pair exactly once). A folder holds one teacher
//! only: running another teacher into it is refused, so disparities are never silently mixed.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use dataset::shard::Shard;
use matching::DisparityRange;
use serde::{Deserialize, Serialize};

use workflow::matcher::{Matcher, RangeSource};
use workflow::pairs::PairFolder;
use workflow::predict::{read_pair, write_disparity};
use workflow::progress::{Progress, Silent};
use workflow::stage::{claim_folder, read_json, run_items, BatchSummary};

/// File name of the teacher record beside the disparities.
pub const RECORD_FILE: &str = "teacher.json";

/// `teacher.json`: which teacher made the disparities of a folder, enough to tell two teachers
/// apart and to rerun one.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TeacherRecord {
    /// `sgm` (the classical matcher, MGM or SGM) or `monsterpp`.
    pub teacher: String,
    /// The range rule of the classical teacher.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub range: Option<serde_json::Value>,
    /// The matcher's description and settings.
    #[serde(flatten)]
    pub settings: serde_json::Map<String, serde_json::Value>,
}

impl TeacherRecord {
    /// The record of `matcher` run over `range` (every pair), or per pair.
    pub fn new(matcher: &Matcher, range: Option<DisparityRange>) -> Self {
        let settings = match matcher.settings() {
            serde_json::Value::Object(m) => m,
            _ => serde_json::Map::new(),
        };
        let range = matches!(matcher, Matcher::Classical(_)).then(|| match range {
            Some((lo, hi)) => serde_json::json!([lo, hi]),
            None => {
                serde_json::json!("per pair: rectify/<stem>.json, else estimated from the images")
            }
        });
        TeacherRecord {
            teacher: matcher.kind().to_string(),
            range,
            settings,
        }
    }

    /// The record of a teacher folder, `None` when it has none (disparities from elsewhere).
    pub fn read(teacher_dir: &Path) -> Result<Option<Self>> {
        read_json(&teacher_dir.join(RECORD_FILE))
    }

    /// The folder of these disparities under a training set's `disparity_maps/`: the release
    /// calls MonSter++'s `monster++`.
    pub fn dataset_folder_name(&self) -> String {
        match self.teacher.as_str() {
            "monsterpp" => "monster++".to_string(),
            other => other.to_string(),
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
    pub matcher: Matcher,
    /// One disparity range for every pair (classical matcher); `None` takes each pair's
    /// `rectify/<stem>.json` range when present, else estimates it from the images.
    pub range: Option<DisparityRange>,
    pub shard: Shard,
}

/// The disparity file of pair `stem` in a teacher folder.
pub fn disparity_path(teacher_dir: &Path, stem: &str) -> PathBuf {
    teacher_dir.join(format!("{stem}.iio"))
}

/// Checks `teacher.json` in `out_dir` against `record`, writing it when absent. A different
/// teacher already recorded there is an error: its disparities would be mixed with these.
pub fn claim_teacher_folder(out_dir: &Path, record: &TeacherRecord) -> Result<()> {
    claim_folder(&out_dir.join(RECORD_FILE), record, |old| {
        format!(
            "{} holds disparities of another teacher ({}); write this teacher ({}) to another \
                 folder, or empty the folder to redo it",
            out_dir.display(),
            old.teacher,
            record.teacher
        )
    })
}

/// Runs the teacher over the pairs of the shard that have no disparity yet.
pub fn run_teacher(opts: &TeacherOptions, progress: &dyn Progress) -> Result<BatchSummary> {
    let folder = PairFolder::new(&opts.pairs_dir);
    let pairs = folder.list()?;
    if pairs.is_empty() {
        bail!("no pairs in {}/L", opts.pairs_dir.display());
    }
    claim_teacher_folder(
        &opts.out_dir,
        &TeacherRecord::new(&opts.matcher, opts.range),
    )?;
    let label = format!("teacher ({})", opts.matcher.name());
    run_items(
        &pairs,
        &opts.shard,
        &label,
        progress,
        |p| disparity_path(&opts.out_dir, &p.stem).is_file(),
        |p| {
            let (left, right) = read_pair(&p.left, &p.right)?;
            let range = RangeSource::for_pair(opts.range, &folder, &p.stem)?;
            let matched = opts
                .matcher
                .disparity(&left, &right, range, &Silent)
                .with_context(|| format!("matching {}", p.stem))?;
            write_disparity(&disparity_path(&opts.out_dir, &p.stem), &matched.disparity)
        },
        |p| p.stem.clone(),
    )
}

//! The rectified-pair folder, the one layout every stage reads and writes pairs in (the public
//! release's `synchronic_only/` and test splits, `seasonstereo rectify`, `world`, a `reconstruct`
//! work folder):
//!
//! ```text
//! <root>/L/<stem>.{iio,npy}        rectified left image, NPY float32 (H, W, C)
//! <root>/R/<stem>.{iio,npy}        rectified right image, same size
//! <root>/homography/<stem>.npz     Hleft, Hright: raw → rectified (optional for some stages)
//! <root>/disparity/<stem>.iio      a disparity of the pair (ground truth, or a matcher's)
//! <root>/rectify/<stem>.json       how `rectify` made the pair (RectifyRecord: ranges, region)
//! ```
//!
//! `<stem>` is `<LEFTID>-<RIGHTID>` ([`dataset::PairStem`]). Writers use `.iio`; readers take
//! `.iio` or `.npy` and refuse a stem present as both.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use camera::rectify::Roi;
use dataset::Side;
use raster::formats::read_homographies;
use raster::Homography;
use serde::{Deserialize, Serialize};

/// Extensions of rectified images, in order of preference.
pub const IMAGE_EXTENSIONS: [&str; 2] = ["iio", "npy"];

/// A folder of rectified pairs.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PairFolder {
    root: PathBuf,
}

/// The files of one pair of a [`PairFolder`] (the images as found, the companions where a writer
/// puts them).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PairPaths {
    pub stem: String,
    pub left: PathBuf,
    pub right: PathBuf,
    pub homography: PathBuf,
    pub disparity: PathBuf,
}

impl PairFolder {
    pub fn new(root: impl Into<PathBuf>) -> Self {
        PairFolder { root: root.into() }
    }

    pub fn root(&self) -> &Path {
        &self.root
    }

    fn file(&self, dir: &str, stem: &str, ext: &str) -> PathBuf {
        self.root.join(dir).join(format!("{stem}.{ext}"))
    }

    /// Where a writer puts pair `stem` (`.iio` images).
    pub fn paths(&self, stem: &str) -> PairPaths {
        PairPaths {
            stem: stem.to_string(),
            left: self.file("L", stem, "iio"),
            right: self.file("R", stem, "iio"),
            homography: self.file("homography", stem, "npz"),
            disparity: self.file("disparity", stem, "iio"),
        }
    }

    /// The record `rectify` wrote for pair `stem`.
    pub fn rectify_record_path(&self, stem: &str) -> PathBuf {
        self.file("rectify", stem, "json")
    }

    /// The stems of the left images, sorted (what a stage that reads only predictions and
    /// the frames' sizes needs).
    pub fn stems(&self) -> Result<Vec<String>> {
        Ok(self.left_images()?.into_iter().map(|(s, _)| s).collect())
    }

    fn left_images(&self) -> Result<Vec<(String, PathBuf)>> {
        if !self.root.is_dir() {
            anyhow::bail!(
                "{}: no such folder (a pair folder holds L/<stem>.iio and R/<stem>.iio)",
                self.root.display()
            );
        }
        image_stems(&self.root.join("L")).with_context(|| {
            format!(
                "{} is not a pair folder: expected L/<stem>.iio and R/<stem>.iio inside",
                self.root.display()
            )
        })
    }

    /// The pairs of the folder, sorted by stem (the order shards partition). Every `L/<stem>`
    /// needs its `R/<stem>`.
    pub fn list(&self) -> Result<Vec<PairPaths>> {
        self.left_images()?
            .into_iter()
            .map(|(stem, left)| {
                let right = self.image(Side::Right, &stem)?.with_context(|| {
                    format!(
                        "pair {stem}: {} has no right image R/{stem}.iio (or .npy) in {}",
                        left.display(),
                        self.root.display()
                    )
                })?;
                Ok(PairPaths {
                    left,
                    right,
                    ..self.paths(&stem)
                })
            })
            .collect()
    }

    /// Pair `stem` with its images as found (`.iio` or `.npy`); the `.iio` paths when absent, so
    /// the error of the first read names the file expected.
    pub fn pair(&self, stem: &str) -> Result<PairPaths> {
        let mut p = self.paths(stem);
        if let Some(l) = self.image(Side::Left, stem)? {
            p.left = l;
        }
        if let Some(r) = self.image(Side::Right, stem)? {
            p.right = r;
        }
        Ok(p)
    }

    /// The `side` image of pair `stem`, `None` when absent, an error when both `.iio` and `.npy`
    /// exist.
    pub fn image(&self, side: Side, stem: &str) -> Result<Option<PathBuf>> {
        let found: Vec<PathBuf> = IMAGE_EXTENSIONS
            .iter()
            .map(|e| self.file(side.dir(), stem, e))
            .filter(|p| p.is_file())
            .collect();
        match found.len() {
            0 => Ok(None),
            1 => Ok(found.into_iter().next()),
            _ => bail!(
                "{} and {} both exist: keep one of them",
                found[0].display(),
                found[1].display()
            ),
        }
    }

    /// Size `(width, height)` of the rectified pair `stem` (its left image).
    pub fn size(&self, stem: &str) -> Result<(usize, usize)> {
        let left = self
            .image(Side::Left, stem)?
            .with_context(|| format!("no L/{stem}.iio in {}", self.root.display()))?;
        Ok(raster::read_image(left)?.size())
    }

    /// The homographies (raw → rectified) of pair `stem`.
    pub fn homographies(&self, stem: &str) -> Result<(Homography, Homography)> {
        let path = self.paths(stem).homography;
        if !path.is_file() {
            bail!(
                "{} is missing: images and masks are rectified with the pair's homographies \
                 (written by `seasonstereo rectify`, or the release's synchronic_only/homography)",
                path.display()
            );
        }
        Ok(read_homographies(&path)?)
    }

    /// Every record of `rectify/`, sorted by file name (the pairs `rectify` or `reconstruct
    /// --keep-intermediates` made, whether or not their images are still here).
    pub fn rectify_records(&self) -> Result<Vec<RectifyRecord>> {
        let dir = self.root.join("rectify");
        let entries = std::fs::read_dir(&dir).with_context(|| {
            format!(
                "{}: no rectify records; give the folder `seasonstereo rectify` wrote (it holds \
                 rectify/<pair>.json)",
                self.root.display()
            )
        })?;
        let mut files: Vec<PathBuf> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().and_then(|e| e.to_str()) == Some("json"))
            .collect();
        files.sort();
        files
            .iter()
            .map(|f| {
                crate::stage::read_json(f)?
                    .with_context(|| format!("{} vanished while listing", f.display()))
            })
            .collect()
    }

    /// How `rectify` made pair `stem`, when it did.
    pub fn rectify_record(&self, stem: &str) -> Result<Option<RectifyRecord>> {
        let record: Option<RectifyRecord> =
            crate::stage::read_json(&self.rectify_record_path(stem))?;
        if let Some(r) = &record {
            let (lo, hi) = r.disparity_range;
            if lo > hi {
                bail!(
                    "{}: disparity_range [{lo}, {hi}] is reversed",
                    self.rectify_record_path(stem).display()
                );
            }
        }
        Ok(record)
    }
}

/// `(stem, path)` of every `.iio`/`.npy` file in `dir`, sorted by stem; hidden and temporary
/// files are ignored, a stem present with both extensions is refused.
fn image_stems(dir: &Path) -> Result<Vec<(String, PathBuf)>> {
    let entries =
        std::fs::read_dir(dir).with_context(|| format!("cannot list {}", dir.display()))?;
    let mut out: Vec<(String, PathBuf)> = Vec::new();
    for e in entries {
        let path = e
            .with_context(|| format!("listing {}", dir.display()))?
            .path();
        let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("");
        if !IMAGE_EXTENSIONS.contains(&ext) || !path.is_file() {
            continue;
        }
        let Some(stem) = path.file_stem().and_then(|s| s.to_str()) else {
            continue;
        };
        if stem.starts_with('.') {
            continue;
        }
        out.push((stem.to_string(), path));
    }
    out.sort();
    for w in out.windows(2) {
        if w[0].0 == w[1].0 {
            bail!(
                "{} and {} both exist: keep one of them",
                w[0].1.display(),
                w[1].1.display()
            );
        }
    }
    Ok(out)
}

/// The record of one rectified pair, `rectify/<stem>.json`: written by `rectify` and by
/// `reconstruct --keep-intermediates`, read through [`PairFolder::rectify_record`]
/// by `teacher` (the disparity range) and `masks --pairs` (the cameras and homographies).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RectifyRecord {
    pub stem: String,
    /// The raw images.
    pub left: PathBuf,
    pub right: PathBuf,
    /// The JSON cameras, when the images' RPC tags were not used.
    pub rpc_left: Option<PathBuf>,
    pub rpc_right: Option<PathBuf>,
    /// Region of the left raw image.
    pub roi: Roi,
    /// Altitudes of the scene, metres, and where they came from.
    pub alt_range: (f64, f64),
    #[serde(rename = "alt_range_source")]
    pub alt_source: String,
    /// Disparity search range of the rectified pair, pixels (inclusive).
    pub disparity_range: (i32, i32),
    /// `(width, height)` of the rectified images.
    pub size: (usize, usize),
    /// Where the region lies in the rectified frame.
    pub roi_in_frame: Roi,
    pub flipped: bool,
    pub pixels_per_metre: f64,
    pub max_row_error_px: f64,
    /// Share of the region the right image covers.
    pub right_coverage: f64,
    #[serde(rename = "Hleft")]
    pub h_left: [[f64; 3]; 3],
    #[serde(rename = "Hright")]
    pub h_right: [[f64; 3]; 3],
    pub files: RectifiedFiles,
}

/// The files of a rectified pair.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RectifiedFiles {
    pub left: PathBuf,
    pub right: PathBuf,
    pub homography: PathBuf,
}

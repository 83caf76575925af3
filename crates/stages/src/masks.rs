//! `masks`: water, tree and building masks from ONE segmentation pass per image (paper Sec. 3.2,
//! release `preprocessing/segmentation/infer_{water,tree,building}_openearthmap.py`).
//!
//! Input: every image under a folder (recursive; `.png .tif .tiff .iio .npy`, sorted by path;
//! outputs are named by file stem, so stems must be unique). Output, in the release's layout
//! (`../shared/design/segformer-dinov3.md` A.4), for each image `<stem>`:
//!
//! ```text
//! <out>/water_segmentation/masks/<stem>_mask.png      0 = water, 255 = other
//! <out>/tree_segmentation/masks/<stem>_mask.png       0 = tree, 1 = other
//! <out>/building_segmentation/masks/<stem>_mask.png   0 = building, 1 = other
//! <out>/<class>_segmentation/probs/<stem>_<class>_prob.png   uint8(trunc(255·p))
//! <out>/<class>_segmentation/<class>_percentages.txt         one line per image (rebuilt each run)
//! <out>/classes/<stem>.png                            the class map (OpenEarthMap ids)
//! <out>/records/<stem>.json                           written last: the image is finished
//! <out>/masks.json                                    which segmenter made the folder
//! ```
//!
//! The segmenter is SegFormer (OpenEarthMap mit-b2, `nn::segformer`) with weights (preferred),
//! the offline [`rules`] for real imagery (colour + height above ground from the pairs'
//! disparities, [`heights`]; scored against real labels by [`score`]), or the offline
//! [`offline::PixelClassifier`] trained on the procedural world; all go through the same
//! post-processing (`dataset::segmentation`: small-component removal, hole filling,
//! building dilation, areas in percent of the image). Masks stay in the frame of the image they
//! were computed on: `dataset build` rectifies raw-image masks with each pair's homographies.
//! Resumable (finished images skipped) and shardable over the sorted image list.

pub mod heights;
pub mod offline;
pub mod pixel_features;
pub mod project;
pub mod rules;
pub mod score;

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use dataset::segmentation::{
    argmax_classes, class_mask, percentages_header, MaskKind, MaskOptions, Segmentation,
};
use dataset::shard::Shard;
use raster::formats::{write_png, PngDepth};
use raster::Image;
use serde::{Deserialize, Serialize};
use serde_json::json;

use workflow::progress::Progress;
use workflow::stage::{claim_folder, read_json, run_items, write_json, BatchSummary};

/// File suffixes read as images (case-insensitive).
pub const IMAGE_SUFFIXES: [&str; 5] = ["png", "tif", "tiff", "iio", "npy"];
/// Name of the folder record.
pub const RECORD_FILE: &str = "masks.json";

/// Water, tree and building masks of one image, in one pass.
pub trait ImageSegmenter {
    /// Written to `masks.json` and every record.
    fn name(&self) -> String;
    /// Masks at the image's own size; `image` holds 8-bit values (0–255), 1–4 channels.
    fn segment(&self, image: &Image) -> Result<Segmentation>;
    /// [`ImageSegmenter::segment`] of a listed image, with what the record should say about the
    /// inputs it used beyond the pixels (e.g. heights); segmenters that need only the pixels keep
    /// this default.
    fn segment_input(
        &self,
        image: &Image,
        _input: &InputImage,
    ) -> Result<(Segmentation, serde_json::Value)> {
        Ok((self.segment(image)?, serde_json::Value::Null))
    }
}

/// `masks.json` (and the first field of every image's record): which segmenter made the masks.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct MasksRecord {
    pub segmenter: String,
}

impl MasksRecord {
    /// The record of a masks folder, `None` when it has none.
    pub fn read(masks_dir: &Path) -> Result<Option<Self>> {
        read_json(&masks_dir.join(RECORD_FILE))
    }
}

/// The SegFormer layout of the release's weights (OpenEarthMap mit-b2): the preset
/// [`SegformerSegmenter::load`] is given unless another is asked for.
pub const SEGFORMER_PRESET: &str = "mit-b2";

/// SegFormer with the release's weights.
#[cfg(feature = "network")]
pub struct SegformerSegmenter {
    pub segmenter: nn::segformer::Segmenter,
    /// The weights file, for the record.
    pub weights: PathBuf,
}

#[cfg(feature = "network")]
impl SegformerSegmenter {
    /// Loads the release's checkpoint (`openearthmap_segformer_mit-b2.pt`, or safetensors in HF
    /// naming) strictly; `preset` `mit-b2` (the release) or `tiny` (the parity fixture).
    pub fn load(weights: &Path, preset: &str, device: nn::device::DeviceChoice) -> Result<Self> {
        use nn::segformer::{SegformerConfig, Segmenter, SegmenterConfig};
        let config = match preset {
            "mit-b2" | "mit_b2" => SegmenterConfig::release(),
            "tiny" => SegmenterConfig::with_model(SegformerConfig::tiny()),
            other => bail!("unknown SegFormer preset {other:?} (expected mit-b2 or tiny)"),
        };
        let device = device.device().map_err(anyhow::Error::msg)?;
        let segmenter = Segmenter::from_file(weights, config, &device)
            .with_context(|| format!("loading SegFormer from {}", weights.display()))?;
        Ok(SegformerSegmenter {
            segmenter,
            weights: weights.to_path_buf(),
        })
    }
}

#[cfg(feature = "network")]
impl ImageSegmenter for SegformerSegmenter {
    fn name(&self) -> String {
        format!("segformer ({})", self.weights.display())
    }

    fn segment(&self, image: &Image) -> Result<Segmentation> {
        Ok(self.segmenter.segment(image)?)
    }
}

/// The offline default: [`offline::PixelClassifier`] + the release's post-processing.
pub struct OfflineSegmenter {
    /// Options of the water, tree and building masks (the release's defaults by default).
    pub options: [MaskOptions; 3],
}

impl Default for OfflineSegmenter {
    fn default() -> Self {
        OfflineSegmenter {
            options: MaskKind::ALL.map(MaskOptions::defaults),
        }
    }
}

impl ImageSegmenter for OfflineSegmenter {
    fn name(&self) -> String {
        format!(
            "offline pixel classifier v1 (Gaussian mixtures on colour/texture features, trained on procedural worlds {:?} at {} px)",
            offline::TRAINING_SEEDS,
            offline::TRAINING_SIZE
        )
    }

    fn segment(&self, image: &Image) -> Result<Segmentation> {
        let (w, h) = image.size();
        if w == 0 || h == 0 {
            bail!("the image is empty");
        }
        let model = offline::PixelClassifier::shared()?;
        let probs = model.probabilities(image);
        let pred = argmax_classes(&probs, offline::CLASSES);
        let mask = |i: usize| class_mask(MaskKind::ALL[i], &self.options[i], &probs, &pred, w, h);
        Ok(Segmentation {
            classes: Image::new(w, h, 1, pred.iter().map(|&c| c as f32).collect())?,
            water: mask(0)?,
            tree: mask(1)?,
            building: mask(2)?,
        })
    }
}

/// The offline default for real imagery: [`rules`] on colour and, when the pairs are given, on
/// the height above ground from their disparities ([`heights`]).
pub struct RulesSegmenter {
    pub options: [MaskOptions; 3],
    /// Rectified pairs with disparities; `None`: colour only.
    pub pairs: Option<heights::PairIndex>,
}

impl RulesSegmenter {
    pub fn new(pairs: Option<heights::PairIndex>) -> Self {
        RulesSegmenter {
            options: MaskKind::ALL.map(MaskOptions::defaults),
            pairs,
        }
    }
}

/// Measured on the 10 DFC2019 JAX_068 development images against the LiDAR classes
/// (BENCHMARKS.md, "Masks on real imagery"), for `--help` and the records.
pub const RULES_REAL_SCORES: &str =
    "DFC2019 JAX_068 dev, 10 images: tree IoU 0.36 (recall 0.63), building IoU 0.78 with heights (targets tree IoU 0.6 / recall 0.7 not met: LiDAR class 5 misses much visible canopy); colour only tree IoU 0.21 (recall 0.70)";

impl ImageSegmenter for RulesSegmenter {
    fn name(&self) -> String {
        let heights = match &self.pairs {
            Some(_) => "with heights above ground from the stereo pairs",
            None => "colour only: no pairs given, no building or water mask",
        };
        format!("offline rules v2 (vegetation index + height above ground; {heights}; {RULES_REAL_SCORES})")
    }

    fn segment(&self, image: &Image) -> Result<Segmentation> {
        rules::segment(image, None, &self.options)
    }

    fn segment_input(
        &self,
        image: &Image,
        input: &InputImage,
    ) -> Result<(Segmentation, serde_json::Value)> {
        let Some(index) = &self.pairs else {
            return Ok((
                self.segment(image)?,
                json!({"heights": "none (colour only)"}),
            ));
        };
        match heights::image_heights(index, &input.stem, image.size())? {
            Some(h) => {
                let known = |im: &Image| {
                    im.data().iter().filter(|v| v.is_finite()).count() as f64
                        / im.data().len().max(1) as f64
                };
                let note = json!({"heights": {"pairs": h.pairs, "measured_share": known(&h.measured), "filled_share": known(&h.filled)}});
                Ok((rules::segment(image, Some(&h), &self.options)?, note))
            }
            None => Ok((
                self.segment(image)?,
                json!({"heights": format!("none: {} is in no pair with a disparity (colour only)", input.stem)}),
            )),
        }
    }
}

/// What `masks` does.
pub struct MasksOptions {
    pub images_dir: PathBuf,
    pub out_dir: PathBuf,
    pub shard: Shard,
    pub segmenter: Box<dyn ImageSegmenter>,
}

/// One input image.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct InputImage {
    pub stem: String,
    /// File name with its extension (the percentage files' first column).
    pub file_name: String,
    pub path: PathBuf,
}

/// The images under `dir` (recursive), sorted by path; duplicate stems are refused (the outputs
/// are named by stem).
pub fn list_images(dir: &Path) -> Result<Vec<InputImage>> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) -> Result<()> {
        let entries =
            std::fs::read_dir(dir).with_context(|| format!("cannot list {}", dir.display()))?;
        for e in entries {
            let path = e
                .with_context(|| format!("listing {}", dir.display()))?
                .path();
            let hidden = path
                .file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with('.'));
            if hidden {
                continue;
            }
            if path.is_dir() {
                walk(&path, out)?;
            } else {
                let ext = path
                    .extension()
                    .and_then(|e| e.to_str())
                    .unwrap_or("")
                    .to_ascii_lowercase();
                if IMAGE_SUFFIXES.contains(&ext.as_str()) {
                    out.push(path);
                }
            }
        }
        Ok(())
    }
    let mut paths = Vec::new();
    walk(dir, &mut paths)?;
    paths.sort();
    let mut images: Vec<InputImage> = Vec::with_capacity(paths.len());
    let mut seen = std::collections::HashMap::new();
    for path in paths {
        let stem = path
            .file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or("")
            .to_string();
        let file_name = path
            .file_name()
            .and_then(|s| s.to_str())
            .unwrap_or("")
            .to_string();
        if let Some(other) = seen.insert(stem.clone(), path.clone()) {
            bail!(
                "{} and {} have the same stem {stem:?}: outputs are named by stem, rename one",
                other.display(),
                path.display()
            );
        }
        images.push(InputImage {
            stem,
            file_name,
            path,
        });
    }
    Ok(images)
}

/// 8-bit values for the segmenter: NaN → 0, rounded; values above 255 are refused (rescale
/// 16-bit imagery first).
pub fn to_8bit(image: &Image, path: &Path) -> Result<Image> {
    let max = image.finite_range().map_or(0.0, |r| r.1);
    if max > 255.5 {
        bail!(
            "{} has values up to {max}: the segmenters expect 8-bit images (0–255); rescale it first",
            path.display()
        );
    }
    let mut out = image.clone();
    for v in out.data_mut() {
        *v = if v.is_finite() {
            v.round().clamp(0.0, 255.0)
        } else {
            0.0
        };
    }
    Ok(out)
}

/// Folder of class `kind` in the output.
pub fn class_dir(out_dir: &Path, kind: MaskKind) -> PathBuf {
    out_dir.join(format!("{}_segmentation", kind.name()))
}

/// The mask file of image `stem` (release naming).
pub fn mask_path(out_dir: &Path, kind: MaskKind, stem: &str) -> PathBuf {
    class_dir(out_dir, kind)
        .join("masks")
        .join(format!("{stem}_mask.png"))
}

/// The probability picture of image `stem`.
pub fn prob_path(out_dir: &Path, kind: MaskKind, stem: &str) -> PathBuf {
    class_dir(out_dir, kind)
        .join("probs")
        .join(format!("{stem}_{}_prob.png", kind.name()))
}

fn record_path(out_dir: &Path, stem: &str) -> PathBuf {
    out_dir.join("records").join(format!("{stem}.json"))
}

/// Writes every file of one image's segmentation; the record last.
pub fn write_segmentation(
    out_dir: &Path,
    image: &InputImage,
    seg: &Segmentation,
    segmenter: &str,
    inputs: &serde_json::Value,
) -> Result<()> {
    let mut lines = serde_json::Map::new();
    for kind in MaskKind::ALL {
        let m = seg.get(kind);
        write_png(
            mask_path(out_dir, kind, &image.stem),
            &m.png_values(),
            PngDepth::Eight,
        )?;
        write_png(
            prob_path(out_dir, kind, &image.stem),
            &m.probability_u8(),
            PngDepth::Eight,
        )?;
        lines.insert(
            kind.name().into(),
            m.percentage_line(&image.file_name).into(),
        );
    }
    write_png(
        out_dir.join("classes").join(format!("{}.png", image.stem)),
        &seg.classes,
        PngDepth::Eight,
    )?;
    write_json(
        &record_path(out_dir, &image.stem),
        &json!({"image": image.path.display().to_string(), "segmenter": segmenter, "inputs": inputs, "percentages": lines}),
    )
}

/// Rebuilds the three `<class>_percentages.txt` from the records present, sorted by file name.
pub fn write_percentages(out_dir: &Path) -> Result<usize> {
    let dir = out_dir.join("records");
    let mut records: Vec<serde_json::Value> = Vec::new();
    if dir.is_dir() {
        for e in std::fs::read_dir(&dir).with_context(|| format!("listing {}", dir.display()))? {
            let p = e?.path();
            if p.extension().and_then(|e| e.to_str()) != Some("json")
                || p.file_name()
                    .and_then(|n| n.to_str())
                    .is_some_and(|n| n.starts_with('.'))
            {
                continue;
            }
            let text =
                std::fs::read_to_string(&p).with_context(|| format!("reading {}", p.display()))?;
            records.push(
                serde_json::from_str(&text)
                    .with_context(|| format!("{} is not valid JSON", p.display()))?,
            );
        }
    }
    for kind in MaskKind::ALL {
        let mut lines: Vec<String> = records
            .iter()
            .filter_map(|r| r["percentages"][kind.name()].as_str().map(str::to_string))
            .collect();
        lines.sort();
        let text = std::iter::once(percentages_header(kind))
            .chain(lines)
            .map(|l| l + "\n")
            .collect::<String>();
        let path = class_dir(out_dir, kind).join(format!("{}_percentages.txt", kind.name()));
        raster::formats::write_atomically(&path, |f| std::io::Write::write_all(f, text.as_bytes()))
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(records.len())
}

fn record_segmenter(path: &Path) -> Option<String> {
    read_json::<MasksRecord>(path).ok()?.map(|r| r.segmenter)
}

/// Runs `masks` over the shard's unfinished images, then rebuilds the percentage files.
pub fn run_masks(opts: &MasksOptions, progress: &dyn Progress) -> Result<BatchSummary> {
    let images = list_images(&opts.images_dir)?;
    if images.is_empty() {
        bail!(
            "no images ({}) under {}",
            IMAGE_SUFFIXES.join(", "),
            opts.images_dir.display()
        );
    }
    let name = opts.segmenter.name();
    claim_folder(
        &opts.out_dir.join(RECORD_FILE),
        &MasksRecord {
            segmenter: name.clone(),
        },
        |old| {
            format!(
                "{} holds masks of another segmenter ({}); write these ({name}) to another folder",
                opts.out_dir.display(),
                old.segmenter
            )
        },
    )?;
    let summary = run_items(
        &images,
        &opts.shard,
        "masks (one segmentation per image)",
        progress,
        |im| {
            record_segmenter(&record_path(&opts.out_dir, &im.stem)).as_deref()
                == Some(name.as_str())
        },
        |im| {
            let raw = raster::read_image(&im.path)
                .with_context(|| format!("reading {}", im.path.display()))?;
            let (seg, inputs) = opts
                .segmenter
                .segment_input(&to_8bit(&raw, &im.path)?, im)
                .with_context(|| format!("segmenting {}", im.path.display()))?;
            write_segmentation(&opts.out_dir, im, &seg, &name, &inputs)
        },
        |im| im.path.display().to_string(),
    )?;
    write_percentages(&opts.out_dir)?;
    Ok(summary)
}

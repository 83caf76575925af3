//! `dataset build`: the training set in the layout the trainer reads (the release's
//! `dataset_generation.py` + `build_experiment_csv.py`, see [`dataset`] for the tree).
//!
//! Per selected real pair (the work items; resumable, shardable over the sorted pairs):
//! - `homography/<pair>.npz`: the pair's homographies adapted to the crops of `synthesize`;
//! - `masks/{L,R}`: the rectified footprint of each (cropped) raw image; without a crop record the
//!   finite pixels of the rectified real image (our `rectify` writes NaN outside);
//! - `water_masks`, `tree_masks`, `building_masks`: the `masks` stage's `<id>_mask.png` (release
//!   polarity: the class is 0), rectified; a missing file falls back like the release — keep
//!   masks all 1 inside the footprint, building masks all 0 — and is listed in
//!   `missing_files.txt`;
//! - the images of every combination: the real image and each accepted seasonal variant on both
//!   views, 25 combinations with 4 seasons (5 synchronic + 20 diachronic), NaN written as 0;
//! - the teacher disparity copied into `disparity_maps/<teacher>/` (`val/disparity/` for the
//!   validation split), LiDAR disparities into `disparity_maps/GT/`;
//! - `.build/<pair>.json`, written last: the pair's variants and fallbacks (its "finished" marker).
//!
//! Every file is written atomically and skipped when present, so a killed build redoes at most the
//! file it was writing. When every pair is finished (the last shard, or any rerun), the subsets
//! (S1, S2, S3, all; `sub_val` for a validation split), the AOI lists, `summary.txt`,
//! `missing_files.txt` and `manifest.json` are written.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use dataset::experiment::{write_aois, write_experiment_csv, ExperimentRow};
use dataset::layout::{DatasetDir, MaskKind, TrainLayout};
use dataset::manifest::{KindCounts, Manifest, SplitManifest, SubsetEntry};
use dataset::masks::{from_segmentation, segmentation_path, write_mask_npy, MaskFile};
use dataset::shard::Shard;
use dataset::subset::{build_subsets, PairVariants, Subset};
use dataset::{PairStem, Side};
use raster::formats::{write_homographies, write_npy, write_png, PngDepth};
use raster::geometry::warp_homography;
use raster::{Homography, Image, Mask};
use serde::{Deserialize, Serialize};

use crate::synthesize::{accepted_tags, selected_pairs, zero_invalid, CropRecord, SyntheticLayout};
use crate::teacher::TeacherRecord;
use workflow::pairs::PairFolder;
use workflow::progress::Progress;
use workflow::stage::write_text;

/// Name of the experiment list of a validation split.
pub const VAL_LIST: &str = "sub_val";

/// The `masks` stage's folders of `<id>_mask.png` files (any may be absent).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct MaskDirs {
    pub water: Option<PathBuf>,
    pub tree: Option<PathBuf>,
    pub building: Option<PathBuf>,
}

impl MaskDirs {
    /// The release's folders under `root`: `{water,tree,building}_segmentation/masks/`.
    pub fn release(root: &Path) -> Self {
        let d = |c: &str| Some(root.join(format!("{c}_segmentation")).join("masks"));
        MaskDirs {
            water: d("water"),
            tree: d("tree"),
            building: d("building"),
        }
    }

    /// The segmenter named in `<root>/masks.json` (written by `seasonstereo masks`).
    pub fn recorded_segmenter(root: &Path) -> Option<String> {
        let text = std::fs::read_to_string(root.join("masks.json")).ok()?;
        let v: serde_json::Value = serde_json::from_str(&text).ok()?;
        Some(v.get("segmenter")?.as_str()?.to_string())
    }

    fn dir(&self, kind: MaskKind) -> Option<&Path> {
        match kind {
            MaskKind::Water => self.water.as_deref(),
            MaskKind::Tree => self.tree.as_deref(),
            MaskKind::Building => self.building.as_deref(),
            MaskKind::Valid => None,
        }
    }
}

/// What `dataset build` does.
#[derive(Clone, Debug)]
pub struct BuildOptions {
    /// Synchronic pairs: `L/`, `R/` (rectified) and `homography/`.
    pub pairs_dir: PathBuf,
    /// Selected pairs (curate's list); `None` = every pair.
    pub selected: Option<PathBuf>,
    /// The `synthesize` folder; `None` = real pairs only.
    pub synthetic_dir: Option<PathBuf>,
    pub masks: MaskDirs,
    /// Name of the segmenter for the manifest.
    pub segmenter: String,
    /// Teacher disparities `<pair>.iio` of the real pairs.
    pub teacher_dir: PathBuf,
    /// Teacher name: the folder `disparity_maps/<name>` (default: from `teacher.json`; the release
    /// calls MonSter++'s `monster++`).
    pub teacher_name: Option<String>,
    /// LiDAR-derived (or exact) disparities `<pair>.iio`, optional.
    pub lidar_dir: Option<PathBuf>,
    /// The dataset folder.
    pub out_dir: PathBuf,
    /// `train` or `val`.
    pub split: String,
    /// Seed of the S3 draw.
    pub seed: u64,
    pub shard: Shard,
    /// Also write PNG previews (`png/…`), as the release does by default.
    pub previews: bool,
    /// Stop after writing this many combinations (tests: a build killed midway).
    pub stop_after: Option<usize>,
}

impl BuildOptions {
    pub fn new(pairs_dir: &Path, teacher_dir: &Path, out_dir: &Path) -> Self {
        BuildOptions {
            pairs_dir: pairs_dir.to_path_buf(),
            selected: None,
            synthetic_dir: None,
            masks: MaskDirs::default(),
            segmenter: "none (release defaults)".into(),
            teacher_dir: teacher_dir.to_path_buf(),
            teacher_name: None,
            lidar_dir: None,
            out_dir: out_dir.to_path_buf(),
            split: "train".into(),
            seed: 0,
            shard: Shard::ALL,
            previews: false,
            stop_after: None,
        }
    }
}

/// What one run did.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct BuildSummary {
    /// Selected pairs, and those of this shard.
    pub pairs: usize,
    pub pairs_in_shard: usize,
    /// Pairs finished before this run (skipped) and now.
    pub pairs_skipped: usize,
    pub pairs_done: usize,
    /// Combinations written now, and found already written.
    pub combinations_written: usize,
    pub combinations_skipped: usize,
    /// Pairs still unfinished (other shards, or `stop_after`).
    pub pending: usize,
    /// True when the subsets and the manifest were written.
    pub finalized: bool,
    /// Segmentation masks that fell back to the release's defaults (all pairs).
    pub missing_masks: usize,
    /// Rows of each subset list (when finalized).
    pub subsets: Vec<(String, KindCounts)>,
    /// Pairs that failed in this run (name, the error as one line); a rerun retries them.
    pub failed: Vec<(String, String)>,
}

/// The record of a finished pair (`<split>/.build/<pair>.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PairRecord {
    pub pair: String,
    pub left_tags: Vec<String>,
    pub right_tags: Vec<String>,
    pub combinations: usize,
    /// Segmentation files that were absent (release defaults used).
    pub missing_masks: Vec<String>,
    /// Variants rejected by the fidelity check.
    pub rejected: Vec<String>,
    pub width: usize,
    pub height: usize,
}

fn record_path(split_dir: &Path, pair: &PairStem) -> PathBuf {
    split_dir
        .join(".build")
        .join(format!("{}.json", pair.base_name()))
}

fn read_record(path: &Path) -> Result<Option<PairRecord>> {
    if !path.is_file() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(path)?;
    Ok(Some(serde_json::from_str(&text).with_context(|| {
        format!(
            "{} is malformed (delete it to rebuild the pair)",
            path.display()
        )
    })?))
}

/// The folder name of a teacher: `--teacher-name`, else `teacher.json`'s name (`monsterpp` →
/// the release's `monster++`), else the folder's own name.
fn teacher_name(opts: &BuildOptions) -> Result<String> {
    if let Some(n) = &opts.teacher_name {
        return Ok(n.clone());
    }
    if let Some(record) = TeacherRecord::read(&opts.teacher_dir)? {
        return Ok(record.dataset_folder_name());
    }
    Ok(opts
        .teacher_dir
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or("teacher")
        .to_string())
}

/// The split's layout and where its supervising disparities go.
fn split_layout(opts: &BuildOptions, dir: &DatasetDir, teacher: &str) -> TrainLayout {
    if opts.split == "val" {
        dir.val()
    } else {
        let l = TrainLayout::new(dir.split_dir(&opts.split), dir.teacher_dir(teacher));
        match opts.lidar_dir {
            Some(_) => l.with_lidar(dir.lidar_dir()),
            None => l,
        }
    }
}

/// Runs `dataset build` (see the module docs).
pub fn run_build(opts: &BuildOptions, progress: &dyn Progress) -> Result<BuildSummary> {
    if opts.split.is_empty() || opts.split.contains(['/', '\\']) {
        bail!(
            "split name {:?} must be a plain folder name (train, val)",
            opts.split
        );
    }
    let pairs = selected_pairs(&opts.pairs_dir, opts.selected.as_deref())?;
    let dir = DatasetDir::new(&opts.out_dir);
    let teacher = teacher_name(opts)?;
    let layout = split_layout(opts, &dir, &teacher);
    let synthetic = opts.synthetic_dir.as_ref().map(SyntheticLayout::new);
    let mut summary = BuildSummary {
        pairs: pairs.len(),
        ..Default::default()
    };
    let mine = opts.shard.select(&pairs);
    summary.pairs_in_shard = mine.len();
    let mut budget = opts.stop_after;
    progress.begin(&format!("dataset build ({})", opts.split), mine.len());
    for (k, pair) in mine.iter().enumerate() {
        if record_path(&layout.root, pair).is_file() {
            summary.pairs_skipped += 1;
        } else if budget == Some(0) {
            break;
        } else {
            match build_pair(
                opts,
                &layout,
                synthetic.as_ref(),
                pair,
                &mut summary,
                &mut budget,
            ) {
                Ok(true) => summary.pairs_done += 1,
                Ok(false) => {}
                Err(e) => summary
                    .failed
                    .push((pair.to_string(), workflow::outputs::one_line(&e))),
            }
        }
        progress.advance(k + 1);
    }
    progress.end();
    if let (Some((pair, cause)), 0) = (
        summary.failed.first(),
        summary.pairs_done + summary.pairs_skipped,
    ) {
        return Err(workflow::outputs::Incomplete::Nothing {
            message: format!(
                "no pair built: all {} failed; first, pair {pair}: {cause}",
                summary.failed.len()
            ),
        }
        .into());
    }

    let records: Vec<Option<PairRecord>> = pairs
        .iter()
        .map(|p| read_record(&record_path(&layout.root, p)))
        .collect::<Result<_>>()?;
    summary.pending = records.iter().filter(|r| r.is_none()).count();
    summary.missing_masks = records
        .iter()
        .flatten()
        .map(|r| r.missing_masks.len())
        .sum();
    if summary.pending == 0 {
        let records: Vec<PairRecord> = records.into_iter().flatten().collect();
        finalize(
            opts,
            &dir,
            &layout,
            &teacher,
            &pairs,
            &records,
            &mut summary,
        )?;
    }
    Ok(summary)
}

/// The variant `tag` of the `side` image of `pair` (from `synthesize`'s `cropped-synthetic/`),
/// rectified into the pair's frame (`size`) with the pair's homography `h` adapted to the crop.
/// Outside the crop's footprint the image is 0. This stage alone rectifies variants.
fn rectified_variant(
    layout: &SyntheticLayout,
    pair: &PairStem,
    side: Side,
    tag: &str,
    h: &Homography,
    size: (usize, usize),
) -> Result<Image> {
    let id = side_id(pair, side);
    let crop = layout.read_crop(id)?.with_context(|| {
        format!(
            "{} is missing: run `seasonstereo synthesize` for image {id}",
            layout.crop_record(id).display()
        )
    })?;
    let src = layout.variant(id, tag);
    let variant = raster::read_image(&src)?;
    if variant.size() != (crop.width, crop.height) {
        bail!(
            "{} is {}x{} but its crop is {}x{}",
            src.display(),
            variant.width(),
            variant.height(),
            crop.width,
            crop.height
        );
    }
    let (mut image, _) = warp_homography(&variant.to_rgb(), &crop.adapt(h), size.0, size.1)?;
    zero_invalid(&mut image);
    Ok(image)
}

/// The source image of one view: the real rectified image or a variant's tag.
fn real_image(pairs: &PairFolder, pair: &PairStem, side: Side) -> Result<Image> {
    let name = pair.base_name();
    let p = pairs
        .image(side, &name)?
        .with_context(|| format!("no {}/{name}.iio in {}", side.dir(), pairs.root().display()))?;
    let mut im = raster::read_image(&p)?.to_rgb();
    zero_invalid(&mut im);
    Ok(im)
}

/// Builds one pair; returns true when it is finished (false when `budget` ran out midway).
fn build_pair(
    opts: &BuildOptions,
    layout: &TrainLayout,
    synthetic: Option<&SyntheticLayout>,
    pair: &PairStem,
    summary: &mut BuildSummary,
    budget: &mut Option<usize>,
) -> Result<bool> {
    let inputs = PairInputs::read(opts, synthetic, pair)?;
    let missing_masks = write_geometry(opts, layout, pair, &inputs)?;
    copy_disparities(opts, layout, pair, &inputs)?;
    let Some(combinations) =
        write_combinations(opts, layout, synthetic, pair, &inputs, summary, budget)?
    else {
        return Ok(false);
    };
    let record = PairRecord {
        pair: inputs.name,
        left_tags: inputs.tags[0].clone(),
        right_tags: inputs.tags[1].clone(),
        combinations,
        missing_masks,
        rejected: rejected_variants(synthetic, pair)?,
        width: inputs.size.0,
        height: inputs.size.1,
    };
    workflow::stage::write_json(
        &record_path(&layout.root, pair),
        &serde_json::to_value(&record)?,
    )?;
    Ok(true)
}

/// What one pair is built from: its rectified frame, its accepted synthetic variants, their
/// crops and the pair's homographies.
struct PairInputs {
    /// `<left id>-<right id>`.
    name: String,
    pairs: PairFolder,
    /// The frame every rectified file must have.
    size: (usize, usize),
    /// Accepted variant tags of the left and the right image.
    tags: [Vec<String>; 2],
    /// The crop each side's variants were made on, if any.
    crop: [Option<CropRecord>; 2],
    /// `None` only when nothing needs them (no variants, no masks).
    homographies: Option<(Homography, Homography)>,
}

impl PairInputs {
    fn read(
        opts: &BuildOptions,
        synthetic: Option<&SyntheticLayout>,
        pair: &PairStem,
    ) -> Result<Self> {
        let name = pair.base_name();
        let pairs = PairFolder::new(&opts.pairs_dir);
        let size = pairs.size(&name)?;
        let accepted = match synthetic {
            Some(s) => accepted_tags(s, pair)?,
            None => Default::default(),
        };
        let tags = Side::BOTH.map(|side| accepted.get(side.dir()).cloned().unwrap_or_default());
        let crop_of = |side: Side| -> Result<Option<CropRecord>> {
            match synthetic {
                Some(s) => s.read_crop(side_id(pair, side)),
                None => Ok(None),
            }
        };
        let crop = [crop_of(Side::Left)?, crop_of(Side::Right)?];
        let homographies = match pairs.homographies(&name) {
            Ok(h) => Some(h),
            Err(e) => {
                let needed = tags.iter().any(|t| !t.is_empty())
                    || [MaskKind::Water, MaskKind::Tree, MaskKind::Building]
                        .iter()
                        .any(|k| opts.masks.dir(*k).is_some());
                if needed {
                    return Err(e);
                }
                None
            }
        };
        Ok(PairInputs {
            name,
            pairs,
            size,
            tags,
            crop,
            homographies,
        })
    }

    /// The homography of `side`, adapted to its variants' crop.
    fn cropped_homography(&self, side: usize) -> Option<Homography> {
        let h = self
            .homographies
            .as_ref()
            .map(|(l, r)| if side == 0 { *l } else { *r });
        h.map(|h| self.crop[side].map_or(h, |c| c.adapt(&h)))
    }
}

/// The geometry both sides share: the (cropped) homographies and each side's masks. Returns
/// the segmentations that were missing.
fn write_geometry(
    opts: &BuildOptions,
    layout: &TrainLayout,
    pair: &PairStem,
    inputs: &PairInputs,
) -> Result<Vec<String>> {
    if inputs.homographies.is_some() {
        let out = layout.homography(pair);
        if !out.is_file() {
            let (hl, hr) = (inputs.cropped_homography(0), inputs.cropped_homography(1));
            write_homographies(&out, &hl.expect("known"), &hr.expect("known"))?;
        }
    }
    let mut missing_masks = Vec::new();
    for (i, side) in Side::BOTH.into_iter().enumerate() {
        write_side_masks(
            opts,
            layout,
            pair,
            side,
            inputs.cropped_homography(i),
            inputs.crop[i],
            inputs.size,
            &mut missing_masks,
        )?;
    }
    Ok(missing_masks)
}

/// The teacher's disparity, and the LiDAR one for training splits when there is one.
fn copy_disparities(
    opts: &BuildOptions,
    layout: &TrainLayout,
    pair: &PairStem,
    inputs: &PairInputs,
) -> Result<()> {
    let name = &inputs.name;
    copy_disparity(
        &opts.teacher_dir.join(format!("{name}.iio")),
        &layout.teacher(pair),
        inputs.size,
        "teacher disparity: run `seasonstereo teacher` on the synchronic pairs",
    )?;
    if let (Some(src), Some(dst)) = (&opts.lidar_dir, layout.lidar(pair)) {
        if opts.split != "val" {
            copy_disparity(
                &src.join(format!("{name}.iio")),
                &dst,
                inputs.size,
                "LiDAR disparity of the pair",
            )?;
        }
    }
    Ok(())
}

/// Writes the images of every combination of the pair's real and synthetic sides that is not
/// there yet, one combination per unit of `budget`. Returns the number of combinations, or
/// `None` when the budget ran out first.
fn write_combinations(
    opts: &BuildOptions,
    layout: &TrainLayout,
    synthetic: Option<&SyntheticLayout>,
    pair: &PairStem,
    inputs: &PairInputs,
    summary: &mut BuildSummary,
    budget: &mut Option<usize>,
) -> Result<Option<usize>> {
    let variants = PairVariants {
        pair: pair.clone(),
        left_tags: inputs.tags[0].clone(),
        right_tags: inputs.tags[1].clone(),
    };
    let mut cache: HashMap<(Side, Option<String>), Image> = HashMap::new();
    let mut source = |side: Side, tag: &Option<String>| -> Result<Image> {
        let key = (side, tag.clone());
        if let Some(im) = cache.get(&key) {
            return Ok(im.clone());
        }
        let im = side_image(synthetic, pair, inputs, side, tag)?;
        cache.insert(key, im.clone());
        Ok(im)
    };
    let combos = variants.combinations();
    for combo in &combos {
        let files = [
            (Side::Left, layout.image(Side::Left, combo), &combo.left.tag),
            (
                Side::Right,
                layout.image(Side::Right, combo),
                &combo.right.tag,
            ),
        ];
        if files.iter().all(|(_, p, _)| p.is_file()) {
            summary.combinations_skipped += 1;
            continue;
        }
        if *budget == Some(0) {
            return Ok(None);
        }
        for (side, path, tag) in &files {
            if !path.is_file() {
                let im = source(*side, tag)?;
                write_npy(path, &im)?;
                if opts.previews {
                    let p = layout.preview("", *side, &combo.to_string());
                    write_png(&p, &clamp_u8(&im), PngDepth::Eight)?;
                }
            }
        }
        summary.combinations_written += 1;
        if let Some(b) = budget.as_mut() {
            *b -= 1;
        }
    }
    Ok(Some(combos.len()))
}

/// One side's image of a combination: the real rectified one, or the variant `tag` rectified
/// into the pair's frame.
fn side_image(
    synthetic: Option<&SyntheticLayout>,
    pair: &PairStem,
    inputs: &PairInputs,
    side: Side,
    tag: &Option<String>,
) -> Result<Image> {
    match tag {
        None => real_image(&inputs.pairs, pair, side),
        Some(t) => {
            let s = synthetic.expect("tags come from the synthetic folder");
            let (hl, hr) = inputs.homographies.expect("checked above");
            let h = if side == Side::Left { hl } else { hr };
            rectified_variant(s, pair, side, t, &h, inputs.size)
        }
    }
}

/// The variants the synthesis rejected, `<image id>_<season>`, for the pair's record.
fn rejected_variants(synthetic: Option<&SyntheticLayout>, pair: &PairStem) -> Result<Vec<String>> {
    let Some(s) = synthetic else {
        return Ok(Vec::new());
    };
    let mut out = Vec::new();
    for side in Side::BOTH {
        let id = side_id(pair, side);
        if let Some(r) = s.read_variants(id)? {
            out.extend(
                r.seasons
                    .iter()
                    .filter(|x| !x.passed)
                    .map(|x| format!("{id}_{}", x.season)),
            );
        }
    }
    Ok(out)
}

fn side_id(pair: &PairStem, side: Side) -> &str {
    match side {
        Side::Left => &pair.left.id,
        Side::Right => &pair.right.id,
    }
}

fn clamp_u8(im: &Image) -> Image {
    let mut o = im.clone();
    o.data_mut()
        .iter_mut()
        .for_each(|v| *v = v.clamp(0.0, 255.0).round());
    o
}

/// Warps a raw-frame mask into the rectified frame (bilinear on 0/1, > 0.5: nearest up to the
/// half-pixel border); outside the raw image it is false.
pub fn rectify_mask(mask: &Mask, h: &Homography, size: (usize, usize)) -> Result<Mask> {
    let (warped, inside) = warp_homography(&mask.to_image(), h, size.0, size.1)?;
    let data = warped
        .data()
        .iter()
        .zip(inside.data())
        .map(|(&v, &i)| i && v > 0.5)
        .collect();
    Ok(Mask::new(size.0, size.1, data)?)
}

#[allow(clippy::too_many_arguments)]
fn write_side_masks(
    opts: &BuildOptions,
    layout: &TrainLayout,
    pair: &PairStem,
    side: Side,
    h_crop: Option<Homography>,
    crop: Option<CropRecord>,
    size: (usize, usize),
    missing: &mut Vec<String>,
) -> Result<()> {
    let id = side_id(pair, side);
    // Missing segmentations are recorded even when the masks exist from an earlier run.
    let files = segmentation_files(opts, id, side, missing);
    if MaskKind::ALL
        .iter()
        .all(|&k| layout.mask(k, side, pair).is_file())
    {
        return Ok(());
    }
    let (raw_size, segmentations) = read_segmentations(&files, crop, id)?;
    let footprint = match (raw_size, h_crop) {
        (Some((w, h)), Some(hc)) => rectify_mask(&Mask::filled(w, h, true), &hc, size)?,
        _ => finite_pixels(opts, pair, side, size)?,
    };
    write_mask(opts, layout, pair, side, MaskKind::Valid, &footprint)?;
    for (kind, seg) in segmentations {
        let m = class_mask(pair, kind, seg, h_crop, size, &footprint)?;
        write_mask(opts, layout, pair, side, kind, &m)?;
    }
    Ok(())
}

/// Each class's segmentation of image `id`, when its folder has one; the missing ones are
/// added to `missing` with the folder they were looked for in.
fn segmentation_files(
    opts: &BuildOptions,
    id: &str,
    side: Side,
    missing: &mut Vec<String>,
) -> Vec<(MaskKind, Option<PathBuf>)> {
    [MaskKind::Water, MaskKind::Tree, MaskKind::Building]
        .iter()
        .map(|&k| {
            let f = opts
                .masks
                .dir(k)
                .map(|d| segmentation_path(d, id))
                .filter(|p| p.is_file());
            if f.is_none() {
                let dir = opts.masks.dir(k).map_or_else(
                    || format!("<no {} mask folder>", k.dir()),
                    |d| d.display().to_string(),
                );
                missing.push(format!(
                    "[MISSING_{}_{}] {dir}/{id}_mask.png",
                    k.dir().to_uppercase(),
                    side.dir()
                ));
            }
            (k, f)
        })
        .collect()
}

/// Each class's segmentation, when there is one.
type Segmentations = Vec<(MaskKind, Option<Image>)>;

/// Reads the segmentations in the raw frame of image `id`: the crop when synthesize made one
/// (a segmentation of the whole raw image is cropped like the image), else the segmentations'
/// own size, which must agree. Returns the raw frame's size, if known, and each class's
/// segmentation.
fn read_segmentations(
    files: &[(MaskKind, Option<PathBuf>)],
    crop: Option<CropRecord>,
    id: &str,
) -> Result<(Option<(usize, usize)>, Segmentations)> {
    let mut raw_size = crop.map(|c| (c.width, c.height));
    let mut segmentations = Vec::new();
    for (k, f) in files {
        let Some(p) = f else {
            segmentations.push((*k, None));
            continue;
        };
        let mut im = raster::read_image(p)?;
        if let Some(c) = crop {
            if im.size() == (c.source_width, c.source_height) && im.size() != (c.width, c.height) {
                im = raster::geometry::crop(&im, c.x0, c.y0, c.width, c.height)?;
            }
        }
        match raw_size {
            Some(s) if s != im.size() => bail!(
                "mask/source size mismatch: {} is {}x{}, image {id} is {}x{} (segment the crops of `synthesize`, OUT/cropped/, or the whole raw image)",
                p.display(), im.width(), im.height(), s.0, s.1
            ),
            None => raw_size = Some(im.size()),
            _ => {}
        }
        segmentations.push((*k, Some(im)));
    }
    Ok((raw_size, segmentations))
}

/// The footprint when no raw frame is known: the finite pixels of the rectified real image.
fn finite_pixels(
    opts: &BuildOptions,
    pair: &PairStem,
    side: Side,
    size: (usize, usize),
) -> Result<Mask> {
    let p = PairFolder::new(&opts.pairs_dir)
        .image(side, &pair.base_name())?
        .context("real image vanished")?;
    let im = raster::read_image(&p)?;
    let c = im.channels();
    let data = im
        .data()
        .chunks(c)
        .map(|px| px.iter().all(|v| v.is_finite()))
        .collect();
    Ok(Mask::new(size.0, size.1, data)?)
}

/// One class's mask in the rectified frame: its segmentation rectified (or, without a
/// homography, taken as it is when it already has the frame's size), else the release's
/// default (keep everything inside the footprint, no building).
fn class_mask(
    pair: &PairStem,
    kind: MaskKind,
    seg: Option<Image>,
    h_crop: Option<Homography>,
    size: (usize, usize),
    footprint: &Mask,
) -> Result<Mask> {
    let polarity = if kind == MaskKind::Building {
        MaskFile::Building
    } else {
        MaskFile::Keep
    };
    Ok(match (seg, h_crop) {
        (Some(im), Some(hc)) => rectify_mask(&from_segmentation(&im, polarity), &hc, size)?,
        (Some(im), None) if im.size() == size => from_segmentation(&im, polarity).and(footprint)?,
        (Some(_), None) => bail!(
            "pair {pair} has no homography to rectify its {} mask",
            kind.dir()
        ),
        (None, _) if polarity == MaskFile::Keep => footprint.clone(),
        (None, _) => Mask::filled(size.0, size.1, false),
    })
}

/// Writes one mask of a side, with its preview when asked.
fn write_mask(
    opts: &BuildOptions,
    layout: &TrainLayout,
    pair: &PairStem,
    side: Side,
    kind: MaskKind,
    m: &Mask,
) -> Result<()> {
    write_mask_npy(&layout.mask(kind, side, pair), m)?;
    if opts.previews {
        let mut pic = m.to_image();
        pic.data_mut().iter_mut().for_each(|v| *v *= 255.0);
        write_png(
            layout.preview(kind.dir(), side, &pair.base_name()),
            &pic,
            PngDepth::Eight,
        )?;
    }
    Ok(())
}

/// Copies a disparity into the set (skipped when present), checking its size.
fn copy_disparity(src: &Path, dst: &Path, size: (usize, usize), hint: &str) -> Result<()> {
    if dst.is_file() {
        return Ok(());
    }
    if !src.is_file() {
        bail!("{} is missing ({hint})", src.display());
    }
    let d = raster::read_image(src)?;
    if d.size() != size || d.channels() != 1 {
        bail!(
            "{} is {}x{}x{} but the pair is {}x{} (one channel expected)",
            src.display(),
            d.width(),
            d.height(),
            d.channels(),
            size.0,
            size.1
        );
    }
    write_npy(dst, &d)?;
    Ok(())
}

fn finalize(
    opts: &BuildOptions,
    dir: &DatasetDir,
    layout: &TrainLayout,
    teacher: &str,
    pairs: &[PairStem],
    records: &[PairRecord],
    summary: &mut BuildSummary,
) -> Result<()> {
    let variants: Vec<PairVariants> = records
        .iter()
        .map(|r| {
            Ok(PairVariants {
                pair: PairStem::parse(&r.pair)?,
                left_tags: r.left_tags.clone(),
                right_tags: r.right_tags.clone(),
            })
        })
        .collect::<Result<_, dataset::DatasetError>>()?;
    let lists = build_subsets(&variants, opts.seed);
    let mut split = SplitManifest {
        pairs: pairs.len(),
        combinations: KindCounts::of(&lists[&Subset::All]),
        rejected_variants: records.iter().map(|r| r.rejected.len()).sum(),
        missing_masks: summary.missing_masks,
        teacher_dir: relative(&dir.root, &layout.teacher_dir),
        lidar_dir: layout.lidar_dir.as_ref().map(|d| relative(&dir.root, d)),
        ..Default::default()
    };
    let mut entries: Vec<(String, &str, &[ExperimentRow])> = Vec::new();
    if opts.split == "val" {
        entries.push(("val".into(), VAL_LIST, &lists[&Subset::All]));
    } else {
        for s in Subset::ALL {
            entries.push((s.label().into(), s.csv_name(), &lists[&s]));
        }
    }
    for (label, csv, rows) in entries {
        write_experiment_csv(&dir.experiment_csv(csv), rows)?;
        let counts = KindCounts::of(rows);
        summary.subsets.push((label.clone(), counts.clone()));
        split.subsets.insert(
            label,
            SubsetEntry {
                csv: format!("experiments/{csv}.csv"),
                counts,
            },
        );
    }
    write_aois(&dir.aois_csv(&opts.split), pairs)?;
    let missing: String = records
        .iter()
        .flat_map(|r| r.missing_masks.iter().map(|m| format!("{m}\n")))
        .collect();
    write_text(&layout.root.join("missing_files.txt"), &missing)?;
    let c = &split.combinations;
    write_text(
        &layout.root.join("summary.txt"),
        &format!(
            "split={}\nreference_pairs={}\nreal_pairs_written={}\nsynthetic_pairs_written={}\n\
             synchronic_synthetic={}\ndiachronic={}\nrejected_variants={}\nmissing_masks={}\n",
            opts.split,
            pairs.len(),
            c.real,
            c.synchronic_synthetic + c.diachronic,
            c.synchronic_synthetic,
            c.diachronic,
            split.rejected_variants,
            split.missing_masks
        ),
    )?;
    let generator = match &opts.synthetic_dir {
        Some(d) => crate::synthesize::recorded_generator(d)?.unwrap_or_else(|| "unknown".into()),
        None => "none".into(),
    };
    let mut manifest = Manifest::read_optional(&dir.manifest())?
        .unwrap_or_else(|| Manifest::new(&generator, teacher, &opts.segmenter, opts.seed));
    if opts.split != "val" {
        manifest.generator = generator;
        manifest.teacher = teacher.to_string();
        manifest.segmenter = opts.segmenter.clone();
        manifest.seed = opts.seed;
    }
    manifest.splits.insert(opts.split.clone(), split);
    manifest.write(&dir.manifest())?;
    summary.finalized = true;
    Ok(())
}

fn relative(root: &Path, p: &Path) -> String {
    p.strip_prefix(root)
        .unwrap_or(p)
        .to_string_lossy()
        .into_owned()
}

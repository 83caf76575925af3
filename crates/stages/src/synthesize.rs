//! `synthesize`: seasonal variants of every image of the selected pairs (paper Sec. 3.2, release
//! `preprocessing/synthetic_data_generation/` + the rectification of `dataset_generation.py`).
//!
//! Per image (the work items; resumable, shardable over the sorted image ids):
//! 1. centre crop of the raw image (paper: 1024² of a 2048² tile; images smaller than the crop are
//!    kept whole), written as `cropped/<id>.tif` with its crop record `cropped/<id>.json`;
//! 2. one variant per season from a [`SeasonGenerator`] (class maps as hints when given);
//! 3. the geometry-fidelity check of every variant against the crop ([`synth::fidelity::check`]):
//!    passing variants go to `cropped-synthetic/<id>_<season>.tif` (the release's
//!    `Train-Track3-cropped-synthetic` naming `<stem>_<suffix>`), failing ones to
//!    `rejected/<id>_<season>.tif` and `rejected.csv`, and are never used;
//! 4. `variants/<id>.json`, written last, records the outcome (the item's "finished" marker).
//!
//! Then every pair of the shard whose two images are finished gets its variants rectified with
//! the pair's homographies adapted to the crop (`H ∘ T(x0, y0)`: crop pixel → raw pixel → rectified)
//! into the frame of the rectified real pair: `rectified/<pair>/{L,R}_<season>.npy`. Pairs whose
//! images belong to another shard are rectified by `dataset build` (which does it on demand).

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use dataset::shard::Shard;
use dataset::PairStem;
use raster::formats::{write_geotiff, GeoTiffMeta};
use raster::geometry::centre_crop;
use raster::{Homography, Image};
use serde::{Deserialize, Serialize};
use synth::fidelity::FidelityParams;
use synth::{Season, SeasonGenerator, SourceImage};

use workflow::pairs::PairFolder;
use workflow::progress::Progress;
use workflow::stage::{claim_folder, read_json, run_items, write_json, BatchSummary};

/// Default centre crop, pixels (the paper's 1024² of a 2048² tile).
pub const DEFAULT_CROP: usize = 1024;

/// Extensions of raw images, in order of preference.
pub const RAW_EXTENSIONS: [&str; 6] = ["tif", "tiff", "png", "npy", "iio", "pfm"];

/// Where `synthesize` writes (see the module docs).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SyntheticLayout {
    pub root: PathBuf,
}

impl SyntheticLayout {
    pub fn new(root: impl Into<PathBuf>) -> Self {
        SyntheticLayout { root: root.into() }
    }

    /// The real crop `cropped/<id>.tif` (the input of `masks`).
    pub fn cropped(&self, id: &str) -> PathBuf {
        self.root.join("cropped").join(format!("{id}.tif"))
    }

    /// Where the crop lies in the raw image: `cropped/<id>.json`.
    pub fn crop_record(&self, id: &str) -> PathBuf {
        self.root.join("cropped").join(format!("{id}.json"))
    }

    /// An accepted variant: `cropped-synthetic/<id>_<tag>.tif`.
    pub fn variant(&self, id: &str, tag: &str) -> PathBuf {
        self.root
            .join("cropped-synthetic")
            .join(format!("{id}_{tag}.tif"))
    }

    /// A variant rejected by the fidelity check: `rejected/<id>_<tag>.tif`.
    pub fn rejected_variant(&self, id: &str, tag: &str) -> PathBuf {
        self.root.join("rejected").join(format!("{id}_{tag}.tif"))
    }

    /// The outcome of image `id`: `variants/<id>.json` (written last).
    pub fn variant_record(&self, id: &str) -> PathBuf {
        self.root.join("variants").join(format!("{id}.json"))
    }

    /// Every rejected variant, one line each.
    pub fn rejected_csv(&self) -> PathBuf {
        self.root.join("rejected.csv")
    }

    /// The generator that made the variants.
    pub fn record(&self) -> PathBuf {
        self.root.join("synthesize.json")
    }

    /// The crop record of `id`, `None` when `synthesize` has not cropped it.
    pub fn read_crop(&self, id: &str) -> Result<Option<CropRecord>> {
        read_json(&self.crop_record(id))
    }

    /// The variant record of `id`, `None` when the image is not finished.
    pub fn read_variants(&self, id: &str) -> Result<Option<VariantRecord>> {
        read_json(&self.variant_record(id))
    }
}

/// Where a crop lies in its raw image.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct CropRecord {
    pub source_width: usize,
    pub source_height: usize,
    /// Top-left pixel of the crop in the raw image.
    pub x0: usize,
    pub y0: usize,
    pub width: usize,
    pub height: usize,
}

impl CropRecord {
    /// The crop of a `w × h` image to at most `crop × crop`, centred as
    /// [`raster::geometry::centre_crop`] does.
    pub fn centred(w: usize, h: usize, crop: usize) -> Self {
        let (x0, y0, width, height) = raster::geometry::centre_window(w, h, crop, crop);
        CropRecord {
            source_width: w,
            source_height: h,
            x0,
            y0,
            width,
            height,
        }
    }

    /// A raw → rectified homography of the full image adapted to the crop: crop pixel → raw pixel
    /// → rectified (the release's `H_full @ T(cx, cy)`).
    pub fn adapt(&self, h: &Homography) -> Homography {
        h.compose(&Homography::translation(self.x0 as f64, self.y0 as f64))
    }
}

/// One season's outcome.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SeasonOutcome {
    pub season: String,
    pub passed: bool,
    /// The fidelity check's measurements, as text.
    pub report: String,
}

/// The outcome of one image (`variants/<id>.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct VariantRecord {
    pub id: String,
    pub generator: String,
    pub seasons: Vec<SeasonOutcome>,
}

impl VariantRecord {
    /// Tags of the variants that passed the fidelity check.
    pub fn passed(&self) -> Vec<String> {
        self.seasons
            .iter()
            .filter(|s| s.passed)
            .map(|s| s.season.clone())
            .collect()
    }
}

/// What `synthesize` does.
#[derive(Clone, Debug)]
pub struct SynthesizeOptions {
    /// Synchronic pairs: `L/`, `R/` (rectified) and `homography/<pair>.npz`.
    pub pairs_dir: PathBuf,
    /// Raw images `<id>.{tif,png,npy,iio,…}`, searched recursively (the release's
    /// `Track3-RGB-*/<AOI>/` folders work as they are).
    pub raw_dir: PathBuf,
    /// Optional class maps `<id>.png` (OpenEarthMap ids) in the raw frame, handed to the generator.
    pub classes_dir: Option<PathBuf>,
    /// Selected pairs (curate's `selected.txt`/`.csv`); `None` = every pair of `pairs_dir`.
    pub selected: Option<PathBuf>,
    pub out_dir: PathBuf,
    /// Centre crop side, pixels.
    pub crop: usize,
    pub seasons: Vec<Season>,
    pub fidelity: FidelityParams,
    pub shard: Shard,
}

impl SynthesizeOptions {
    pub fn new(pairs_dir: &Path, raw_dir: &Path, out_dir: &Path) -> Self {
        SynthesizeOptions {
            pairs_dir: pairs_dir.to_path_buf(),
            raw_dir: raw_dir.to_path_buf(),
            classes_dir: None,
            selected: None,
            out_dir: out_dir.to_path_buf(),
            crop: DEFAULT_CROP,
            seasons: Season::ALL.to_vec(),
            fidelity: FidelityParams::default(),
            shard: Shard::ALL,
        }
    }
}

/// What `synthesize` did.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct SynthesizeSummary {
    /// Images of the selected pairs.
    pub images: BatchSummary,
    /// Variants accepted / rejected in this run.
    pub accepted: usize,
    pub rejected: usize,
}

/// The selected pairs: from the list, or every pair of `pairs_dir`; sorted.
pub fn selected_pairs(pairs_dir: &Path, selected: Option<&Path>) -> Result<Vec<PairStem>> {
    let all: Vec<PairStem> = PairFolder::new(pairs_dir)
        .list()?
        .into_iter()
        .map(|p| PairStem::parse(&p.stem))
        .collect::<Result<_, _>>()?;
    let mut out = match selected {
        None => all,
        Some(list) => {
            let known: BTreeSet<&PairStem> = all.iter().collect();
            let chosen = dataset::experiment::read_pair_list(list)?;
            for s in &chosen {
                if !known.contains(s) {
                    bail!(
                        "{} selects pair {s}, which is not in {}/L",
                        list.display(),
                        pairs_dir.display()
                    );
                }
            }
            chosen
        }
    };
    out.sort();
    if out.is_empty() {
        bail!("no pair selected in {}", pairs_dir.display());
    }
    Ok(out)
}

/// Index of the files under `dir` (recursively) with one of `exts`, by file stem. Two files with
/// the same stem are refused.
pub fn index_files(dir: &Path, exts: &[&str]) -> Result<HashMap<String, PathBuf>> {
    let mut out: HashMap<String, PathBuf> = HashMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let entries =
            std::fs::read_dir(&d).with_context(|| format!("cannot list {}", d.display()))?;
        for e in entries {
            let p = e?.path();
            if p.is_dir() {
                stack.push(p);
                continue;
            }
            let ext = raster::formats::extension_of(&p);
            let Some(stem) = p.file_stem().and_then(|s| s.to_str()) else {
                continue;
            };
            if stem.starts_with('.') || !exts.contains(&ext.as_str()) {
                continue;
            }
            if let Some(old) = out.insert(stem.to_string(), p.clone()) {
                bail!(
                    "{} and {} have the same image id: keep one",
                    old.display(),
                    p.display()
                );
            }
        }
    }
    Ok(out)
}

/// Replaces non-finite values by 0 (the black border of rectified training images).
pub fn zero_invalid(image: &mut Image) {
    for v in image.data_mut() {
        if !v.is_finite() {
            *v = 0.0;
        }
    }
}

/// Runs `synthesize` (see the module docs) with `generator`.
pub fn run_synthesize(
    opts: &SynthesizeOptions,
    generator: &dyn SeasonGenerator,
    progress: &dyn Progress,
) -> Result<SynthesizeSummary> {
    if opts.crop == 0 {
        bail!("the crop size must be positive");
    }
    if opts.seasons.is_empty() {
        bail!("no season to generate");
    }
    let layout = SyntheticLayout::new(&opts.out_dir);
    claim_generator(&layout, &generator.name())?;
    let pairs = selected_pairs(&opts.pairs_dir, opts.selected.as_deref())?;
    let ids: Vec<String> = pairs
        .iter()
        .flat_map(|p| [p.left.id.clone(), p.right.id.clone()])
        .collect::<BTreeSet<_>>()
        .into_iter()
        .collect();
    let raw = index_files(&opts.raw_dir, &RAW_EXTENSIONS)?;
    let classes = match &opts.classes_dir {
        Some(d) => index_files(d, &["png", "tif", "tiff", "npy", "iio"])?,
        None => HashMap::new(),
    };
    let mut summary = SynthesizeSummary::default();
    let (mut accepted, mut rejected) = (0, 0);
    summary.images = run_items(
        &ids,
        &opts.shard,
        "seasonal variants",
        progress,
        |id| layout.variant_record(id).is_file(),
        |id| {
            let record = synthesize_image(opts, &layout, generator, id, &raw, &classes)?;
            let ok = record.passed().len();
            accepted += ok;
            rejected += record.seasons.len() - ok;
            Ok(())
        },
        |id| id.clone(),
    )?;
    summary.accepted = accepted;
    summary.rejected = rejected;
    write_rejected_csv(&layout, &ids)?;

    Ok(summary)
}

/// `synthesize.json`: the generator that made a folder's variants.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct GeneratorRecord {
    pub generator: String,
}

/// Records the generator in `synthesize.json`; a folder made by another generator is refused so
/// variants are never mixed.
fn claim_generator(layout: &SyntheticLayout, name: &str) -> Result<()> {
    let record = GeneratorRecord {
        generator: name.to_string(),
    };
    claim_folder(&layout.record(), &record, |old| {
        format!(
            "{} holds variants of generator {} (not {name}): use another output folder",
            layout.root.display(),
            old.generator
        )
    })
}

/// The generator recorded in a synthesize folder.
pub fn recorded_generator(dir: &Path) -> Result<Option<String>> {
    let record: Option<GeneratorRecord> = read_json(&SyntheticLayout::new(dir).record())?;
    Ok(record.map(|r| r.generator))
}

fn synthesize_image(
    opts: &SynthesizeOptions,
    layout: &SyntheticLayout,
    generator: &dyn SeasonGenerator,
    id: &str,
    raw: &HashMap<String, PathBuf>,
    classes: &HashMap<String, PathBuf>,
) -> Result<VariantRecord> {
    let path = raw.get(id).with_context(|| {
        format!(
            "no raw image {id}.{{{}}} under {}",
            RAW_EXTENSIONS.join(","),
            opts.raw_dir.display()
        )
    })?;
    let image = raster::read_image(path)?.to_rgb();
    let crop = CropRecord::centred(image.width(), image.height(), opts.crop);
    let (cropped, _) = centre_crop(&image, crop.width, crop.height)?;
    let class_crop = match classes.get(id) {
        Some(p) => {
            // A class map of the raw image (cropped here) or of the crop (`masks` on OUT/cropped).
            let c = raster::read_image(p)?.channel(0);
            if c.size() == (crop.width, crop.height) {
                Some(c)
            } else if c.size() == image.size() {
                Some(centre_crop(&c, crop.width, crop.height)?.0)
            } else {
                bail!(
                    "class map {} is {}x{} but image {} is {}x{} (crop {}x{})",
                    p.display(),
                    c.width(),
                    c.height(),
                    path.display(),
                    image.width(),
                    image.height(),
                    crop.width,
                    crop.height
                );
            }
        }
        None => None,
    };
    if !layout.cropped(id).is_file() {
        write_geotiff(layout.cropped(id), &cropped, &GeoTiffMeta::default())?;
    }
    write_json(&layout.crop_record(id), &crop)?;
    let mut source = SourceImage::new(id, &cropped);
    if let Some(c) = &class_crop {
        source = source.with_classes(c);
    }
    let mut seasons = Vec::new();
    for &season in &opts.seasons {
        let tag = season.tag();
        let (ok_path, bad_path) = (layout.variant(id, tag), layout.rejected_variant(id, tag));
        // A variant written by an interrupted run is checked again, not regenerated.
        let variant = if ok_path.is_file() {
            raster::read_image(&ok_path)?
        } else if bad_path.is_file() {
            raster::read_image(&bad_path)?
        } else {
            generator
                .generate(&source, season)
                .with_context(|| format!("generating {tag} for {id}"))?
        };
        let report = synth::fidelity::check(&cropped, &variant, &opts.fidelity)
            .with_context(|| format!("fidelity check of {id} {tag}"))?;
        let passed = report.passed;
        let (keep, drop) = if passed {
            (ok_path, bad_path)
        } else {
            (bad_path, ok_path)
        };
        if !keep.is_file() {
            write_geotiff(&keep, &variant, &GeoTiffMeta::default())?;
        }
        if drop.is_file() {
            std::fs::remove_file(&drop).with_context(|| format!("removing {}", drop.display()))?;
        }
        seasons.push(SeasonOutcome {
            season: tag.to_string(),
            passed,
            report: report.to_string(),
        });
    }
    let record = VariantRecord {
        id: id.to_string(),
        generator: generator.name(),
        seasons,
    };
    write_json(&layout.variant_record(id), &record)?;
    Ok(record)
}

/// Rewrites `rejected.csv` from the finished images' records.
fn write_rejected_csv(layout: &SyntheticLayout, ids: &[String]) -> Result<()> {
    let mut text = String::from("id,season,report\n");
    for id in ids {
        if let Some(r) = layout.read_variants(id)? {
            for s in r.seasons.iter().filter(|s| !s.passed) {
                text += &format!("{id},{},\"{}\"\n", s.season, s.report.replace('"', "'"));
            }
        }
    }
    raster::formats::write_atomically(layout.rejected_csv(), |w| {
        use std::io::Write;
        w.write_all(text.as_bytes())
    })?;
    Ok(())
}

/// Accepted tags of each side of `pair` (`"L"`, `"R"`), from the finished images' records.
pub fn accepted_tags(
    layout: &SyntheticLayout,
    pair: &PairStem,
) -> Result<BTreeMap<&'static str, Vec<String>>> {
    let tags = |id: &str| -> Result<Vec<String>> {
        Ok(layout
            .read_variants(id)?
            .map(|r| r.passed())
            .unwrap_or_default())
    };
    Ok(BTreeMap::from([
        ("L", tags(&pair.left.id)?),
        ("R", tags(&pair.right.id)?),
    ]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crop_records_adapt_homographies() {
        let c = CropRecord::centred(2048, 2048, 1024);
        assert_eq!((c.x0, c.y0, c.width, c.height), (512, 512, 1024, 1024));
        let small = CropRecord::centred(300, 200, 1024);
        assert_eq!(
            (small.x0, small.y0, small.width, small.height),
            (0, 0, 300, 200)
        );
        // Crop pixel (0, 0) is raw pixel (512, 512); through H = translation(3, -2).
        let h = c.adapt(&Homography::translation(3.0, -2.0));
        assert_eq!(h.apply(0.0, 0.0), (515.0, 510.0));
    }
}

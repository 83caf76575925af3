//! The synchronic-pair layout every data stage reads: `<root>/L/<stem>.{iio,npy}` and
//! `<root>/R/<stem>.{iio,npy}` (rectified images, NPY float32 HWC), as in the public release's
//! `synchronic_only/` folder and the training layout. Optional companions: `homography/<stem>.npz`
//! and, for pairs rectified by `seasonstereo rectify`, `rectify/<stem>.json` (disparity range).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};

/// Extensions of rectified images, in order of preference.
pub const IMAGE_EXTENSIONS: [&str; 2] = ["iio", "npy"];

/// The two images of one rectified pair.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SynchronicPair {
    pub stem: String,
    pub left: PathBuf,
    pub right: PathBuf,
}

/// Lists the pairs under `root`, sorted by stem (the order shards partition). Every `L/<stem>`
/// needs its `R/<stem>`; a stem present as both `.iio` and `.npy` is ambiguous and refused.
pub fn list_pairs(root: &Path) -> Result<Vec<SynchronicPair>> {
    let left_dir = root.join("L");
    let stems = image_stems(&left_dir).with_context(|| {
        format!(
            "{} is not a pair folder: expected L/<stem>.iio and R/<stem>.iio inside",
            root.display()
        )
    })?;
    let mut pairs = Vec::with_capacity(stems.len());
    for (stem, left) in stems {
        let right = find_image(&root.join("R"), &stem)?.with_context(|| {
            format!(
                "pair {stem}: {} has no right image R/{stem}.iio (or .npy) in {}",
                left.display(),
                root.display()
            )
        })?;
        pairs.push(SynchronicPair { stem, left, right });
    }
    Ok(pairs)
}

/// The image `<dir>/<stem>.{iio,npy}`, `None` when absent, an error when both exist.
pub fn find_image(dir: &Path, stem: &str) -> Result<Option<PathBuf>> {
    let found: Vec<PathBuf> = IMAGE_EXTENSIONS
        .iter()
        .map(|e| dir.join(format!("{stem}.{e}")))
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

/// `(stem, path)` of every `.iio`/`.npy` file in `dir`, sorted by stem; hidden and temporary
/// files are ignored.
pub fn image_stems(dir: &Path) -> Result<Vec<(String, PathBuf)>> {
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

/// The disparity range written by `seasonstereo rectify` for this pair
/// (`<root>/rectify/<stem>.json`, key `disparity_range`), when present.
pub fn rectify_range(root: &Path, stem: &str) -> Result<Option<(i32, i32)>> {
    let path = root.join("rectify").join(format!("{stem}.json"));
    if !path.is_file() {
        return Ok(None);
    }
    let text =
        std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    let v: serde_json::Value = serde_json::from_str(&text)
        .with_context(|| format!("{} is not valid JSON", path.display()))?;
    let r = v.get("disparity_range").and_then(|r| r.as_array());
    match r.map(|r| r.iter().map(|x| x.as_i64()).collect::<Vec<_>>()) {
        Some(r) if r.len() == 2 && r.iter().all(Option::is_some) => {
            let (lo, hi) = (r[0].unwrap_or(0), r[1].unwrap_or(0));
            if lo > hi {
                bail!(
                    "{}: disparity_range [{lo}, {hi}] is reversed",
                    path.display()
                );
            }
            Ok(Some((lo as i32, hi as i32)))
        }
        _ => bail!(
            "{}: expected \"disparity_range\": [MIN, MAX] (integers)",
            path.display()
        ),
    }
}

//! Where the evaluation finds its inputs: the test splits' pair folders, the cameras and the
//! ground truth.
//!
//! Assumptions (the public release's exact folder names are not available here, so every root
//! is given on the command line):
//!
//! ```text
//! <SPLIT_DIR>/L/<stem>.iio            rectified left image, NPY float32 (H, W, C)
//! <SPLIT_DIR>/R/<stem>.iio            rectified right image, same size
//! <SPLIT_DIR>/homography/<stem>.npz   Hleft, Hright: raw → rectified, 3×3
//! <SPLIT_DIR>/disparity/<stem>.iio    optional LiDAR-derived disparity (Omaha > 192 px rule)
//! <RPC_DIR>/<IMAGEID>.json            SatNeRF/rpcm camera of each raw image (`root_dir`)
//! <TRUTH_DIR>/<AOI>_DSM.tif           ground-truth DSM, float32 GeoTIFF in UTM
//! <TRUTH_DIR>/<AOI>_CLS.tif           DFC2019 classes (5 foliage, 9 water); without it nothing
//!                                     is masked (as in the release)
//! <TRUTH_DIR>/<AOI>_WATER.png         optional water mask on the same grid, read only with a
//!                                     _CLS.tif: ZERO = water (the release's convention)
//! ```
//!
//! `<stem>` is `<LEFTID>-<RIGHTID>` ([`PairStem`], split at the first `-`); the pairs of a split are those of its
//! [`PairFolder`] (`L/*.iio` or `.npy`), sorted by stem. The AOI of a pair is the AOI of its left image ([`AoiRule`]).
//! Predictions given as files are looked up as `<PRED_DIR>/<SPLIT>/<stem>.<ext>` when the folder
//! `<PRED_DIR>/<SPLIT>` exists, else `<PRED_DIR>/<stem>.<ext>`, with `<ext>` one of `iio`, `npy`,
//! `tif`, `pfm`.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use dataset::PairStem;

use workflow::pairs::PairFolder;

/// The benchmark's splits in Table 1's column order: (key, column title). A split named on the
/// command line is matched to a key after lower-casing and mapping ` `/`-` to `_`, with the
/// aliases of [`canonical_split`].
pub const TABLE_SPLITS: [(&str, &str); 4] = [
    ("jacksonville", "Jacksonville"),
    ("buenos_aires", "Buenos Aires"),
    ("omaha_synchronic", "Omaha Synch."),
    ("omaha_diachronic", "Omaha Diach."),
];

/// The Table 1 key of a split name (`"Jacksonville"`, `"jax"`, `"omaha-sync"`, …), or `None`
/// for a split of the user's own.
pub fn canonical_split(name: &str) -> Option<&'static str> {
    let n = name
        .trim()
        .to_ascii_lowercase()
        .replace('.', "")
        .replace([' ', '-'], "_");
    let key = match n.as_str() {
        "jacksonville" | "jax" => "jacksonville",
        "buenos_aires" | "buenosaires" | "ba" | "iarpa" => "buenos_aires",
        "omaha_synchronic" | "omaha_synch" | "omaha_sync" | "oma_sync" | "omaha_s" => {
            "omaha_synchronic"
        }
        "omaha_diachronic" | "omaha_diach" | "omaha_dia" | "oma_dia" | "omaha_d" => {
            "omaha_diachronic"
        }
        _ => return None,
    };
    Some(key)
}

/// True for the Omaha splits, where pairs whose ground-truth disparity exceeds the limit are
/// dropped: a Table 1 Omaha split, or any split whose name contains "omaha".
pub fn is_omaha_split(name: &str) -> bool {
    canonical_split(name).is_some_and(|k| k.starts_with("omaha"))
        || name.to_ascii_lowercase().contains("omaha")
}

/// How the AOI (the ground-truth tile) of an image id is found.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum AoiRule {
    /// The first `n` `_`-separated fields: with `n = 2`, `JAX_068_001_RGB` → `JAX_068` (the
    /// DFC2019 / IARPA naming). An id with `n` fields or fewer loses its last field (`W1_A` →
    /// `W1`); an id without `_` is its own AOI.
    Fields(usize),
    /// Every pair belongs to this AOI.
    Fixed(String),
}

impl Default for AoiRule {
    fn default() -> Self {
        AoiRule::Fields(2)
    }
}

impl AoiRule {
    /// The AOI of an image id.
    pub fn aoi_of(&self, image_id: &str) -> String {
        match self {
            AoiRule::Fixed(a) => a.clone(),
            AoiRule::Fields(n) => {
                let fields: Vec<&str> = image_id.split('_').collect();
                let keep = if fields.len() > *n {
                    *n
                } else {
                    fields.len().saturating_sub(1).max(1)
                };
                fields[..keep.max(1)].join("_")
            }
        }
    }
}

/// A test split: its Table 1 name and its pair folder.
#[derive(Clone, Debug, PartialEq)]
pub struct Split {
    pub name: String,
    pub dir: PathBuf,
}

impl Split {
    /// Parses `NAME=DIR`.
    pub fn parse(s: &str) -> Result<Split, String> {
        let (name, dir) = s.split_once('=').ok_or_else(|| {
            format!("expected NAME=DIR, e.g. Jacksonville=data/test/jax, got {s:?}")
        })?;
        if name.trim().is_empty() || dir.is_empty() {
            return Err(format!("expected NAME=DIR with both parts, got {s:?}"));
        }
        Ok(Split {
            name: name.trim().to_string(),
            dir: PathBuf::from(dir),
        })
    }

    /// The stems of the split's pairs, sorted.
    pub fn stems(&self) -> Result<Vec<String>> {
        PairFolder::new(&self.dir)
            .stems()
            .with_context(|| format!("split {:?}", self.name))
    }
}

/// The files of one pair of a split.
#[derive(Clone, Debug, PartialEq)]
pub struct PairFiles {
    pub stem: String,
    pub left_id: String,
    pub right_id: String,
    pub aoi: String,
    pub left: PathBuf,
    pub right: PathBuf,
    pub homography: PathBuf,
    /// The LiDAR-derived disparity, which may be absent.
    pub gt_disparity: PathBuf,
    pub rpc_left: PathBuf,
    pub rpc_right: PathBuf,
    pub truth: TruthFiles,
}

impl PairFiles {
    pub fn new(
        split_dir: &Path,
        stem: &str,
        rpc_dir: &Path,
        truth_dir: &Path,
        rule: &AoiRule,
    ) -> Result<Self> {
        let ids = PairStem::parse(stem)?;
        let (l, r) = (ids.left.id.as_str(), ids.right.id.as_str());
        let aoi = rule.aoi_of(l);
        let files = PairFolder::new(split_dir).pair(stem)?;
        Ok(PairFiles {
            stem: stem.to_string(),
            left_id: l.to_string(),
            right_id: r.to_string(),
            left: files.left,
            right: files.right,
            homography: files.homography,
            gt_disparity: files.disparity,
            rpc_left: rpc_dir.join(format!("{l}.json")),
            rpc_right: rpc_dir.join(format!("{r}.json")),
            truth: TruthFiles::new(truth_dir, &aoi),
            aoi,
        })
    }
}

/// The ground truth of one AOI.
#[derive(Clone, Debug, PartialEq)]
pub struct TruthFiles {
    pub dsm: PathBuf,
    pub cls: PathBuf,
    /// Optional.
    pub water: PathBuf,
}

impl TruthFiles {
    pub fn new(truth_dir: &Path, aoi: &str) -> Self {
        TruthFiles {
            dsm: truth_dir.join(format!("{aoi}_DSM.tif")),
            cls: truth_dir.join(format!("{aoi}_CLS.tif")),
            water: truth_dir.join(format!("{aoi}_WATER.png")),
        }
    }
}

/// Where a predicted disparity of pair `stem` of split `split` is, under `dir` (see the module
/// docs); the error lists the paths tried.
pub fn prediction_path(dir: &Path, split: &str, stem: &str) -> Result<PathBuf> {
    let sub = dir.join(split);
    let base = if sub.is_dir() { sub } else { dir.to_path_buf() };
    let tried: Vec<PathBuf> = ["iio", "npy", "tif", "pfm"]
        .iter()
        .map(|e| base.join(format!("{stem}.{e}")))
        .collect();
    match tried.iter().find(|p| p.is_file()) {
        Some(p) => Ok(p.clone()),
        None => bail!(
            "no predicted disparity for pair {stem}: none of {} exists",
            tried
                .iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn aoi_rule() {
        let r = AoiRule::default();
        assert_eq!(r.aoi_of("JAX_068_001_RGB"), "JAX_068");
        assert_eq!(r.aoi_of("OMA_212_009_RGB"), "OMA_212");
        assert_eq!(r.aoi_of("WORLD_1_A"), "WORLD_1");
        assert_eq!(r.aoi_of("W1_A"), "W1");
        assert_eq!(r.aoi_of("single"), "single");
        assert_eq!(AoiRule::Fields(3).aoi_of("JAX_068_001_RGB"), "JAX_068_001");
        assert_eq!(AoiRule::Fixed("X".into()).aoi_of("JAX_068_001_RGB"), "X");
    }

    #[test]
    fn split_names_and_stems() {
        assert_eq!(canonical_split("Buenos Aires"), Some("buenos_aires"));
        assert_eq!(canonical_split("omaha-sync"), Some("omaha_synchronic"));
        assert_eq!(canonical_split("mine"), None);
        assert!(is_omaha_split("Omaha Diach.") && is_omaha_split("omaha_test"));
        assert!(!is_omaha_split("Jacksonville"));
        assert!(Split::parse("Jacksonville=/d").is_ok() && Split::parse("x").is_err());
    }
}

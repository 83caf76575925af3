//! Where every file of a training set lives (see the crate docs for the tree).

use std::path::{Path, PathBuf};

use crate::stem::PairStem;

/// Extension of the rectified images and masks of a split.
pub const IMAGE_EXT: &str = "npy";
/// Extension of disparities.
pub const DISPARITY_EXT: &str = "iio";
/// Folder under `disparity_maps/` of the LiDAR-derived (or exact) disparities, as in the release.
pub const LIDAR_DIR_NAME: &str = "GT";

/// A view of a pair.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Side {
    Left,
    Right,
}

impl Side {
    pub const BOTH: [Side; 2] = [Side::Left, Side::Right];

    /// `L` or `R`, the folder names of the layout.
    pub fn dir(self) -> &'static str {
        match self {
            Side::Left => "L",
            Side::Right => "R",
        }
    }
}

/// The semantic masks of a pair.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum MaskKind {
    /// Inside the rectified footprint (1 = valid).
    Valid,
    /// KEEP mask: 1 = not water.
    Water,
    /// KEEP mask: 1 = not tree.
    Tree,
    /// 1 = building.
    Building,
}

impl MaskKind {
    pub const ALL: [MaskKind; 4] = [
        MaskKind::Valid,
        MaskKind::Water,
        MaskKind::Tree,
        MaskKind::Building,
    ];

    /// Folder of the mask kind under a split.
    pub fn dir(self) -> &'static str {
        match self {
            MaskKind::Valid => "masks",
            MaskKind::Water => "water_masks",
            MaskKind::Tree => "tree_masks",
            MaskKind::Building => "building_masks",
        }
    }
}

/// One split of a training set (the release's `train/` or `val/`) and the disparities that
/// supervise it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TrainLayout {
    /// The split folder: `L/`, `R/`, `homography/`, `masks/`, …
    pub root: PathBuf,
    /// Teacher disparities `<pair>.iio` of the REAL pairs.
    pub teacher_dir: PathBuf,
    /// LiDAR-derived (or exact) disparities `<pair>.iio`, when the set has them.
    pub lidar_dir: Option<PathBuf>,
}

impl TrainLayout {
    /// A split at `root` supervised by the disparities in `teacher_dir`.
    pub fn new(root: impl Into<PathBuf>, teacher_dir: impl Into<PathBuf>) -> Self {
        TrainLayout {
            root: root.into(),
            teacher_dir: teacher_dir.into(),
            lidar_dir: None,
        }
    }

    /// The same split with LiDAR disparities in `dir`.
    pub fn with_lidar(mut self, dir: impl Into<PathBuf>) -> Self {
        self.lidar_dir = Some(dir.into());
        self
    }

    /// The input image of `stem` on `side` (a real or synthetic view).
    pub fn image(&self, side: Side, stem: &PairStem) -> PathBuf {
        self.image_by_name(side, &stem.to_string())
    }

    /// `L/<name>.npy` or `R/<name>.npy`.
    pub fn image_by_name(&self, side: Side, name: &str) -> PathBuf {
        self.root
            .join(side.dir())
            .join(format!("{name}.{IMAGE_EXT}"))
    }

    /// The REAL image of the pair `stem` derives from.
    pub fn real_image(&self, side: Side, stem: &PairStem) -> PathBuf {
        self.image_by_name(side, &stem.base_name())
    }

    /// Homographies of the base pair.
    pub fn homography(&self, stem: &PairStem) -> PathBuf {
        self.root
            .join("homography")
            .join(format!("{}.npz", stem.base_name()))
    }

    /// A mask of the base pair.
    pub fn mask(&self, kind: MaskKind, side: Side, stem: &PairStem) -> PathBuf {
        self.root
            .join(kind.dir())
            .join(side.dir())
            .join(format!("{}.{IMAGE_EXT}", stem.base_name()))
    }

    /// Preview picture of a mask or image (written with `--preview`).
    pub fn preview(&self, what: &str, side: Side, name: &str) -> PathBuf {
        let mut p = self.root.join("png");
        if !what.is_empty() {
            p = p.join(what);
        }
        p.join(side.dir()).join(format!("{name}.png"))
    }

    /// Teacher disparity of the base pair.
    pub fn teacher(&self, stem: &PairStem) -> PathBuf {
        self.teacher_dir
            .join(format!("{}.{DISPARITY_EXT}", stem.base_name()))
    }

    /// LiDAR disparity of the base pair, when the set has a LiDAR folder.
    pub fn lidar(&self, stem: &PairStem) -> Option<PathBuf> {
        self.lidar_dir
            .as_ref()
            .map(|d| d.join(format!("{}.{DISPARITY_EXT}", stem.base_name())))
    }
}

/// A whole training set folder (the release's `data/diachronic-stereo-synthetic/`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DatasetDir {
    pub root: PathBuf,
}

impl DatasetDir {
    pub fn new(root: impl Into<PathBuf>) -> Self {
        DatasetDir { root: root.into() }
    }

    /// A split folder (`train`, `val`).
    pub fn split_dir(&self, split: &str) -> PathBuf {
        self.root.join(split)
    }

    /// `disparity_maps/<teacher>/` (the release's `monster++`; ours also `sgm`).
    pub fn teacher_dir(&self, teacher: &str) -> PathBuf {
        self.root.join("disparity_maps").join(teacher)
    }

    /// `disparity_maps/GT/`.
    pub fn lidar_dir(&self) -> PathBuf {
        self.root.join("disparity_maps").join(LIDAR_DIR_NAME)
    }

    /// The training split supervised by `teacher`, with the LiDAR folder when it exists.
    pub fn train(&self, teacher: &str) -> TrainLayout {
        let layout = TrainLayout::new(self.split_dir("train"), self.teacher_dir(teacher));
        let lidar = self.lidar_dir();
        if lidar.is_dir() {
            layout.with_lidar(lidar)
        } else {
            layout
        }
    }

    /// The validation split, supervised (and scored) by its own `val/disparity/` ground truth, as
    /// the release's trainer reads it.
    pub fn val(&self) -> TrainLayout {
        let root = self.split_dir("val");
        let truth = root.join("disparity");
        TrainLayout::new(root, truth.clone()).with_lidar(truth)
    }

    /// `experiments/`.
    pub fn experiments_dir(&self) -> PathBuf {
        self.root.join("experiments")
    }

    /// `experiments/<name>.csv`.
    pub fn experiment_csv(&self, name: &str) -> PathBuf {
        self.experiments_dir().join(format!("{name}.csv"))
    }

    /// `manifest.json`.
    pub fn manifest(&self) -> PathBuf {
        self.root.join("manifest.json")
    }

    /// `train_aois.csv` / `val_aois.csv`.
    pub fn aois_csv(&self, split: &str) -> PathBuf {
        self.root.join(format!("{split}_aois.csv"))
    }

    /// True when `dir` looks like a dataset folder (has `train/L`).
    pub fn looks_like(dir: &Path) -> bool {
        dir.join("train").join("L").is_dir()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_follow_the_release() {
        let d = DatasetDir::new("/d");
        let t = d.train("monster++");
        let s = PairStem::parse("A__winter-B").unwrap();
        assert_eq!(
            t.image(Side::Left, &s),
            Path::new("/d/train/L/A__winter-B.npy")
        );
        assert_eq!(
            t.real_image(Side::Right, &s),
            Path::new("/d/train/R/A-B.npy")
        );
        assert_eq!(
            t.mask(MaskKind::Water, Side::Left, &s),
            Path::new("/d/train/water_masks/L/A-B.npy")
        );
        assert_eq!(
            t.teacher(&s),
            Path::new("/d/disparity_maps/monster++/A-B.iio")
        );
        assert_eq!(t.homography(&s), Path::new("/d/train/homography/A-B.npz"));
        assert_eq!(
            d.experiment_csv("sub_val"),
            Path::new("/d/experiments/sub_val.csv")
        );
        assert_eq!(d.val().teacher(&s), Path::new("/d/val/disparity/A-B.iio"));
    }
}

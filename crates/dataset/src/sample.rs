//! Reading training samples: an input pair of any season combination, the REAL synchronic pair it
//! derives from, the disparities that supervise it and the masks of its base pair — exactly the
//! files the release's `StereoDFC` dataset reads.

use std::path::{Path, PathBuf};

use raster::{Image, Mask};

use crate::experiment::{read_experiment_csv, ExperimentRow};
use crate::layout::{MaskKind, Side, TrainLayout};
use crate::masks::read_mask;
use crate::stem::PairStem;
use crate::{DatasetError, Result};

const BUILD_HINT: &str =
    "written by `seasonstereo dataset build` (or `seasonstereo dataset world`)";
const TEACHER_HINT: &str = "teacher disparity of the real pair: run `seasonstereo teacher`, or \
    point the layout's teacher folder at the right disparity_maps/<teacher>";
const LIDAR_HINT: &str = "LiDAR-derived disparity of the real pair (disparity_maps/GT); \
    configuration (a) needs it for every pair";
const MASK_HINT: &str = "mask of the base pair, written by `seasonstereo dataset build` from the \
    `seasonstereo masks` output (the release's defaults when a segmentation is absent)";

/// One training sample.
#[derive(Clone, Debug)]
pub struct Sample {
    /// The input pair (real or synthetic views, any season combination), values as stored (0–255).
    pub input_left: Image,
    pub input_right: Image,
    /// The real synchronic pair the input derives from (the photometric loss's reference).
    pub real_left: Image,
    pub real_right: Image,
    /// Teacher disparity of the real pair (1 channel; NaN where the teacher gave none).
    pub teacher: Image,
    /// LiDAR-derived disparity of the real pair, when the layout has a LiDAR folder.
    pub lidar: Option<Image>,
    /// Rectification footprint ∧ ¬water ∧ ¬tree on the left view. The supervising disparity's own
    /// validity (finite, > 0) is NOT included: see [`Sample::supervision_mask`].
    pub valid_left: Mask,
    /// Buildings on the left view (the photometric loss's region).
    pub building_left: Mask,
    pub stem: PairStem,
    pub diachronic: bool,
}

impl Sample {
    /// `valid_left` ∧ finite ∧ > 0 of the supervising disparity (the teacher, or the LiDAR one when
    /// `lidar` is true and present): the release's `valid` tensor.
    pub fn supervision_mask(&self, lidar: bool) -> Mask {
        let d = match (&self.lidar, lidar) {
            (Some(l), true) => l,
            _ => &self.teacher,
        };
        let mut m = self.valid_left.clone();
        for (v, &x) in m.data_mut().iter_mut().zip(d.data()) {
            *v = *v && x.is_finite() && x > 0.0;
        }
        m
    }
}

fn read_raster(path: &Path, hint: &str) -> Result<Image> {
    if !path.exists() {
        return Err(DatasetError::missing(path, hint));
    }
    Ok(raster::read_image(path)?)
}

/// Reads a disparity: (H, W) or (H, W, 1), as the release's `_to_2d_map`.
fn read_disparity(path: &Path, hint: &str) -> Result<Image> {
    let d = read_raster(path, hint)?;
    if d.channels() != 1 {
        return Err(DatasetError::format(
            path,
            format!("a disparity must have 1 channel, got {}", d.channels()),
        ));
    }
    Ok(d)
}

fn check_size(
    path: &Path,
    got: (usize, usize),
    want: (usize, usize),
    stem: &PairStem,
) -> Result<()> {
    if got != want {
        return Err(DatasetError::format(
            path,
            format!(
                "is {}x{} but the disparity of {stem} is {}x{} (rebuild the pair with `seasonstereo dataset build`)",
                got.0, got.1, want.0, want.1
            ),
        ));
    }
    Ok(())
}

/// Loads the sample `stem` from `layout`. Errors name the missing or mismatched file and the stage
/// that writes it.
pub fn load_sample(layout: &TrainLayout, stem: &PairStem) -> Result<Sample> {
    let teacher_path = layout.teacher(stem);
    let teacher = read_disparity(&teacher_path, TEACHER_HINT)?;
    let size = teacher.size();
    let image = |path: PathBuf, hint: &str| -> Result<Image> {
        let im = read_raster(&path, hint)?;
        check_size(&path, im.size(), size, stem)?;
        Ok(im)
    };
    let input_left = image(layout.image(Side::Left, stem), BUILD_HINT)?;
    let input_right = image(layout.image(Side::Right, stem), BUILD_HINT)?;
    let (real_left, real_right) = if stem.is_real() {
        (input_left.clone(), input_right.clone())
    } else {
        (
            image(layout.real_image(Side::Left, stem), BUILD_HINT)?,
            image(layout.real_image(Side::Right, stem), BUILD_HINT)?,
        )
    };
    let lidar = match layout.lidar(stem) {
        Some(p) => {
            let d = read_disparity(&p, LIDAR_HINT)?;
            check_size(&p, d.size(), size, stem)?;
            Some(d)
        }
        None => None,
    };
    let mask = |kind: MaskKind| -> Result<Mask> {
        let p = layout.mask(kind, Side::Left, stem);
        let m = read_mask(&p, MASK_HINT)?;
        check_size(&p, m.size(), size, stem)?;
        Ok(m)
    };
    let valid_left = mask(MaskKind::Valid)?
        .and(&mask(MaskKind::Water)?)?
        .and(&mask(MaskKind::Tree)?)?;
    let building_left = mask(MaskKind::Building)?;
    Ok(Sample {
        input_left,
        input_right,
        real_left,
        real_right,
        teacher,
        lidar,
        valid_left,
        building_left,
        diachronic: stem.is_diachronic(),
        stem: stem.clone(),
    })
}

/// The samples of one split: from an experiment list or every image of `L/`.
#[derive(Clone, Debug)]
pub struct SampleIndex {
    pub layout: TrainLayout,
    pub rows: Vec<ExperimentRow>,
}

impl SampleIndex {
    /// The samples listed in an experiment CSV.
    pub fn from_experiment(layout: TrainLayout, csv: &Path) -> Result<Self> {
        let rows = read_experiment_csv(csv)?;
        if rows.is_empty() {
            return Err(DatasetError::format(csv, "lists no sample"));
        }
        Ok(SampleIndex { layout, rows })
    }

    /// Every `L/<stem>.npy` of the split, sorted (the release's `build_experiment_csv.py`).
    pub fn from_folder(layout: TrainLayout) -> Result<Self> {
        let dir = layout.root.join(Side::Left.dir());
        let entries = std::fs::read_dir(&dir).map_err(|e| match e.kind() {
            std::io::ErrorKind::NotFound => DatasetError::missing(&dir, BUILD_HINT),
            _ => DatasetError::io(&dir, e),
        })?;
        let mut stems = Vec::new();
        for e in entries {
            let e = e.map_err(|err| DatasetError::io(&dir, err))?;
            let name = e.file_name().to_string_lossy().into_owned();
            if let Some(s) = name.strip_suffix(&format!(".{}", crate::layout::IMAGE_EXT)) {
                if !s.starts_with('.') {
                    stems.push(PairStem::parse(s)?);
                }
            }
        }
        stems.sort();
        if stems.is_empty() {
            return Err(DatasetError::missing(dir.join("*.npy"), BUILD_HINT));
        }
        Ok(SampleIndex {
            layout,
            rows: stems.into_iter().map(ExperimentRow::of).collect(),
        })
    }

    /// Keeps the samples whose AOI is listed (one per line) in `aois_csv`.
    pub fn retain_aois(&mut self, aois_csv: &Path) -> Result<()> {
        let text = std::fs::read_to_string(aois_csv).map_err(|e| DatasetError::io(aois_csv, e))?;
        let aois: std::collections::HashSet<&str> = text
            .lines()
            .map(str::trim)
            .filter(|l| !l.is_empty())
            .collect();
        self.rows.retain(|r| aois.contains(r.stem.aoi()));
        if self.rows.is_empty() {
            return Err(DatasetError::format(
                aois_csv,
                "no sample left after the AOI filter",
            ));
        }
        Ok(())
    }

    pub fn len(&self) -> usize {
        self.rows.len()
    }

    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// The stem of sample `i`.
    pub fn stem(&self, i: usize) -> &PairStem {
        &self.rows[i].stem
    }

    /// Loads sample `i` (its `diachronic` flag from the list when the list has the column).
    pub fn load(&self, i: usize) -> Result<Sample> {
        let row = &self.rows[i];
        let mut s = load_sample(&self.layout, &row.stem)?;
        s.diachronic = row.is_diachronic();
        Ok(s)
    }

    /// Checks that every file of every sample exists (as the release does up front), naming the
    /// first missing one.
    pub fn check_files(&self) -> Result<()> {
        let l = &self.layout;
        for r in &self.rows {
            let s = &r.stem;
            let mut files = vec![
                (l.image(Side::Left, s), BUILD_HINT),
                (l.image(Side::Right, s), BUILD_HINT),
                (l.real_image(Side::Left, s), BUILD_HINT),
                (l.real_image(Side::Right, s), BUILD_HINT),
                (l.teacher(s), TEACHER_HINT),
            ];
            if let Some(p) = l.lidar(s) {
                files.push((p, LIDAR_HINT));
            }
            for k in MaskKind::ALL {
                files.push((l.mask(k, Side::Left, s), MASK_HINT));
            }
            for (p, hint) in files {
                if !p.exists() {
                    return Err(DatasetError::missing(p, hint));
                }
            }
        }
        Ok(())
    }
}

/// The release's evaluation crop: centre crop to `size` (top-left at `(H−size)/2`), then
/// edge-replicate padding up to `size` with the extra pixel at the bottom/right.
pub fn centre_crop_or_pad(image: &Image, size: usize) -> Image {
    let (w, h, c) = (image.width(), image.height(), image.channels());
    let top = h.saturating_sub(size) / 2;
    let left = w.saturating_sub(size) / 2;
    let (ch, cw) = (h.min(size), w.min(size));
    let (pad_t, pad_l) = ((size - ch) / 2, (size - cw) / 2);
    let mut data = Vec::with_capacity(size * size * c);
    for y in 0..size {
        let sy = top + y.saturating_sub(pad_t).min(ch - 1);
        for x in 0..size {
            let sx = left + x.saturating_sub(pad_l).min(cw - 1);
            data.extend_from_slice(image.pixel(sx, sy));
        }
    }
    Image::new(size, size, c, data).expect("sizes match")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crop_and_pad_like_numpy() {
        let im = Image::from_fn(4, 2, |x, y| (10 * y + x) as f32);
        // Crop width 4 → 2 from column 1; pad height 2 → 2 (nothing). Then size 3: crop cols 0..3
        // (left = (4-3)/2 = 0), pad rows: top 0, bottom 1 (edge).
        let out = centre_crop_or_pad(&im, 3);
        assert_eq!(
            out.data(),
            &[0.0, 1.0, 2.0, 10.0, 11.0, 12.0, 10.0, 11.0, 12.0]
        );
        let out = centre_crop_or_pad(&im, 2);
        assert_eq!(out.data(), &[1.0, 2.0, 11.0, 12.0]);
    }
}

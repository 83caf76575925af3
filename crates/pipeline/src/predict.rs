//! Disparity prediction for one rectified pair, and writing it in the format the user asked for.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use matching::SgmParams;
use nn::config::MonsterConfig;
use nn::infer::{MonsterPredictor, Normalisation};
use raster::{colormap, Image};

use crate::progress::{track, Progress};

/// Reads a rectified pair; both images must have the same size.
pub fn read_pair(left: &Path, right: &Path) -> Result<(Image, Image)> {
    let l = raster::read_image(left)
        .with_context(|| format!("reading the left image {}", left.display()))?;
    let r = raster::read_image(right)
        .with_context(|| format!("reading the right image {}", right.display()))?;
    if l.size() != r.size() {
        bail!(
            "the pair is not rectified to one size: {} is {}x{} but {} is {}x{}",
            left.display(),
            l.width(),
            l.height(),
            right.display(),
            r.width(),
            r.height()
        );
    }
    Ok((l, r))
}

/// Matches a pair with census + SGM over `range` (estimated from the images when `None`; prefer a
/// range from the cameras when you have them). Returns the disparity and the range used.
pub fn predict_sgm(
    left: &Image,
    right: &Image,
    range: Option<(i32, i32)>,
    params: &SgmParams,
    progress: &dyn Progress,
) -> Result<(Image, (i32, i32))> {
    let (d_min, d_max) = match range {
        Some(r) => r,
        None => matching::estimate_range(left, right)
            .context("estimating the disparity range (give one with --range)")?,
    };
    let params = SgmParams {
        d_min,
        d_max,
        ..params.clone()
    };
    let total = 5 * left.height();
    let disparity = track(progress, "matching (census + SGM)", total, |cb| {
        matching::match_pair_with_progress(left, right, &params, Some(cb))
    })?;
    Ok((disparity, (d_min, d_max)))
}

/// How to run MonSter++ (`seasonstereo predict --model monsterpp`).
#[derive(Clone, Debug)]
pub struct MonsterOptions {
    /// Weights: an upstream `.pth` state dict or safetensors (upstream key names).
    pub weights: PathBuf,
    /// Preset: `vitl` (the released checkpoints), `vitb`, `vits` or `tiny` (the parity fixture).
    pub preset: String,
    /// Refinement iterations (≥ 7); `None`: the preset's (32, 8 for tiny).
    pub iters: Option<usize>,
    /// Maximum disparity, a multiple of 32; `None`: the preset's (416, 64 for tiny).
    pub max_disp: Option<usize>,
    /// Mapping of the samples to 0–255.
    pub normalisation: Normalisation,
    /// Peak memory of one forward pass, bytes; larger pairs are cut into strips of rows.
    pub memory_budget: u64,
    /// Strip height in rows (forces tiling).
    pub tile_rows: Option<usize>,
    /// Overlap of consecutive strips, rows.
    pub tile_overlap: usize,
    /// `auto`, `cpu`, `wgpu` or `cuda`.
    pub device: String,
}

impl MonsterOptions {
    /// Defaults for `weights` and `preset`.
    pub fn new(weights: impl Into<PathBuf>, preset: &str) -> Self {
        Self {
            weights: weights.into(),
            preset: preset.to_string(),
            iters: None,
            max_disp: None,
            normalisation: Normalisation::AsIs,
            memory_budget: nn::infer::DEFAULT_MEMORY_BUDGET,
            tile_rows: None,
            tile_overlap: nn::infer::DEFAULT_TILE_OVERLAP,
            device: "auto".to_string(),
        }
    }

    /// The network configuration these options describe.
    pub fn config(&self) -> Result<MonsterConfig> {
        let mut config = MonsterConfig::preset(&self.preset)?;
        if let Some(i) = self.iters {
            config.iters = i;
        }
        if let Some(d) = self.max_disp {
            config.max_disp = d;
        }
        config.validate()?;
        Ok(config)
    }

    /// Builds the network and loads the weights.
    pub fn load(&self) -> Result<MonsterPredictor> {
        let config = self.config()?;
        let device = nn::infer::device_by_name(&self.device).map_err(anyhow::Error::msg)?;
        let mut p = MonsterPredictor::load(config, &self.weights, device)?;
        p.normalisation = self.normalisation;
        p.memory_budget = self.memory_budget;
        p.tile_rows = self.tile_rows;
        p.tile_overlap = self.tile_overlap;
        Ok(p)
    }
}

/// Disparity of a rectified pair with MonSter++ (`predictor` from [`MonsterOptions::load`]):
/// NaN where the left image has no data. Large pairs are cut into strips of rows, one progress
/// step each.
pub fn predict_monster(
    predictor: &MonsterPredictor,
    left: &Image,
    right: &Image,
    progress: &dyn Progress,
) -> Result<Image> {
    let strips = predictor.plan(left.width(), left.height())?;
    let c = predictor.config();
    let label = format!(
        "MonSter++ ({}, {} iterations, max disparity {}{})",
        nn::infer::preset_name(c),
        predictor.iters,
        c.max_disp,
        if strips.len() > 1 {
            format!(
                ", {} strips of {} rows",
                strips.len(),
                strips[0].1 - strips[0].0
            )
        } else {
            String::new()
        }
    );
    let d = track(progress, &label, strips.len(), |cb| {
        predictor.predict_with_progress(left, right, &|done, total| cb(done, total))
    })?;
    Ok(d)
}

/// Writes a disparity map; the extension picks the format: `.iio`/`.npy` (NPY float32),
/// `.tif`/`.tiff` (float32 TIFF), `.pfm` keep the values with NaN for invalid pixels; `.png`
/// writes a colour-mapped picture for viewing (turbo, invalid black), not the values.
pub fn write_disparity(path: &Path, disparity: &Image) -> Result<()> {
    let is_png = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("png"));
    if is_png {
        colormap::write_colorized_png(path, disparity, None)?;
    } else {
        raster::write_image(path, disparity)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mismatched_pair_names_both_files() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a.iio"), dir.path().join("b.iio"));
        raster::write_image(&a, &Image::filled(8, 8, 1, 1.0)).unwrap();
        raster::write_image(&b, &Image::filled(8, 9, 1, 1.0)).unwrap();
        let msg = format!("{:#}", read_pair(&a, &b).unwrap_err());
        assert!(
            msg.contains("a.iio") && msg.contains("b.iio") && msg.contains("8x9"),
            "{msg}"
        );
        let missing = format!(
            "{:#}",
            read_pair(&dir.path().join("none.iio"), &b).unwrap_err()
        );
        assert!(missing.contains("none.iio"), "{missing}");
    }

    #[test]
    fn writes_values_or_pictures_by_extension() {
        let dir = tempfile::tempdir().unwrap();
        let d = Image::new(2, 1, 1, vec![3.5, f32::NAN]).unwrap();
        for ext in ["iio", "tif", "pfm"] {
            let p = dir.path().join(format!("d.{ext}"));
            write_disparity(&p, &d).unwrap();
            let back = raster::read_image(&p).unwrap();
            assert_eq!(back.data()[0], 3.5);
            assert!(back.data()[1].is_nan());
        }
        let p = dir.path().join("d.png");
        write_disparity(&p, &d).unwrap();
        let png = raster::read_image(&p).unwrap();
        assert_eq!(png.channels(), 3);
        assert_eq!(
            png.pixel(1, 0),
            &[0.0, 0.0, 0.0],
            "invalid pixels are black"
        );
    }
}

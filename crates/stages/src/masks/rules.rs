//! The offline segmenter for real satellite RGB: a few rules on colour and on the height above
//! the local ground ([`super::heights`]), thresholds set on the DFC2019 JAX_068 development
//! images (BENCHMARKS.md, "Masks on real imagery"):
//!
//! - vegetation: chromatic excess green `(2G − R − B)/(R + G + B)` averaged over 7×7 > 0.025
//!   (canopies are textured; the mean keeps their shadowed leaves);
//! - tree = vegetation ∧ not measured at ground level: measured height > 2 m, or no measured
//!   height at all (stereo misses much of the canopy, and the filled DSM fills those holes
//!   ground-first, so it cannot tell); a missed tree costs the training loss more than a masked
//!   lawn;
//! - building = filled height > 2.5 m ∧ not vegetation;
//! - water (decided first: water can be green) = low ∧ (dark ∧ smooth, or blue): filled height
//!   < 1 m and either mean brightness 15×15 < 0.16 with local std 15×15 < 0.03, or the 7×7 mean
//!   of the blue chroma `(B − R)/(R + G + B)` > 0.25 with mean brightness < 0.3 (clear water
//!   is blue; shadows on WorldView-3 are bluish too, but stay below 0.25 on nearly all of the
//!   JAX_068 pixels, winter 006 included), in components the release's clean-up keeps (none on
//!   the JAX_068 images, which have no water; see BENCHMARKS.md for the procedural world);
//! - classes (OpenEarthMap ids): 5 tree, 8 building, 6 water, 2 rangeland (vegetation at ground
//!   level), 3 developed (the rest).
//!
//! Without heights only the colour rules can run: tree = vegetation, no building and no water
//! (both need heights), and the record says so.

use anyhow::{bail, Result};
use dataset::segmentation::{class_mask, MaskKind, MaskOptions, Segmentation};
use raster::Image;
use world::class;

use super::heights::ImageHeights;
use super::offline::CLASSES;
use super::pixel_features::box_mean;

/// Threshold on the 7×7 mean of chromatic excess green.
pub const VEGETATION_EXG: f64 = 0.025;
/// Measured height above ground of a tree, metres.
pub const TREE_HEIGHT_M: f32 = 2.0;
/// Filled height above ground of a building, metres.
pub const BUILDING_HEIGHT_M: f32 = 2.5;
/// The water rule (BENCHMARKS.md, "Masks on real imagery"): low, and either dark and smooth
/// or blue.
struct WaterRule {
    /// Filled height above ground below which a pixel can be water, metres.
    below_height_m: f32,
    /// Dark and smooth: mean brightness (of R, G, B in 0–1) and local std over 15×15 below these.
    dark_brightness: f64,
    smooth_std: f64,
    /// Blue: 7×7 mean blue chroma above the first, mean brightness below the second.
    blue_chroma: f64,
    blue_brightness: f64,
}

const WATER_RULE: WaterRule = WaterRule {
    below_height_m: 1.0,
    dark_brightness: 0.16,
    smooth_std: 0.03,
    blue_chroma: 0.25,
    blue_brightness: 0.3,
};

impl WaterRule {
    /// Whether a pixel of filled height `filled`, mean brightness `mean`, local std `spread` and
    /// mean blue chroma `blue` is water. Unknown heights (NaN) do not rule water out; green
    /// water is still water.
    fn holds(&self, filled: f32, mean: f64, spread: f64, blue: f64) -> bool {
        let low = filled.is_nan() || filled < self.below_height_m;
        let dark_smooth = mean < self.dark_brightness && spread < self.smooth_std;
        let blue_water = blue > self.blue_chroma && mean < self.blue_brightness;
        low && (dark_smooth || blue_water)
    }
}

/// OpenEarthMap ids of the class map.
const RANGELAND: usize = class::RANGELAND as usize;
const DEVELOPED: usize = class::DEVELOPED as usize;
const TREE: usize = class::TREE as usize;
const WATER: usize = class::WATER as usize;
const BUILDING: usize = class::BUILDING as usize;

/// The class of every pixel of an 8-bit RGB (or grey) image, with or without heights.
pub fn classify(image: &Image, heights: Option<&ImageHeights>) -> Vec<usize> {
    let (w, h) = image.size();
    let c = image.channels();
    let n = w * h;
    let mut exg = Vec::with_capacity(n);
    let mut v = Vec::with_capacity(n);
    let mut blue = Vec::with_capacity(n);
    for p in image.data().chunks_exact(c) {
        let at = |i: usize| (p[i.min(c - 1)] as f64 / 255.0).clamp(0.0, 1.0);
        let (r, g, b) = if c >= 3 {
            (at(0), at(1), at(2))
        } else {
            (at(0), at(0), at(0))
        };
        exg.push((2.0 * g - r - b) / (r + g + b + 1e-3));
        v.push((r + g + b) / 3.0);
        blue.push((b - r) / (r + g + b + 1e-3));
    }
    let exg = box_mean(&exg, w, h, 3);
    let (mean, spread) = match heights {
        Some(_) => {
            let v2: Vec<f64> = v.iter().map(|a| a * a).collect();
            let m = box_mean(&v, w, h, 7);
            let m2 = box_mean(&v2, w, h, 7);
            let s = m
                .iter()
                .zip(&m2)
                .map(|(a, b)| (b - a * a).max(0.0).sqrt())
                .collect();
            (m, s)
        }
        None => (Vec::new(), Vec::new()),
    };
    let blue = match heights {
        Some(_) => box_mean(&blue, w, h, 3),
        None => Vec::new(),
    };
    (0..n)
        .map(|i| {
            let vegetation = exg[i] > VEGETATION_EXG;
            let Some(hg) = heights else {
                return if vegetation { TREE } else { DEVELOPED };
            };
            let measured = hg.measured.data()[i];
            let filled = hg.filled.data()[i];
            if WATER_RULE.holds(filled, mean[i], spread[i], blue[i]) {
                WATER
            } else if vegetation {
                let raised = !measured.is_finite() || measured > TREE_HEIGHT_M;
                if raised {
                    TREE
                } else {
                    RANGELAND
                }
            } else if filled > BUILDING_HEIGHT_M {
                BUILDING
            } else {
                DEVELOPED
            }
        })
        .collect()
}

/// Masks and class map through the release's clean-up ([`class_mask`] on one-hot
/// probabilities: a rule has no softer score to give).
pub fn segment(
    image: &Image,
    heights: Option<&ImageHeights>,
    options: &[MaskOptions; 3],
) -> Result<Segmentation> {
    let (w, h) = image.size();
    if w == 0 || h == 0 {
        bail!("the image is empty");
    }
    if let Some(hg) = heights {
        if hg.measured.size() != (w, h) || hg.filled.size() != (w, h) {
            bail!(
                "heights are {:?} but the image is {w}x{h}",
                hg.measured.size()
            );
        }
    }
    let pred = classify(image, heights);
    let n = w * h;
    let mut probs = vec![0f32; CLASSES * n];
    for (i, &k) in pred.iter().enumerate() {
        probs[k * n + i] = 1.0;
    }
    let mask = |i: usize| class_mask(MaskKind::ALL[i], &options[i], &probs, &pred, w, h);
    Ok(Segmentation {
        classes: Image::new(w, h, 1, pred.iter().map(|&c| c as f32).collect())?,
        water: mask(0)?,
        tree: mask(1)?,
        building: mask(2)?,
    })
}

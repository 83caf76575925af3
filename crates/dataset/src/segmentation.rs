//! From class scores to the three masks of the pipeline, as the release's mask scripts do it:
//! scores resized to the original image size (bilinear, align_corners = False), softmax over the
//! classes, argmax (first index on ties), then per class the raw mask, the clean-up
//! (small-component removal → hole filling → dilation, areas in percent of the image) and the
//! files' values (keep-mask PNG, probability PNG, percentage line).
//!
//! Plain CPU code shared by every segmenter (SegFormer's logits in `nn`, the offline rules in
//! `pipeline`), so it lives here and not beside a network.

use raster::morphology::{area_from_percent, dilate_square, fill_holes, remove_small_components};
use raster::{Image, Mask};

use crate::{DatasetError, Result};

/// The OpenEarthMap classes, in the order of the release's SegFormer head.
pub const OPENEARTHMAP_LABELS: [&str; 9] = [
    "Background",
    "Bareland",
    "Grass",
    "Pavement",
    "Road",
    "Tree",
    "Water",
    "Cropland",
    "Building",
];

/// The three masks the pipeline needs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum MaskKind {
    /// Water (OpenEarthMap 6); PNG 0 = water, 255 = other.
    Water,
    /// Tree (OpenEarthMap 5); PNG 0 = tree, 1 = other.
    Tree,
    /// Building (OpenEarthMap 8); PNG 0 = building, 1 = other.
    Building,
}

impl MaskKind {
    /// Water, tree, building.
    pub const ALL: [MaskKind; 3] = [MaskKind::Water, MaskKind::Tree, MaskKind::Building];

    /// `water` / `tree` / `building` (file names, percentage headers).
    pub fn name(self) -> &'static str {
        match self {
            MaskKind::Water => "water",
            MaskKind::Tree => "tree",
            MaskKind::Building => "building",
        }
    }

    /// The first class id whose label contains the name (case-insensitive), as the reference
    /// scripts find it: 6, 5, 8 for OpenEarthMap.
    pub fn class_id(self, labels: &[&str]) -> Option<usize> {
        labels
            .iter()
            .position(|l| l.to_lowercase().contains(self.name()))
    }

    /// PNG value of the pixels NOT in the class (the class itself is always 0).
    pub fn png_other_value(self) -> f32 {
        match self {
            MaskKind::Water => 255.0,
            MaskKind::Tree | MaskKind::Building => 1.0,
        }
    }
}

/// Per-class options of the reference scripts (their command-line flags).
#[derive(Debug, Clone, PartialEq)]
pub struct MaskOptions {
    /// Class id in the logits.
    pub class_id: usize,
    /// `--threshold`: raw mask = probability ≥ t instead of argmax == class.
    pub threshold: Option<f32>,
    /// Components smaller than this percent of the image are removed (0 = off).
    pub min_component_pct: f64,
    /// Enclosed holes smaller than this percent of the image are filled (0 = off).
    pub fill_hole_pct: f64,
    /// Square dilation radius in pixels (iterations of a 3×3 dilation; 0 = off).
    pub dilation: usize,
}

impl MaskOptions {
    /// The defaults of the release's script for `kind` (OpenEarthMap ids):
    /// water 0.1 % / 0.1 %, tree 0.05 % / off, building off / off with a 3-pixel dilation.
    pub fn defaults(kind: MaskKind) -> Self {
        let class_id = kind
            .class_id(&OPENEARTHMAP_LABELS)
            .expect("OpenEarthMap labels name every mask class");
        let (min_component_pct, fill_hole_pct, dilation) = match kind {
            MaskKind::Water => (0.1, 0.1, 0),
            MaskKind::Tree => (0.05, 0.0, 0),
            MaskKind::Building => (0.0, 0.0, 3),
        };
        Self {
            class_id,
            threshold: None,
            min_component_pct,
            fill_hole_pct,
            dilation,
        }
    }
}

/// One class's result at the original image size.
#[derive(Debug, Clone)]
pub struct ClassMask {
    /// Which mask.
    pub kind: MaskKind,
    /// Before the clean-up (argmax == class, or probability ≥ threshold).
    pub raw: Mask,
    /// After removal, filling and dilation: true = the class.
    pub mask: Mask,
    /// Softmax probability of the class (1 channel, f32).
    pub probability: Image,
}

impl ClassMask {
    /// The values of `masks/<stem>_mask.png`: 0 for the class ("keep" mask), 255 (water) or
    /// 1 (tree, building) elsewhere. 1 channel, to be written as 8-bit grey.
    pub fn png_values(&self) -> Image {
        let other = self.kind.png_other_value();
        let (w, h) = self.mask.size();
        let data = self
            .mask
            .data()
            .iter()
            .map(|&m| if m { 0.0 } else { other })
            .collect();
        Image::new(w, h, 1, data).expect("sizes match")
    }

    /// The values of `probs/<stem>_<class>_prob.png`: `uint8(clip(p·255, 0, 255))`, truncated.
    pub fn probability_u8(&self) -> Image {
        let mut out = self.probability.clone();
        for v in out.data_mut() {
            *v = (*v * 255.0).clamp(0.0, 255.0).trunc();
        }
        out
    }

    /// Pixels of the class in the final mask.
    pub fn pixels(&self) -> usize {
        self.mask.count()
    }

    /// The line of `<class>_percentages.txt`: `<file name> <100·n/total, 6 decimals> <n> <total>`.
    pub fn percentage_line(&self, file_name: &str) -> String {
        let total = self.mask.width() * self.mask.height();
        let n = self.pixels();
        let pct = if total == 0 {
            0.0
        } else {
            100.0 * n as f64 / total as f64
        };
        format!("{file_name} {pct:.6} {n} {total}")
    }
}

/// Header line of `<class>_percentages.txt`.
pub fn percentages_header(kind: MaskKind) -> String {
    let c = kind.name();
    format!("image_name {c}_percentage {c}_pixels total_pixels")
}

/// Everything one image gives, at its original size.
#[derive(Debug, Clone)]
pub struct Segmentation {
    /// Argmax class ids (1 channel, integers in f32).
    pub classes: Image,
    /// Water mask and probability.
    pub water: ClassMask,
    /// Tree mask and probability.
    pub tree: ClassMask,
    /// Building mask and probability.
    pub building: ClassMask,
}

impl Segmentation {
    /// The result for `kind`.
    pub fn get(&self, kind: MaskKind) -> &ClassMask {
        match kind {
            MaskKind::Water => &self.water,
            MaskKind::Tree => &self.tree,
            MaskKind::Building => &self.building,
        }
    }
}

/// Source taps of torch's linear interpolation (align_corners = False) for each output index:
/// (i0, i1, w0, w1), in f32 as torch's CPU `upsample_bilinear2d` computes them.
fn linear_taps(input: usize, output: usize) -> Vec<(usize, usize, f32, f32)> {
    let scale = input as f32 / output as f32;
    (0..output)
        .map(|i| {
            let src = scale * (i as f32 + 0.5) - 0.5;
            let real = if src < 0.0 { 0.0 } else { src };
            let i0 = (real.floor() as usize).min(input - 1);
            let lambda = (real - i0 as f32).clamp(0.0, 1.0);
            let i1 = if i0 + 1 < input { i0 + 1 } else { i0 };
            (i0, i1, 1.0 - lambda, lambda)
        })
        .collect()
}

/// Class-major scores `classes`×h×w → `classes`×height×width, bilinear (align_corners = False),
/// bit-exact with torch's generic CPU kernel: per axis `fma(t0, w0, t1·w1)` (the contraction its
/// compiled kernel performs), the width taps inside, the height taps outside.
pub fn upsample_scores(
    scores: &[f32],
    classes: usize,
    (w, h): (usize, usize),
    (width, height): (usize, usize),
) -> Vec<f32> {
    assert_eq!(
        scores.len(),
        classes * w * h,
        "scores do not fit {classes}x{h}x{w}"
    );
    let xs = linear_taps(w, width);
    let ys = linear_taps(h, height);
    let lerp = |a: f32, wa: f32, b: f32, wb: f32| a.mul_add(wa, b * wb);
    let mut out = vec![0f32; classes * width * height];
    for (plane, dst) in scores
        .chunks_exact(w * h)
        .zip(out.chunks_exact_mut(width * height))
    {
        for (&(y0, y1, wy0, wy1), row) in ys.iter().zip(dst.chunks_exact_mut(width)) {
            let (r0, r1) = (&plane[y0 * w..(y0 + 1) * w], &plane[y1 * w..(y1 + 1) * w]);
            for (&(x0, x1, wx0, wx1), o) in xs.iter().zip(row.iter_mut()) {
                let t0 = lerp(r0[x0], wx0, r0[x1], wx1);
                let t1 = lerp(r1[x0], wx0, r1[x1], wx1);
                *o = lerp(t0, wy0, t1, wy1);
            }
        }
    }
    out
}

/// Softmax over the classes of class-major scores (`classes` planes of `pixels` values), in f32.
pub fn softmax_classes(scores: &[f32], classes: usize) -> Vec<f32> {
    let n = scores.len() / classes;
    let mut out = vec![0f32; scores.len()];
    let mut e = vec![0f32; classes];
    for i in 0..n {
        let max = (0..classes)
            .map(|c| scores[c * n + i])
            .fold(f32::NEG_INFINITY, f32::max);
        let mut sum = 0f32;
        for (c, ec) in e.iter_mut().enumerate() {
            *ec = (scores[c * n + i] - max).exp();
            sum += *ec;
        }
        for (c, ec) in e.iter().enumerate() {
            out[c * n + i] = ec / sum;
        }
    }
    out
}

/// Argmax over the classes (first index on ties) of class-major values.
pub fn argmax_classes(values: &[f32], classes: usize) -> Vec<usize> {
    let n = values.len() / classes;
    (0..n)
        .map(|i| {
            let mut best = 0;
            for c in 1..classes {
                if values[c * n + i] > values[best * n + i] {
                    best = c;
                }
            }
            best
        })
        .collect()
}

/// Removal of small components, filling of small enclosed holes, dilation, with the areas of
/// `options` in percent of the mask's pixels (Python rounding); a zero pixel count skips a step.
pub fn clean_mask(raw: &Mask, options: &MaskOptions) -> Mask {
    let total = raw.width() * raw.height();
    let kept = remove_small_components(raw, area_from_percent(options.min_component_pct, total));
    let filled = fill_holes(&kept, area_from_percent(options.fill_hole_pct, total));
    dilate_square(&filled, options.dilation)
}

/// One class's raw mask, clean mask and probability from the class-major probabilities and the
/// argmax of a `width`×`height` image.
pub fn class_mask(
    kind: MaskKind,
    options: &MaskOptions,
    probs: &[f32],
    pred: &[usize],
    width: usize,
    height: usize,
) -> Result<ClassMask> {
    let n = width * height;
    let classes = probs.len() / n.max(1);
    if options.class_id >= classes {
        return Err(DatasetError::Invalid(format!(
            "{} class id {} is out of range: the model has {classes} classes",
            kind.name(),
            options.class_id
        )));
    }
    let p = &probs[options.class_id * n..(options.class_id + 1) * n];
    let raw_data: Vec<bool> = match options.threshold {
        Some(t) => p.iter().map(|&v| v >= t).collect(),
        None => pred.iter().map(|&c| c == options.class_id).collect(),
    };
    let raw = Mask::new(width, height, raw_data)?;
    let mask = clean_mask(&raw, options);
    Ok(ClassMask {
        kind,
        raw,
        mask,
        probability: Image::new(width, height, 1, p.to_vec())?,
    })
}

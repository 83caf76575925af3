//! Inference with MonSter++ on rectified pairs of any size: [`MonsterPredictor`].
//!
//! ```text
//! let predictor = MonsterPredictor::load(MonsterConfig::vitl(), Path::new("mix_all.pth"), Device::flex())?;
//! let disparity: raster::Image = predictor.predict(&left, &right)?;   // (H, W, 1), NaN = invalid
//! ```
//!
//! What `predict` does, in order:
//!
//! 1. **Channels.** Grey (1 channel) is repeated to RGB, grey + alpha (2) keeps the grey, RGB (3)
//!    is used as is, RGBA (4) drops the alpha; more channels are an error.
//! 2. **Values.** The network was trained on 8-bit RGB: samples are used as 0–255 values.
//!    [`Normalisation::AsIs`] (default, fidelity to upstream) passes them through;
//!    satellite products stored as uint16 / reflectances **must be rescaled**, e.g. with
//!    [`Normalisation::Percentile`]`(2.0, 98.0)`, which maps each image's 2nd–98th percentile
//!    (over its finite samples, all channels together) linearly to 0–255 and clips.
//! 3. **Invalid pixels.** Non-finite input samples (NaN outside the raw image after
//!    rectification) are replaced by 0 before the network; the disparity is NaN at every left
//!    pixel that had a non-finite sample.
//! 4. **Padding.** As upstream's `InputPadder(divis_by=32)` ('sintel' mode): replicate padding to
//!    multiples of 32, split `[wd//2, wd − wd//2, ht//2, ht − ht//2]` (left, right, top, bottom);
//!    the output is unpadded the same way.
//! 5. **Memory budget and tiling.** [`estimate_memory_bytes`] gives the peak memory of one
//!    forward pass at a padded size (model weights + activations; see its documentation for the
//!    terms and the calibration). When the whole pair exceeds [`MonsterPredictor::memory_budget`]
//!    (default [`DEFAULT_MEMORY_BUDGET`], 8 GiB), or when [`MonsterPredictor::tile_rows`] is set,
//!    the pair is cut into **horizontal strips of full rows** (epipolar lines are rows, so every
//!    match stays inside its strip), overlapping by [`MonsterPredictor::tile_overlap`] rows
//!    (default 64) and blended with linear ramps over the overlaps. The automatic strip height
//!    is the largest multiple of 32 that fits the budget. When even a 64-row strip of the full
//!    width does not fit, `predict` fails with [`InferError::TooLarge`], which states the
//!    estimate and the budget (crop the pair, or raise the budget).
//!
//! Iterations do not change the memory: in test mode the refinement state is overwritten in
//! place and only the final disparity is upsampled.

use std::path::{Path, PathBuf};

use burn::tensor::{Device, Tensor, TensorData};
use raster::Image;

use crate::config::{ConfigError, EncoderKind, MonsterConfig};
use crate::monster::Monster;
use crate::weights::{file_keys, load_weights, LoadReport, WeightsError};

/// Input sizes must be multiples of this (the 3-D hourglass at 1/4 resolution and REMP's U-Net).
pub const DIVIS_BY: usize = 32;

/// Default memory budget of one forward pass: 8 GiB.
pub const DEFAULT_MEMORY_BUDGET: u64 = 8 << 30;

/// Default overlap of two strips, rows.
pub const DEFAULT_TILE_OVERLAP: usize = 64;

/// Smallest strip height, rows (two 32-row blocks: anything smaller has no vertical context).
pub const MIN_TILE_ROWS: usize = 64;

/// How input samples are mapped to the 0–255 range the network expects.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Normalisation {
    /// Use the samples as they are (8-bit imagery; the upstream behaviour).
    #[default]
    AsIs,
    /// Map each image's `lo`–`hi` percentiles (in %, e.g. 2 and 98) of its finite samples, all
    /// channels together, linearly to 0–255 and clip (uint16 satellite products).
    Percentile(f32, f32),
}

impl Normalisation {
    /// Parses `asis` / `as-is`, or `percentile` (= 2:98), or `percentile:LO:HI`.
    pub fn parse(s: &str) -> Result<Self, String> {
        let t = s.trim().to_ascii_lowercase();
        match t.as_str() {
            "asis" | "as-is" | "none" => return Ok(Self::AsIs),
            "percentile" | "stretch" => return Ok(Self::Percentile(2.0, 98.0)),
            _ => {}
        }
        let rest = t
            .strip_prefix("percentile:")
            .ok_or_else(|| format!("expected as-is, percentile or percentile:LO:HI, got {s:?}"))?;
        let (a, b) = rest
            .split_once(':')
            .ok_or_else(|| format!("expected percentile:LO:HI, e.g. percentile:2:98, got {s:?}"))?;
        let p = |v: &str| v.parse::<f32>().map_err(|e| format!("{v:?} in {s:?}: {e}"));
        let (lo, hi) = (p(a)?, p(b)?);
        if !((0.0..100.0).contains(&lo) && lo < hi && hi <= 100.0) {
            return Err(format!("need 0 ≤ LO < HI ≤ 100 in {s:?}"));
        }
        Ok(Self::Percentile(lo, hi))
    }
}

/// Errors of loading a model or predicting.
#[derive(Debug, thiserror::Error)]
pub enum InferError {
    /// The configuration cannot build a model.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The weights file could not be read (missing, truncated, not a checkpoint).
    #[error("{0}")]
    Weights(WeightsError),
    /// The weights do not fit the configuration: keys missing or mis-shaped.
    #[error(
        "the weights {} do not fit the MonSter++ `{preset}` configuration{hint}\n{listing}",
        file.display()
    )]
    Mismatch {
        /// The weights file.
        file: PathBuf,
        /// The configuration's preset name.
        preset: String,
        /// A guess of the right preset from the file's keys, as a sentence ("" when none).
        hint: String,
        /// The report's listing (truncated to a few keys per kind).
        listing: String,
        /// The full report.
        report: Box<LoadReport>,
    },
    /// The input images are unusable.
    #[error("{0}")]
    Input(String),
    /// Even the smallest strip exceeds the memory budget.
    #[error(
        "a {width}-px wide pair needs about {:.1} GiB for a {MIN_TILE_ROWS}-row strip with the `{preset}` configuration (max disparity {max_disp}), over the memory budget of {:.1} GiB: crop the pair (or lower the max disparity), or raise the budget (--net-memory); --strip-rows ROWS sets the strip height by hand",
        *needed as f64 / GIB, *budget as f64 / GIB
    )]
    TooLarge {
        /// Image width, pixels.
        width: usize,
        /// The configuration's preset name.
        preset: String,
        /// Max disparity of the configuration.
        max_disp: usize,
        /// Estimated bytes of the smallest strip.
        needed: u64,
        /// The budget, bytes.
        budget: u64,
    },
}

const GIB: f64 = (1u64 << 30) as f64;

/// The name of a configuration's preset (`tiny` for the custom fixture configuration).
pub fn preset_name(config: &MonsterConfig) -> &'static str {
    match config.encoder {
        EncoderKind::Vits => "vits",
        EncoderKind::Vitb => "vitb",
        EncoderKind::Vitl => "vitl",
        EncoderKind::Custom => "tiny",
    }
}

/// Peak memory estimate (bytes) of one forward pass of `config` on a `height × width` input
/// (already padded to multiples of 32), plus `weights_bytes` of parameters.
///
/// With h4 = H/4, w4 = W/4, D = max_disp/4, E = ViT width, N = (H/16)(W/16) tokens per view:
///
/// - full-resolution maps (stems, REMP U-Net, context upsampling): `FULLRES` floats per pixel;
/// - the cost volumes at 1/4 resolution (group-wise correlation, 3-D hourglass and its im2col
///   buffers, combined geo encoding volume and its pyramid): `VOLUME` floats per h4·w4·D cell;
/// - the all-pairs correlation along rows at 1/4 resolution (both pyramid levels):
///   1.5·h4·w4·w4 floats (quadratic in the width);
/// - the ViT on both views: 2·N·E·(4 + mlp_ratio) floats per block's working set, plus the
///   attention matrices 2·heads·N² ×3 (scores, softmax, copy).
///
/// The coefficients were calibrated against the peak resident memory measured on the CPU backend
/// (`/usr/bin/time -v` on `crates/nn/examples/forward.rs`): vits at 256×512, max_disp 416, 12 or
/// 32 iterations, and tiny at 64×128 (BENCHMARKS.md, "MonSter++ forward pass"); the estimate
/// lies well above the measured peak. With a 25 % margin the estimate is deliberately
/// conservative (one calibration size; GPU allocators differ).
pub fn estimate_memory_bytes(
    config: &MonsterConfig,
    height: usize,
    width: usize,
    weights_bytes: u64,
) -> u64 {
    const FULLRES: f64 = 150.0;
    const VOLUME: f64 = 40.0;
    let (h, w) = (height as f64, width as f64);
    let (h4, w4) = (h / 4.0, w / 4.0);
    let d = (config.max_disp / 4) as f64;
    let e = config.vit.embed_dim as f64;
    let n = (h / 16.0).ceil() * (w / 16.0).ceil();
    let heads = config.vit.num_heads as f64;
    let floats = FULLRES * h * w
        + VOLUME * h4 * w4 * d
        + 1.5 * h4 * w4 * w4
        + 2.0 * n * e * (4.0 + config.vit.mlp_ratio) * 3.0
        + 2.0 * heads * n * n * 3.0;
    (1.25 * 4.0 * floats) as u64 + weights_bytes + (128u64 << 20)
}

/// MonSter++ with its weights, ready to predict disparities of rectified pairs.
pub struct MonsterPredictor {
    /// The network.
    pub model: Monster,
    /// Where it runs.
    pub device: Device,
    /// Refinement iterations (≥ 7; upstream evaluates with 32).
    pub iters: usize,
    /// Mapping of the input samples to 0–255.
    pub normalisation: Normalisation,
    /// Peak memory allowed for one forward pass, bytes (see [`estimate_memory_bytes`]).
    pub memory_budget: u64,
    /// Strip height, rows, when set: tile even when the budget would allow the whole pair.
    pub tile_rows: Option<usize>,
    /// Overlap of consecutive strips, rows.
    pub tile_overlap: usize,
}

impl MonsterPredictor {
    /// Builds the network for `config` on `device` and loads `weights` (`.pth` state dict or
    /// safetensors, upstream key names). Iterations start at `config.iters`.
    pub fn load(config: MonsterConfig, weights: &Path, device: Device) -> Result<Self, InferError> {
        config.validate()?;
        if !weights.is_file() {
            return Err(InferError::Weights(WeightsError::Io {
                file: weights.to_path_buf(),
                source: std::io::Error::new(
                    std::io::ErrorKind::NotFound,
                    "no such file (MonSter++ checkpoints: the released `.pth` files, e.g. mix_all.pth for --config vitl)",
                ),
            }));
        }
        let mut model = Monster::new(&config, &device);
        match load_weights(&mut model, weights) {
            Ok(_) => {}
            Err(WeightsError::Mismatch { report }) => {
                let guess = guess_preset(weights);
                let preset = preset_name(&config).to_string();
                let hint = match guess {
                    Some(g) if g != preset => {
                        format!(" (the file looks like a `{g}` checkpoint: try --config {g})")
                    }
                    _ => String::new(),
                };
                return Err(InferError::Mismatch {
                    file: weights.to_path_buf(),
                    preset,
                    hint,
                    listing: short_listing(&report, 12),
                    report,
                });
            }
            Err(e) => return Err(InferError::Weights(e)),
        }
        let iters = config.iters;
        Ok(Self {
            model,
            device,
            iters,
            normalisation: Normalisation::AsIs,
            memory_budget: DEFAULT_MEMORY_BUDGET,
            tile_rows: None,
            tile_overlap: DEFAULT_TILE_OVERLAP,
        })
    }

    /// The network's configuration.
    pub fn config(&self) -> &MonsterConfig {
        self.model.config()
    }

    /// Bytes of the model's parameters.
    pub fn weights_bytes(&self) -> u64 {
        4 * self.model.num_params() as u64
    }

    /// Estimated peak memory of one forward pass on an `width × height` input (padded here).
    pub fn estimate_memory(&self, width: usize, height: usize) -> u64 {
        estimate_memory_bytes(
            self.config(),
            pad_to(height),
            pad_to(width),
            self.weights_bytes(),
        )
    }

    /// The strips `(y0, y1)` a `width × height` pair is cut into (one strip = no tiling).
    pub fn plan(&self, width: usize, height: usize) -> Result<Vec<(usize, usize)>, InferError> {
        let rows = match self.tile_rows {
            Some(r) => r.max(1),
            None => {
                if self.estimate_memory(width, height) <= self.memory_budget {
                    height
                } else {
                    let fits = |r: usize| self.estimate_memory(width, r) <= self.memory_budget;
                    if !fits(MIN_TILE_ROWS) {
                        return Err(InferError::TooLarge {
                            width,
                            preset: preset_name(self.config()).to_string(),
                            max_disp: self.config().max_disp,
                            needed: self.estimate_memory(width, MIN_TILE_ROWS),
                            budget: self.memory_budget,
                        });
                    }
                    let mut r = MIN_TILE_ROWS;
                    while r + DIVIS_BY < height && fits(r + DIVIS_BY) {
                        r += DIVIS_BY;
                    }
                    r
                }
            }
        };
        Ok(plan_strips(height, rows, self.tile_overlap))
    }

    /// Disparity of a rectified pair on the left view, `(H, W, 1)`, NaN where the left image
    /// had non-finite samples. See the module documentation for the pre-processing.
    pub fn predict(&self, left: &Image, right: &Image) -> Result<Image, InferError> {
        self.predict_with_progress(left, right, &|_, _| {})
    }

    /// [`predict`](Self::predict), calling `progress(done, total)` after each strip.
    pub fn predict_with_progress(
        &self,
        left: &Image,
        right: &Image,
        progress: &dyn Fn(usize, usize),
    ) -> Result<Image, InferError> {
        if left.size() != right.size() {
            return Err(InferError::Input(format!(
                "the left image is {}x{} but the right one {}x{}",
                left.width(),
                left.height(),
                right.width(),
                right.height()
            )));
        }
        let (w, h) = left.size();
        if w == 0 || h == 0 {
            return Err(InferError::Input("the images are empty".into()));
        }
        if self.iters < 7 {
            return Err(InferError::Input(format!(
                "iters ({}) must be at least 7 (the last 7 iterations are the dual-branch refinement)",
                self.iters
            )));
        }
        let (l, invalid) = prepare(left, self.normalisation, "left")?;
        let (r, _) = prepare(right, self.normalisation, "right")?;
        let strips = self.plan(w, h)?;
        let total = strips.len();
        let overlap = self.tile_overlap.min((strips[0].1 - strips[0].0) / 2);
        let mut acc = vec![0f64; w * h];
        let mut weight = vec![0f64; w * h];
        for (i, &(y0, y1)) in strips.iter().enumerate() {
            let ls = &l[y0 * w * 3..y1 * w * 3];
            let rs = &r[y0 * w * 3..y1 * w * 3];
            let d = self.forward_rgb(ls, rs, w, y1 - y0);
            for y in y0..y1 {
                let wy = strip_weight(y, y0, y1, h, overlap) as f64;
                for x in 0..w {
                    let v = d[(y - y0) * w + x];
                    if v.is_finite() && wy > 0.0 {
                        acc[y * w + x] += wy * v as f64;
                        weight[y * w + x] += wy;
                    }
                }
            }
            progress(i + 1, total);
        }
        let data = acc
            .iter()
            .zip(&weight)
            .zip(&invalid)
            .map(|((&a, &s), &bad)| {
                if bad || s <= 0.0 {
                    f32::NAN
                } else {
                    (a / s) as f32
                }
            })
            .collect();
        Image::new(w, h, 1, data).map_err(|e| InferError::Input(e.to_string()))
    }

    /// One forward pass on interleaved RGB rows (0–255, finite), `height × width`; returns the
    /// unpadded disparity, row-major.
    pub fn forward_rgb(
        &self,
        left: &[f32],
        right: &[f32],
        width: usize,
        height: usize,
    ) -> Vec<f32> {
        let pad = Padding::new(width, height);
        let lt = self.to_tensor(&pad.apply_rgb(left, width, height), &pad);
        let rt = self.to_tensor(&pad.apply_rgb(right, width, height), &pad);
        let out = self.model.forward(lt, rt, self.iters, true);
        let disp: Vec<f32> = out
            .disp
            .into_data()
            .try_into_vec_as::<f32>()
            .expect("f32 disparity");
        pad.unpad(&disp, width, height)
    }

    fn to_tensor(&self, chw: &[f32], pad: &Padding) -> Tensor<4> {
        Tensor::from_data(
            TensorData::new(chw.to_vec(), [1, 3, pad.height, pad.width]),
            &self.device,
        )
    }
}

/// Rounds up to a multiple of [`DIVIS_BY`].
pub fn pad_to(n: usize) -> usize {
    n.div_ceil(DIVIS_BY) * DIVIS_BY
}

/// Upstream's `InputPadder(divis_by=32)`: replicate padding `[wd//2, wd − wd//2, ht//2,
/// ht − ht//2]` (left, right, top, bottom).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Padding {
    /// Columns added on the left.
    pub left: usize,
    /// Rows added on top.
    pub top: usize,
    /// Padded width.
    pub width: usize,
    /// Padded height.
    pub height: usize,
}

impl Padding {
    /// The padding of a `width × height` input.
    pub fn new(width: usize, height: usize) -> Self {
        let (pw, ph) = (pad_to(width), pad_to(height));
        Self {
            left: (pw - width) / 2,
            top: (ph - height) / 2,
            width: pw,
            height: ph,
        }
    }

    /// Interleaved RGB `height × width` → padded planar (3, H', W'), edge-replicated.
    pub fn apply_rgb(&self, rgb: &[f32], width: usize, height: usize) -> Vec<f32> {
        let mut out = vec![0f32; 3 * self.width * self.height];
        let plane = self.width * self.height;
        for yp in 0..self.height {
            let y = yp.saturating_sub(self.top).min(height - 1);
            for xp in 0..self.width {
                let x = xp.saturating_sub(self.left).min(width - 1);
                let s = &rgb[(y * width + x) * 3..(y * width + x) * 3 + 3];
                for (c, &v) in s.iter().enumerate() {
                    out[c * plane + yp * self.width + xp] = v;
                }
            }
        }
        out
    }

    /// Padded single-channel map → the `height × width` original window.
    pub fn unpad(&self, padded: &[f32], width: usize, height: usize) -> Vec<f32> {
        let mut out = Vec::with_capacity(width * height);
        for y in 0..height {
            let row = (y + self.top) * self.width + self.left;
            out.extend_from_slice(&padded[row..row + width]);
        }
        out
    }
}

/// Strips of `rows` rows covering `0..height`, consecutive ones overlapping by about `overlap`
/// rows (the last one is aligned to the bottom). One strip when `rows ≥ height`.
pub fn plan_strips(height: usize, rows: usize, overlap: usize) -> Vec<(usize, usize)> {
    if rows >= height {
        return vec![(0, height)];
    }
    let overlap = overlap.min(rows / 2);
    let stride = (rows - overlap).max(1);
    let mut strips = Vec::new();
    let mut y0 = 0;
    loop {
        if y0 + rows >= height {
            strips.push((height - rows, height));
            break;
        }
        strips.push((y0, y0 + rows));
        y0 += stride;
    }
    strips
}

/// Blend weight of row `y` in strip `y0..y1` of an image of `height` rows: a linear ramp over
/// `overlap` rows at each inner edge of the strip, 1 elsewhere.
fn strip_weight(y: usize, y0: usize, y1: usize, height: usize, overlap: usize) -> f32 {
    let ramp = overlap.max(1) as f32;
    let mut w = 1f32;
    if y0 > 0 {
        w = w.min(((y - y0) as f32 + 0.5) / ramp);
    }
    if y1 < height {
        w = w.min(((y1 - y) as f32 - 0.5) / ramp);
    }
    w.clamp(0.0, 1.0)
}

/// Image → interleaved RGB 0–255 with non-finite samples replaced by 0, and the left-pixel
/// invalid mask.
fn prepare(
    image: &Image,
    norm: Normalisation,
    side: &str,
) -> Result<(Vec<f32>, Vec<bool>), InferError> {
    let c = image.channels();
    let take: &[usize] = match c {
        1 | 2 => &[0, 0, 0],
        3 | 4 => &[0, 1, 2],
        _ => {
            return Err(InferError::Input(format!(
                "the {side} image has {c} channels: expected grey (1), grey + alpha (2), RGB (3) or RGBA (4)"
            )))
        }
    };
    let (lo, hi) = match norm {
        Normalisation::AsIs => (0.0, 255.0),
        Normalisation::Percentile(p_lo, p_hi) => {
            let used = if c <= 2 { 1 } else { 3 };
            let mut v: Vec<f32> = image
                .data()
                .chunks_exact(c)
                .flat_map(|px| px[..used].iter().copied())
                .filter(|v| v.is_finite())
                .collect();
            if v.is_empty() {
                return Err(InferError::Input(format!(
                    "the {side} image has no finite sample"
                )));
            }
            (percentile(&mut v, p_lo), percentile(&mut v, p_hi))
        }
    };
    let scale = if hi > lo { 255.0 / (hi - lo) } else { 1.0 };
    let n = image.width() * image.height();
    let mut rgb = Vec::with_capacity(3 * n);
    let mut invalid = Vec::with_capacity(n);
    for px in image.data().chunks_exact(c) {
        let bad = take.iter().any(|&k| !px[k].is_finite());
        invalid.push(bad);
        for &k in take {
            let v = px[k];
            rgb.push(if !v.is_finite() {
                0.0
            } else {
                match norm {
                    Normalisation::AsIs => v,
                    Normalisation::Percentile(..) => ((v - lo) * scale).clamp(0.0, 255.0),
                }
            });
        }
    }
    Ok((rgb, invalid))
}

/// The `p`-th percentile (0–100, nearest rank on the sorted values).
fn percentile(v: &mut [f32], p: f32) -> f32 {
    let k = ((p / 100.0) * (v.len() - 1) as f32).round() as usize;
    let k = k.min(v.len() - 1);
    *v.select_nth_unstable_by(k, |a, b| a.total_cmp(b)).1
}

/// The preset a weights file was made for, from the width of its ViT (`None` if unknown).
pub fn guess_preset(weights: &Path) -> Option<&'static str> {
    let keys = file_keys(weights).ok()?;
    let (_, shape) = keys.iter().find(|(k, _)| {
        k == "mono_encoder.cls_token" || k == "mono_encoder.patch_embed.proj.bias"
    })?;
    match shape.last()? {
        384 => Some("vits"),
        768 => Some("vitb"),
        1024 => Some("vitl"),
        64 => Some("tiny"),
        _ => None,
    }
}

/// The report's lists, at most `max` keys each.
fn short_listing(report: &LoadReport, max: usize) -> String {
    let mut s = format!(
        "  {} tensors applied, {} missing, {} mismatched, {} unexpected\n",
        report.applied,
        report.missing.len(),
        report.mismatched.len(),
        report.unexpected.len()
    );
    for (title, items) in [
        ("wrong shape", &report.mismatched),
        ("missing in the file", &report.missing),
        ("unexpected (not in the model)", &report.unexpected),
    ] {
        if items.is_empty() {
            continue;
        }
        s.push_str(&format!("  {title}:\n"));
        for k in items.iter().take(max) {
            s.push_str(&format!("    {k}\n"));
        }
        if items.len() > max {
            s.push_str(&format!("    … and {} more\n", items.len() - max));
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn padding_matches_upstream_split() {
        // 64×100 → 128×128 wide: wd = 28 → left 14, right 14; ht = 0.
        let p = Padding::new(100, 64);
        assert_eq!((p.left, p.top, p.width, p.height), (14, 0, 128, 64));
        // 33 → 64: 31 → 15 before, 16 after.
        let p = Padding::new(33, 33);
        assert_eq!((p.left, p.top, p.width, p.height), (15, 15, 64, 64));
        // Replicate and unpad round trip.
        let (w, h) = (5, 3);
        let rgb: Vec<f32> = (0..w * h * 3).map(|i| i as f32).collect();
        let p = Padding::new(w, h);
        let planar = p.apply_rgb(&rgb, w, h);
        assert_eq!(planar[0], rgb[0], "top-left corner replicates pixel (0, 0)");
        let last = planar[p.width * p.height - 1];
        assert_eq!(
            last,
            rgb[(w * h - 1) * 3],
            "bottom-right replicates the last pixel"
        );
        let red = &planar[..p.width * p.height];
        let back = p.unpad(red, w, h);
        let want: Vec<f32> = rgb.iter().step_by(3).copied().collect();
        assert_eq!(back, want);
    }

    #[test]
    fn strips_cover_and_blend_to_one() {
        for (h, rows, ov) in [
            (100, 200, 64),
            (300, 128, 64),
            (1000, 256, 64),
            (130, 64, 32),
        ] {
            let strips = plan_strips(h, rows, ov);
            assert_eq!(strips[0].0, 0);
            assert_eq!(strips.last().unwrap().1, h);
            for s in &strips {
                assert!(s.1 - s.0 == rows.min(h));
            }
            for y in 0..h {
                let total: f32 = strips
                    .iter()
                    .filter(|s| (s.0..s.1).contains(&y))
                    .map(|s| strip_weight(y, s.0, s.1, h, ov.min(rows / 2)))
                    .sum();
                assert!(total > 0.0, "row {y} of {h} has no weight ({strips:?})");
            }
        }
    }

    #[test]
    fn channels_nan_and_percentiles() {
        let grey = Image::new(2, 1, 1, vec![10.0, f32::NAN]).unwrap();
        let (rgb, bad) = prepare(&grey, Normalisation::AsIs, "left").unwrap();
        assert_eq!(rgb, vec![10.0, 10.0, 10.0, 0.0, 0.0, 0.0]);
        assert_eq!(bad, vec![false, true]);
        let rgba = Image::new(1, 1, 4, vec![1.0, 2.0, 3.0, f32::NAN]).unwrap();
        let (rgb, bad) = prepare(&rgba, Normalisation::AsIs, "left").unwrap();
        assert_eq!((rgb, bad), (vec![1.0, 2.0, 3.0], vec![false]));
        let ramp = Image::new(
            101,
            1,
            1,
            (0..101).map(|v| 1000.0 + 10.0 * v as f32).collect(),
        )
        .unwrap();
        let (rgb, _) = prepare(&ramp, Normalisation::Percentile(2.0, 98.0), "left").unwrap();
        assert_eq!(rgb[0], 0.0);
        assert_eq!(rgb[3 * 100], 255.0);
        assert!((rgb[3 * 50] - 127.5).abs() < 1e-3);
        assert!(prepare(&Image::filled(1, 1, 5, 0.0), Normalisation::AsIs, "right").is_err());
        assert_eq!(
            Normalisation::parse("percentile").unwrap(),
            Normalisation::Percentile(2.0, 98.0)
        );
        assert_eq!(
            Normalisation::parse("percentile:1:99").unwrap(),
            Normalisation::Percentile(1.0, 99.0)
        );
        assert_eq!(Normalisation::parse("as-is").unwrap(), Normalisation::AsIs);
        assert!(Normalisation::parse("percentile:9:2").is_err());
    }

    #[test]
    fn memory_estimate_grows_with_size() {
        let c = MonsterConfig::vitl();
        let a = estimate_memory_bytes(&c, 256, 256, 0);
        let b = estimate_memory_bytes(&c, 512, 512, 0);
        assert!(b > 3 * a, "{a} {b}");
    }
}

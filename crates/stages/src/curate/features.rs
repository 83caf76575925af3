//! `S_feat`: the cosine similarity of image features of the left image and its reconstruction,
//! both masked as the release does (0 outside the valid pixels, truncated to 0–255 integers).
//! With DINOv3 weights the features are the network's CLS token; without weights, the offline
//! [`HistogramDescriptor`] below. The scores CSV names the extractor used.

use anyhow::Result;
use raster::{Image, Mask};

/// Computes `S_feat` for one pair.
pub trait FeatureSimilarity {
    /// Short name written to the scores (`"dinov3 (…)"`, `"offline histogram descriptor v1"`).
    fn name(&self) -> String;
    /// Cosine similarity of the features of `left` and `left_hat` (3-channel, 0–255, already 0
    /// outside `valid`).
    fn similarity(&self, left: &Image, left_hat: &Image, valid: &Mask) -> Result<f64>;
}

/// The DINOv3 input normalisation unless another is asked for: `imagenet`, the HF processor's
/// default (the other: `sat493m`).
pub const DINOV3_NORMALISATION: &str = "imagenet";

#[cfg(feature = "network")]
pub use dinov3::Dinov3Similarity;

#[cfg(feature = "network")]
mod dinov3 {
    use anyhow::Result;
    use raster::{Image, Mask};

    use super::FeatureSimilarity;

    /// DINOv3 with weights: the release's score (`nn::dinov3::Dinov3Features::similarity`: masked
    /// uint8 images, 224² antialiased resize, CLS token after the final LayerNorm, cosine).
    pub struct Dinov3Similarity {
        pub features: nn::dinov3::Dinov3Features,
    }

    impl Dinov3Similarity {
        /// Loads an HF DINOv3 checkpoint: layout from `preset` (`vits16`, `vitb16`, `vitl16`,
        /// `tiny`) or inferred from the checkpoint; `normalisation` `imagenet` (the HF processor's
        /// default) or `sat493m`.
        pub fn load(
            weights: &std::path::Path,
            preset: Option<&str>,
            normalisation: &str,
            device: nn::device::DeviceChoice,
        ) -> Result<Self> {
            use anyhow::Context;
            use nn::dinov3::{Dinov3Config, Dinov3Features, Dinov3Preprocess, Normalization};
            let config = match preset {
                Some(p) => Dinov3Config::preset(p).with_context(|| {
                    format!("unknown DINOv3 preset {p:?} (expected vits16, vitb16, vitl16 or tiny)")
                })?,
                None => Dinov3Config::from_checkpoint(weights)?,
            };
            let normalization = Normalization::by_name(normalisation).with_context(|| {
                format!(
                    "unknown DINOv3 normalisation {normalisation:?} (expected imagenet or sat493m)"
                )
            })?;
            let device = device.device().map_err(anyhow::Error::msg)?;
            let features = Dinov3Features::from_file(weights, config, device)
                .with_context(|| format!("loading DINOv3 from {}", weights.display()))?
                .with_preprocess(Dinov3Preprocess {
                    normalization,
                    ..Dinov3Preprocess::default()
                })?;
            Ok(Dinov3Similarity { features })
        }
    }

    impl FeatureSimilarity for Dinov3Similarity {
        fn name(&self) -> String {
            let (weights, _) = self.features.weights();
            let c = self.features.config();
            let p = self.features.preprocess();
            format!(
                "dinov3 ({}, hidden {}, {} layers, {}x{} input, mean {:?} std {:?})",
                weights.display(),
                c.hidden_size,
                c.num_hidden_layers,
                p.width,
                p.height,
                p.normalization.mean,
                p.normalization.std
            )
        }

        fn similarity(&self, left: &Image, left_hat: &Image, valid: &Mask) -> Result<f64> {
            Ok(self.features.similarity(left, left_hat, valid)? as f64)
        }
    }
}

/// An offline appearance descriptor that needs no weights. It is a concatenation of
/// square-rooted, L1-normalised histograms (blocks) over the VALID pixels only, each block scaled
/// by the square root of its weight, so that the cosine similarity of two descriptors is the
/// weighted mean of the blocks' Bhattacharyya coefficients — 1 for identical distributions, 0 for
/// disjoint ones:
///
/// * colour (weight 2): per-channel 32-bin histograms of the 0–255 values (linear soft
///   binning), over the whole image (weight 1) and per cell of a 2×2 grid (weight 1 in all);
/// * gradient orientation (weight 1 per scale, 3 scales): 9-bin unsigned orientation histograms
///   weighted by the gradient magnitude, on a 4×4 grid of cells, of the grey image at full, ½
///   and ¼ resolution (2×2 box averages; a coarse pixel is valid when its four parents are);
/// * gradient magnitude (weight ⅓ per scale): 16-bin histograms of log2(1 + |∇|) over [0, 8).
///
/// Colour blocks react to tints, colour remaps, haze and seasons; magnitude blocks to noise,
/// blur and contrast loss; orientation grids to structural and registration differences. An
/// empty histogram (no valid or no textured pixel in a cell) counts as uniform.
#[derive(Clone, Copy, Debug, Default)]
pub struct HistogramDescriptor;

const COLOUR_BINS: usize = 32;
const ORIENT_BINS: usize = 9;
const ORIENT_GRID: usize = 4;
const MAG_BINS: usize = 16;
const MAG_MAX: f64 = 8.0;
const SCALES: usize = 3;

impl FeatureSimilarity for HistogramDescriptor {
    fn name(&self) -> String {
        "offline histogram descriptor v1 (colour + gradient orientation/magnitude, Bhattacharyya)"
            .to_string()
    }

    fn similarity(&self, left: &Image, left_hat: &Image, valid: &Mask) -> Result<f64> {
        let a = HistogramDescriptor::describe(left, valid)?;
        let b = HistogramDescriptor::describe(left_hat, valid)?;
        Ok(cosine(&a, &b))
    }
}

/// `a·b / (max(‖a‖, 1e-8) · max(‖b‖, 1e-8))` (PyTorch's `cosine_similarity`), in f64.
pub fn cosine(a: &[f32], b: &[f32]) -> f64 {
    let dot: f64 = a.iter().zip(b).map(|(&x, &y)| x as f64 * y as f64).sum();
    let na = a
        .iter()
        .map(|&x| (x as f64).powi(2))
        .sum::<f64>()
        .sqrt()
        .max(1e-8);
    let nb = b
        .iter()
        .map(|&x| (x as f64).powi(2))
        .sum::<f64>()
        .sqrt()
        .max(1e-8);
    dot / (na * nb)
}

/// Adds `weight` to the two bins around continuous position `t` (bin centres at k + 0.5),
/// clamped to the ends.
fn soft_bin(hist: &mut [f64], t: f64, weight: f64) {
    let n = hist.len();
    let u = (t - 0.5).clamp(0.0, (n - 1) as f64);
    let k = (u.floor() as usize).min(n - 1);
    let f = u - k as f64;
    hist[k] += weight * (1.0 - f);
    if k + 1 < n {
        hist[k + 1] += weight * f;
    }
}

/// Circular variant for orientations (bin n wraps to 0).
fn soft_bin_circular(hist: &mut [f64], t: f64, weight: f64) {
    let n = hist.len();
    let u = (t - 0.5).rem_euclid(n as f64);
    let k = (u.floor() as usize) % n;
    let f = u - u.floor();
    hist[k] += weight * (1.0 - f);
    hist[(k + 1) % n] += weight * f;
}

/// Appends `sqrt(weight) · sqrt(h / Σh)` (uniform when Σh = 0).
fn push_block(out: &mut Vec<f32>, hist: &[f64], weight: f64) {
    let s: f64 = hist.iter().sum();
    let n = hist.len() as f64;
    for &v in hist {
        let p = if s > 0.0 { v / s } else { 1.0 / n };
        out.push((weight * p).sqrt() as f32);
    }
}

/// Grey image and mask halved by 2×2 box averages.
fn halve(grey: &[f64], mask: &[bool], w: usize, h: usize) -> (Vec<f64>, Vec<bool>, usize, usize) {
    let (w2, h2) = (w / 2, h / 2);
    let mut g = vec![0.0; w2 * h2];
    let mut m = vec![false; w2 * h2];
    for y in 0..h2 {
        for x in 0..w2 {
            let idx = [
                2 * y * w + 2 * x,
                2 * y * w + 2 * x + 1,
                (2 * y + 1) * w + 2 * x,
                (2 * y + 1) * w + 2 * x + 1,
            ];
            g[y * w2 + x] = idx.iter().map(|&i| grey[i]).sum::<f64>() / 4.0;
            m[y * w2 + x] = idx.iter().all(|&i| mask[i]);
        }
    }
    (g, m, w2, h2)
}

impl HistogramDescriptor {
    /// The descriptor of one masked 3-channel image (see the type's docs).
    pub fn describe(image: &Image, valid: &Mask) -> Result<Vec<f32>> {
        image.check_mask(valid, "feature descriptor")?;
        let (w, h) = image.size();
        let c = image.channels();
        let mut out = Vec::new();
        // Colour: global, then 2×2 cells.
        let mut cells = vec![vec![vec![0.0f64; COLOUR_BINS]; 3]; 5];
        for y in 0..h {
            for x in 0..w {
                if !valid.get(x, y) {
                    continue;
                }
                let cell = 1 + (2 * y / h.max(1)).min(1) * 2 + (2 * x / w.max(1)).min(1);
                let p = image.pixel(x, y);
                for ch in 0..3 {
                    let v = p[ch.min(c - 1)] as f64;
                    let t = v.clamp(0.0, 255.999) / 256.0 * COLOUR_BINS as f64;
                    soft_bin(&mut cells[0][ch], t, 1.0);
                    soft_bin(&mut cells[cell][ch], t, 1.0);
                }
            }
        }
        for (i, cell) in cells.iter().enumerate() {
            let wgt = if i == 0 { 1.0 } else { 0.25 };
            for hist in cell {
                push_block(&mut out, hist, wgt / 3.0);
            }
        }
        // Gradients at three scales.
        let mut grey: Vec<f64> = (0..w * h)
            .map(|i| {
                let p = &image.data()[i * c..(i + 1) * c];
                p.iter().take(3).map(|&v| v as f64).sum::<f64>() / p.len().min(3) as f64
            })
            .collect();
        let mut mask = valid.data().to_vec();
        let (mut sw, mut sh) = (w, h);
        for _ in 0..SCALES {
            let mut orient = vec![vec![0.0f64; ORIENT_BINS]; ORIENT_GRID * ORIENT_GRID];
            let mut mag = vec![0.0f64; MAG_BINS];
            for y in 1..sh.saturating_sub(1) {
                for x in 1..sw.saturating_sub(1) {
                    let i = y * sw + x;
                    if !(mask[i] && mask[i - 1] && mask[i + 1] && mask[i - sw] && mask[i + sw]) {
                        continue;
                    }
                    let gx = (grey[i + 1] - grey[i - 1]) / 2.0;
                    let gy = (grey[i + sw] - grey[i - sw]) / 2.0;
                    let m = (gx * gx + gy * gy).sqrt();
                    soft_bin(&mut mag, (1.0 + m).log2() / MAG_MAX * MAG_BINS as f64, 1.0);
                    if m > 0.0 {
                        let theta = gy.atan2(gx).rem_euclid(std::f64::consts::PI);
                        let cell = (ORIENT_GRID * y / sh).min(ORIENT_GRID - 1) * ORIENT_GRID
                            + (ORIENT_GRID * x / sw).min(ORIENT_GRID - 1);
                        soft_bin_circular(
                            &mut orient[cell],
                            theta / std::f64::consts::PI * ORIENT_BINS as f64,
                            m,
                        );
                    }
                }
            }
            for hist in &orient {
                push_block(&mut out, hist, 1.0 / (ORIENT_GRID * ORIENT_GRID) as f64);
            }
            push_block(&mut out, &mag, 1.0 / 3.0);
            if sw < 4 || sh < 4 {
                // Too small to halve: repeat the last scale's blocks for a fixed length.
                continue;
            }
            let (g, m, w2, h2) = halve(&grey, &mask, sw, sh);
            grey = g;
            mask = m;
            sw = w2;
            sh = h2;
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn textured(w: usize, h: usize, tint: [f32; 3]) -> Image {
        let mut data = Vec::new();
        for y in 0..h {
            for x in 0..w {
                let v = 60.0 + 40.0 * ((x as f32 * 0.7).sin() + (y as f32 * 0.4).cos());
                data.extend(tint.iter().map(|t| (v + t).clamp(0.0, 255.0)));
            }
        }
        Image::new(w, h, 3, data).unwrap()
    }

    #[test]
    fn identical_is_one_and_changes_lower_it() {
        let a = textured(48, 40, [0.0; 3]);
        let m = Mask::filled(48, 40, true);
        let d = HistogramDescriptor;
        assert!((d.similarity(&a, &a, &m).unwrap() - 1.0).abs() < 1e-6);
        let tinted = textured(48, 40, [40.0, -20.0, 10.0]);
        let s = d.similarity(&a, &tinted, &m).unwrap();
        // Colour blocks carry 2/6 of the weight; gradients are unchanged by a tint.
        assert!(s < 0.98, "a strong tint must lower the similarity, got {s}");
        let mut noisy = a.clone();
        for (i, v) in noisy.data_mut().iter_mut().enumerate() {
            *v = (*v + if (i * 7919) % 13 < 6 { 30.0 } else { -30.0 }).clamp(0.0, 255.0);
        }
        let n = d.similarity(&a, &noisy, &m).unwrap();
        assert!(n < 0.97, "heavy noise must lower the similarity, got {n}");
        let len = HistogramDescriptor::describe(&a, &m).unwrap().len();
        let tiny = Image::filled(5, 5, 3, 7.0);
        assert_eq!(
            HistogramDescriptor::describe(&tiny, &Mask::filled(5, 5, true))
                .unwrap()
                .len(),
            len,
            "fixed length whatever the size"
        );
        // Pixels outside the mask do not count.
        let mut b = a.clone();
        b.data_mut()[..3].copy_from_slice(&[255.0, 0.0, 0.0]);
        let mut m2 = m.clone();
        m2.set(0, 0, false);
        assert!((d.similarity(&a, &b, &m2).unwrap() - 1.0).abs() < 1e-6);
        assert!((cosine(&[1.0, 0.0], &[0.0, 0.0])).abs() < 1e-12);
    }
}

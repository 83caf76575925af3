//! The offline segmenter: a per-pixel Gaussian-mixture classifier (generative, 3 full-covariance
//! components per class on the [`pixel_features`]) trained at first use on procedural worlds,
//! whose class maps are exact. Training is deterministic (fixed world seeds, k-means with a
//! deterministic start) and takes a fraction of a second; the model is cached for the process.
//!
//! It knows only what the world contains: OpenEarthMap classes 1–8 as the world paints them
//! (bare land, rangeland, developed space, road, tree, water, agriculture, building). Real
//! imagery differs in appearance, so on real data prefer SegFormer with the release's weights;
//! this default keeps every stage runnable without weights and is measured on unseen worlds.

use std::sync::OnceLock;

use anyhow::{anyhow, Result};
use raster::Image;
use rayon::prelude::*;

use super::pixel_features::{pixel_features, FEATURES};

/// Number of OpenEarthMap classes (ids 0–8).
pub const CLASSES: usize = 9;
/// Mixture components per class.
const COMPONENTS: usize = 3;
/// Added to the covariance diagonals (standardised units): keeps components from becoming
/// over-confident on one world's particulars.
const RIDGE: f64 = 0.05;
/// Seeds and size of the training worlds (tests evaluate on other seeds).
pub const TRAINING_SEEDS: [u64; 3] = [9001, 9002, 9003];
pub const TRAINING_SIZE: usize = 160;

type Vector = [f64; FEATURES];

/// One Gaussian: mean, inverse covariance (row-major) and log normaliser (log weight −
/// ½ log det Σ).
#[derive(Clone, Debug)]
struct Gaussian {
    mean: Vector,
    precision: Vec<f64>,
    log_norm: f64,
}

impl Gaussian {
    fn log_density(&self, x: &Vector) -> f64 {
        let mut d = [0.0; FEATURES];
        for k in 0..FEATURES {
            d[k] = x[k] - self.mean[k];
        }
        let mut q = 0.0;
        for i in 0..FEATURES {
            let row = &self.precision[i * FEATURES..(i + 1) * FEATURES];
            let s: f64 = row.iter().zip(&d).map(|(p, v)| p * v).sum();
            q += d[i] * s;
        }
        self.log_norm - 0.5 * q
    }

    /// Fits a Gaussian with weight `weight` to `samples` (ridge-regularised covariance).
    fn fit(samples: &[&Vector], weight: f64) -> Option<Gaussian> {
        let n = samples.len();
        if n < FEATURES + 2 {
            return None;
        }
        let mut mean = [0.0; FEATURES];
        for s in samples {
            for k in 0..FEATURES {
                mean[k] += s[k];
            }
        }
        mean.iter_mut().for_each(|m| *m /= n as f64);
        let mut cov = vec![0.0; FEATURES * FEATURES];
        for s in samples {
            for i in 0..FEATURES {
                let di = s[i] - mean[i];
                for j in 0..FEATURES {
                    cov[i * FEATURES + j] += di * (s[j] - mean[j]);
                }
            }
        }
        cov.iter_mut().for_each(|c| *c /= (n - 1) as f64);
        for i in 0..FEATURES {
            cov[i * FEATURES + i] += RIDGE;
        }
        let (precision, log_det) = invert_spd(&cov)?;
        Some(Gaussian {
            mean,
            precision,
            log_norm: weight.ln() - 0.5 * log_det,
        })
    }
}

/// Inverse and log-determinant of a symmetric positive-definite matrix (Cholesky).
fn invert_spd(a: &[f64]) -> Option<(Vec<f64>, f64)> {
    let n = FEATURES;
    let mut l = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..=i {
            let mut s = a[i * n + j];
            for k in 0..j {
                s -= l[i * n + k] * l[j * n + k];
            }
            if i == j {
                if s <= 0.0 {
                    return None;
                }
                l[i * n + i] = s.sqrt();
            } else {
                l[i * n + j] = s / l[j * n + j];
            }
        }
    }
    let log_det = 2.0 * (0..n).map(|i| l[i * n + i].ln()).sum::<f64>();
    // Solve L Lᵀ X = I column by column.
    let mut inv = vec![0.0; n * n];
    for col in 0..n {
        let mut y = vec![0.0; n];
        for i in 0..n {
            let mut s = if i == col { 1.0 } else { 0.0 };
            for k in 0..i {
                s -= l[i * n + k] * y[k];
            }
            y[i] = s / l[i * n + i];
        }
        let mut x = vec![0.0; n];
        for i in (0..n).rev() {
            let mut s = y[i];
            for k in i + 1..n {
                s -= l[k * n + i] * x[k];
            }
            x[i] = s / l[i * n + i];
        }
        for i in 0..n {
            inv[i * n + col] = x[i];
        }
    }
    Some((inv, log_det))
}

/// Deterministic k-means (start: samples evenly spaced in brightness order), 12 iterations.
fn kmeans<'a>(samples: &[&'a Vector], k: usize) -> Vec<Vec<&'a Vector>> {
    let mut order: Vec<&Vector> = samples.to_vec();
    order.sort_by(|a, b| a[3].total_cmp(&b[3]));
    let mut centres: Vec<Vector> = (0..k)
        .map(|i| *order[(2 * i + 1) * order.len() / (2 * k)])
        .collect();
    let mut groups: Vec<Vec<&Vector>> = vec![Vec::new(); k];
    for _ in 0..12 {
        groups.iter_mut().for_each(|g| g.clear());
        for s in samples {
            let best = (0..k)
                .min_by(|&a, &b| dist2(s, &centres[a]).total_cmp(&dist2(s, &centres[b])))
                .unwrap_or(0);
            groups[best].push(s);
        }
        for (c, g) in centres.iter_mut().zip(&groups) {
            if g.is_empty() {
                continue;
            }
            let mut m = [0.0; FEATURES];
            for s in g {
                for q in 0..FEATURES {
                    m[q] += s[q];
                }
            }
            *c = m.map(|v| v / g.len() as f64);
        }
    }
    groups
}

fn dist2(a: &Vector, b: &Vector) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum()
}

/// The trained classifier: per class, mixture components (empty for classes never seen).
#[derive(Clone, Debug)]
pub struct PixelClassifier {
    classes: Vec<Vec<Gaussian>>,
    /// Feature standardisation (z-scores over all training pixels).
    centre: Vector,
    scale: Vector,
}

fn standardise(x: &mut Vector, centre: &Vector, scale: &Vector) {
    for k in 0..FEATURES {
        x[k] = (x[k] - centre[k]) / scale[k];
    }
}

impl PixelClassifier {
    /// Trains on `(image, class map)` examples (OpenEarthMap ids 0–8 in the class maps).
    pub fn train(examples: &[(Image, Image)]) -> Result<Self> {
        let mut per_class: Vec<Vec<Vector>> = vec![Vec::new(); CLASSES];
        for (image, classes) in examples {
            if image.size() != classes.size() {
                return Err(anyhow!("training image and class map differ in size"));
            }
            let f = pixel_features(image);
            for (x, &c) in f.into_iter().zip(classes.data()) {
                let c = c as usize;
                if c < CLASSES {
                    per_class[c].push(x);
                }
            }
        }
        let total: usize = per_class.iter().map(Vec::len).sum();
        if total == 0 {
            return Err(anyhow!("no training pixels"));
        }
        let mut centre = [0.0; FEATURES];
        let mut square = [0.0; FEATURES];
        for x in per_class.iter().flatten() {
            for k in 0..FEATURES {
                centre[k] += x[k];
                square[k] += x[k] * x[k];
            }
        }
        let centre = centre.map(|v| v / total as f64);
        let mut scale = [1.0; FEATURES];
        for k in 0..FEATURES {
            scale[k] = (square[k] / total as f64 - centre[k] * centre[k])
                .max(1e-12)
                .sqrt();
        }
        for x in per_class.iter_mut().flatten() {
            standardise(x, &centre, &scale);
        }
        let classes = per_class
            .par_iter()
            .map(|samples| {
                let refs: Vec<&Vector> = samples.iter().collect();
                if refs.is_empty() {
                    return Vec::new();
                }
                let prior = samples.len() as f64 / total as f64;
                let k = if refs.len() >= COMPONENTS * 200 {
                    COMPONENTS
                } else {
                    1
                };
                kmeans(&refs, k)
                    .iter()
                    .filter_map(|g| Gaussian::fit(g, prior * g.len() as f64 / refs.len() as f64))
                    .collect::<Vec<_>>()
            })
            .collect();
        Ok(PixelClassifier {
            classes,
            centre,
            scale,
        })
    }

    /// Trains on the procedural worlds of [`TRAINING_SEEDS`] (plus a colour-jittered copy of
    /// each, for robustness to radiometry).
    pub fn train_on_worlds() -> Result<Self> {
        let examples: Vec<(Image, Image)> = TRAINING_SEEDS
            .par_iter()
            .map(|&seed| -> Result<Vec<(Image, Image)>> {
                let p = world::WorldParams::new(TRAINING_SIZE, seed);
                let w = world::generate(&p, &world::Neutral, &|_, _| {}).map_err(|e| anyhow!(e))?;
                let jitter = jittered(&w.left.image, seed);
                Ok(vec![
                    (w.left.image, w.left.classes.clone()),
                    (jitter, w.left.classes),
                ])
            })
            .collect::<Result<Vec<_>>>()?
            .into_iter()
            .flatten()
            .collect();
        Self::train(&examples)
    }

    /// The classifier trained on the worlds, trained once per process.
    pub fn shared() -> Result<&'static PixelClassifier> {
        static MODEL: OnceLock<Result<PixelClassifier, String>> = OnceLock::new();
        MODEL
            .get_or_init(|| Self::train_on_worlds().map_err(|e| format!("{e:#}")))
            .as_ref()
            .map_err(|e| anyhow!("training the offline segmenter: {e}"))
    }

    /// Class posteriors, class-major (`CLASSES` planes of `width·height` values).
    pub fn probabilities(&self, image: &Image) -> Vec<f32> {
        let f = pixel_features(image);
        let n = f.len();
        let mut out = vec![0f32; CLASSES * n];
        let rows: Vec<[f32; CLASSES]> = f
            .par_iter()
            .map(|x| {
                let mut x = *x;
                standardise(&mut x, &self.centre, &self.scale);
                let x = &x;
                let mut logp = [f64::NEG_INFINITY; CLASSES];
                for (c, comps) in self.classes.iter().enumerate() {
                    if comps.is_empty() {
                        continue;
                    }
                    let l: Vec<f64> = comps.iter().map(|g| g.log_density(x)).collect();
                    let m = l.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                    logp[c] = m + l.iter().map(|v| (v - m).exp()).sum::<f64>().ln();
                }
                let m = logp.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                let mut p = [0f32; CLASSES];
                if m.is_finite() {
                    let s: f64 = logp.iter().map(|v| (v - m).exp()).sum();
                    for c in 0..CLASSES {
                        p[c] = ((logp[c] - m).exp() / s) as f32;
                    }
                } else {
                    p[0] = 1.0;
                }
                p
            })
            .collect();
        for (i, p) in rows.iter().enumerate() {
            for c in 0..CLASSES {
                out[c * n + i] = p[c];
            }
        }
        out
    }
}

/// A deterministic per-channel gain and offset (±15 %, ±10 DN) of a world image.
fn jittered(image: &Image, seed: u64) -> Image {
    let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    let mut next = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    let gain: [f64; 3] = [
        0.85 + 0.3 * next(),
        0.85 + 0.3 * next(),
        0.85 + 0.3 * next(),
    ];
    let offset: [f64; 3] = [
        20.0 * next() - 10.0,
        20.0 * next() - 10.0,
        20.0 * next() - 10.0,
    ];
    let mut out = image.clone();
    let c = out.channels();
    for p in out.data_mut().chunks_exact_mut(c) {
        for ch in 0..c.min(3) {
            p[ch] = (p[ch] as f64 * gain[ch] + offset[ch]).clamp(0.0, 255.0) as f32;
        }
    }
    out
}

/// Intersection over union of `class` between a predicted and a true class map; `None` when the
/// class is in neither.
pub fn class_iou(predicted: &Image, truth: &Image, class: u8) -> Option<f64> {
    let c = class as f32;
    let (mut inter, mut union) = (0usize, 0usize);
    for (&p, &t) in predicted.data().iter().zip(truth.data()) {
        let (a, b) = (p == c, t == c);
        inter += (a && b) as usize;
        union += (a || b) as usize;
    }
    (union > 0).then(|| inter as f64 / union as f64)
}

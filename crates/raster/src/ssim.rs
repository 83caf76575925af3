//! Structural similarity (SSIM, Wang et al. 2004) in the two flavours the paper uses:
//!
//! * [`ssim_gaussian`]: the standard score, identical in definition to scikit-image's
//!   `structural_similarity(gaussian_weights=True, sigma=1.5, use_sample_covariance=False,
//!   data_range=L)`, used to rank training pairs by photometric similarity (`S_SSIM`);
//! * [`ssim_uniform_map`]: scikit-image's defaults (7×7 uniform window, sample covariances),
//!   which is what the released pair-scoring script calls, so `curate` reproduces its numbers;
//! * [`ssim_box3`]: the per-pixel 3×3 box-filter SSIM of Monodepth, used by the photometric
//!   loss `α (1 − SSIM)/2 + (1 − α) |I − Î|`.
//!
//! Statistics are accumulated in f64. NaN samples propagate to every SSIM value whose window
//! contains them (mask them out of the means yourself, e.g. with [`ssim_gaussian_masked`]).

use rayon::prelude::*;

use crate::{Image, Mask, RasterError, Result};

/// Standard deviation of the Gaussian window (Wang et al.; scikit-image's `sigma`).
pub const GAUSSIAN_SIGMA: f64 = 1.5;
/// Window radius: scikit-image uses `truncate = 3.5`, i.e. `int(3.5 σ + 0.5) = 5`, an 11×11 window.
pub const GAUSSIAN_RADIUS: usize = 5;
/// Side of scikit-image's default uniform window (`win_size = 7`).
pub const UNIFORM_WINDOW: usize = 7;
/// SSIM stabilising constants `C1 = (K1 L)²`, `C2 = (K2 L)²` for a data range `L`.
pub const K1: f64 = 0.01;
pub const K2: f64 = 0.03;

/// The 1-D Gaussian window, normalised to sum 1 (the 2-D window is its outer product, as in
/// `scipy.ndimage.gaussian_filter`).
fn gaussian_kernel() -> [f64; 2 * GAUSSIAN_RADIUS + 1] {
    let mut k = [0.0; 2 * GAUSSIAN_RADIUS + 1];
    for (i, v) in k.iter_mut().enumerate() {
        let t = i as f64 - GAUSSIAN_RADIUS as f64;
        *v = (-0.5 * t * t / (GAUSSIAN_SIGMA * GAUSSIAN_SIGMA)).exp();
    }
    let s: f64 = k.iter().sum();
    k.map(|v| v / s)
}

/// scipy's `mode='reflect'` (edge sample repeated: `d c b a | a b c d | d c b a`), applied as
/// often as needed so that it is defined for any offset, even past a tiny image.
#[inline]
fn reflect_scipy(i: isize, n: usize) -> usize {
    let n = n as isize;
    let m = i.rem_euclid(2 * n);
    (if m < n { m } else { 2 * n - 1 - m }) as usize
}

/// PyTorch's `ReflectionPad` (edge not repeated: `c b | a b c | b a`), for offsets of at most
/// one past the border of an axis of length `n ≥ 2`.
#[inline]
fn reflect_torch(i: isize, n: usize) -> usize {
    if i < 0 {
        (-i) as usize
    } else if i as usize >= n {
        2 * n - 2 - i as usize
    } else {
        i as usize
    }
}

fn check_pair(a: &Image, b: &Image, what: &str) -> Result<()> {
    a.check_same_size(b, what)?;
    if a.channels() != b.channels() {
        return Err(RasterError::Shape(format!(
            "{what}: channel counts differ ({} vs {})",
            a.channels(),
            b.channels()
        )));
    }
    Ok(())
}

/// `SSIM = (2 μa μb + C1)(2 σab + C2) / ((μa² + μb² + C1)(σa² + σb² + C2))` from the windowed
/// moments `[E a, E b, E a², E b², E ab]`; `cov_norm` scales the (co)variances (`N/(N−1)` for
/// sample covariances, 1 for population ones).
#[inline]
fn ssim_from_moments(m: &[f64; 5], c1: f64, c2: f64, cov_norm: f64) -> f64 {
    let [ma, mb, maa, mbb, mab] = *m;
    let va = cov_norm * (maa - ma * ma);
    let vb = cov_norm * (mbb - mb * mb);
    let cov = cov_norm * (mab - ma * mb);
    ((2.0 * ma * mb + c1) * (2.0 * cov + c2)) / ((ma * ma + mb * mb + c1) * (va + vb + c2))
}

/// SSIM of every channel with a separable window (`kernel` ⊗ `kernel`, centred, scipy
/// `reflect` borders), planar: `maps[ch][y * W + x]`.
fn windowed_maps(
    a: &Image,
    b: &Image,
    kernel: &[f64],
    data_range: f32,
    cov_norm: f64,
    what: &str,
) -> Result<Vec<Vec<f64>>> {
    check_pair(a, b, what)?;
    if !(data_range.is_finite() && data_range > 0.0) {
        return Err(RasterError::Shape(format!(
            "{what}: data_range must be positive, got {data_range}"
        )));
    }
    let (w, h) = a.size();
    let c = a.channels();
    let l = data_range as f64;
    let (c1, c2) = ((K1 * l).powi(2), (K2 * l).powi(2));
    let r = (kernel.len() / 2) as isize;
    if w == 0 || h == 0 {
        return Ok(vec![Vec::new(); c]);
    }
    let maps = (0..c)
        .map(|ch| {
            // Horizontal pass on the five moment images, one row per task.
            let mut horiz = vec![[0.0f64; 5]; w * h];
            horiz.par_chunks_mut(w).enumerate().for_each(|(y, out)| {
                let (ra, rb) = (a.row(y), b.row(y));
                for (x, o) in out.iter_mut().enumerate() {
                    let mut acc = [0.0f64; 5];
                    for (j, &kw) in kernel.iter().enumerate() {
                        let xx = reflect_scipy(x as isize + j as isize - r, w);
                        let va = ra[xx * c + ch] as f64;
                        let vb = rb[xx * c + ch] as f64;
                        acc[0] += kw * va;
                        acc[1] += kw * vb;
                        acc[2] += kw * va * va;
                        acc[3] += kw * vb * vb;
                        acc[4] += kw * va * vb;
                    }
                    *o = acc;
                }
            });
            // Vertical pass (whole rows at a time, cache friendly), then SSIM.
            let mut map = vec![0.0f64; w * h];
            map.par_chunks_mut(w).enumerate().for_each_init(
                || vec![[0.0f64; 5]; w],
                |acc, (y, out)| {
                    acc.iter_mut().for_each(|m| *m = [0.0; 5]);
                    for (i, &kw) in kernel.iter().enumerate() {
                        let yy = reflect_scipy(y as isize + i as isize - r, h);
                        for (m, src) in acc.iter_mut().zip(&horiz[yy * w..(yy + 1) * w]) {
                            for (mq, sq) in m.iter_mut().zip(src) {
                                *mq += kw * sq;
                            }
                        }
                    }
                    for (o, m) in out.iter_mut().zip(acc.iter()) {
                        *o = ssim_from_moments(m, c1, c2, cov_norm);
                    }
                },
            );
            map
        })
        .collect();
    Ok(maps)
}

/// Gaussian-window SSIM of every channel (population covariances), planar.
fn gaussian_maps(a: &Image, b: &Image, data_range: f32) -> Result<Vec<Vec<f64>>> {
    windowed_maps(a, b, &gaussian_kernel(), data_range, 1.0, "ssim_gaussian")
}

/// Planar per-channel maps → an interleaved image of the inputs' shape.
fn interleave(maps: &[Vec<f64>], w: usize, h: usize) -> Result<Image> {
    let c = maps.len();
    let mut data = vec![0.0f32; w * h * c];
    for (ch, m) in maps.iter().enumerate() {
        for (i, &v) in m.iter().enumerate() {
            data[i * c + ch] = v as f32;
        }
    }
    Image::new(w, h, c, data)
}

/// Mean of planar maps over the pixels where `mask` is true and every channel; `None` for an
/// empty mask.
fn masked_mean_of_maps(maps: &[Vec<f64>], mask: &Mask) -> Option<f64> {
    let n = mask.count();
    if n == 0 || maps.is_empty() {
        return None;
    }
    let s: f64 = maps
        .iter()
        .map(|m| {
            m.iter()
                .zip(mask.data())
                .filter(|(_, &v)| v)
                .map(|(s, _)| s)
                .sum::<f64>()
        })
        .sum();
    Some(s / (n * maps.len()) as f64)
}

/// Mean SSIM with an 11×11 Gaussian window (σ = 1.5), `C1 = (0.01 L)²`, `C2 = (0.03 L)²` with
/// `L = data_range`, population (not sample) covariances and scipy `reflect` boundary handling;
/// as in scikit-image, the mean is taken over the map minus a border of 5 pixels (where the
/// window would leave the image) and channels are averaged. Both images must have the same
/// size and channel count, and be at least 11×11.
pub fn ssim_gaussian(a: &Image, b: &Image, data_range: f32) -> Result<f64> {
    let (w, h) = a.size();
    let win = 2 * GAUSSIAN_RADIUS + 1;
    if w < win || h < win {
        return Err(RasterError::Shape(format!(
            "ssim_gaussian: a {w}x{h} image is smaller than the {win}x{win} window"
        )));
    }
    let maps = gaussian_maps(a, b, data_range)?;
    let p = GAUSSIAN_RADIUS;
    let per_channel: Vec<f64> = maps
        .iter()
        .map(|m| {
            let s: f64 = (p..h - p)
                .map(|y| m[y * w + p..y * w + w - p].iter().sum::<f64>())
                .sum();
            s / ((w - 2 * p) * (h - 2 * p)) as f64
        })
        .collect();
    Ok(per_channel.iter().sum::<f64>() / per_channel.len() as f64)
}

/// The full per-pixel, per-channel map behind [`ssim_gaussian`], same shape as the inputs
/// (border pixels use reflected windows, like scikit-image's `full=True` map).
pub fn ssim_gaussian_map(a: &Image, b: &Image, data_range: f32) -> Result<Image> {
    let maps = gaussian_maps(a, b, data_range)?;
    interleave(&maps, a.width(), a.height())
}

/// Mean of the Gaussian SSIM map over the pixels where `mask` is true (all channels), for
/// scores restricted to a validity mask (rectification borders, water, trees). The mask is
/// used as given: no extra border is removed. `Ok(None)` for an empty mask.
pub fn ssim_gaussian_masked(
    a: &Image,
    b: &Image,
    mask: &Mask,
    data_range: f32,
) -> Result<Option<f64>> {
    a.check_mask(mask, "ssim_gaussian_masked")?;
    Ok(masked_mean_of_maps(&gaussian_maps(a, b, data_range)?, mask))
}

/// scikit-image's `structural_similarity` with its defaults, as the release's pair scoring
/// calls it (`full=True, channel_axis=-1, data_range=L`): a 7×7 **uniform** window
/// (`uniform_filter`, `mode='reflect'`), sample covariances (`N/(N−1)`, N = 49), each channel
/// on its own. Per-pixel, per-channel map, same shape as the inputs, which must be at least
/// 7×7 (scikit-image refuses smaller ones).
pub fn ssim_uniform_map(a: &Image, b: &Image, data_range: f32) -> Result<Image> {
    let maps = uniform_maps(a, b, data_range)?;
    interleave(&maps, a.width(), a.height())
}

/// Mean of [`ssim_uniform_map`] over the pixels of `mask` and every channel (the release's
/// `reduce_metric_map`); `Ok(None)` for an empty mask.
pub fn ssim_uniform_masked(
    a: &Image,
    b: &Image,
    mask: &Mask,
    data_range: f32,
) -> Result<Option<f64>> {
    a.check_mask(mask, "ssim_uniform_masked")?;
    Ok(masked_mean_of_maps(&uniform_maps(a, b, data_range)?, mask))
}

fn uniform_maps(a: &Image, b: &Image, data_range: f32) -> Result<Vec<Vec<f64>>> {
    let (w, h) = a.size();
    let win = UNIFORM_WINDOW;
    if w < win || h < win {
        return Err(RasterError::Shape(format!(
            "ssim_uniform: a {w}x{h} image is smaller than the {win}x{win} window"
        )));
    }
    let n = (win * win) as f64;
    let kernel = [1.0 / win as f64; UNIFORM_WINDOW];
    windowed_maps(a, b, &kernel, data_range, n / (n - 1.0), "ssim_uniform")
}

/// Monodepth's per-pixel SSIM: 3×3 average pooling of the means, variances and covariance after
/// a reflection padding of 1 (PyTorch `ReflectionPad2d`, edge not repeated), `C1 = 0.01²`,
/// `C2 = 0.03²` (images in [0, 1]). Returns SSIM (not the loss) per pixel and channel, same
/// shape as the inputs; the photometric loss uses `clamp((1 − SSIM)/2, 0, 1)`. Images must be
/// at least 2×2 (reflection padding needs a neighbour) and have matching size and channels.
pub fn ssim_box3(a: &Image, b: &Image) -> Result<Image> {
    check_pair(a, b, "ssim_box3")?;
    let (w, h) = a.size();
    if w < 2 || h < 2 {
        return Err(RasterError::Shape(format!(
            "ssim_box3: a {w}x{h} image is too small for reflection padding"
        )));
    }
    let c = a.channels();
    let (c1, c2) = (K1 * K1, K2 * K2);
    let mut data = vec![0.0f32; w * h * c];
    data.par_chunks_mut(w * c).enumerate().for_each_init(
        || vec![[0.0f64; 5]; w * c],
        |col, (y, out)| {
            // Vertical 3-sums of the five moments for every (x, channel) of this row.
            col.iter_mut().for_each(|m| *m = [0.0; 5]);
            for dy in -1..=1isize {
                let yy = reflect_torch(y as isize + dy, h);
                for ((m, &va), &vb) in col.iter_mut().zip(a.row(yy)).zip(b.row(yy)) {
                    let (va, vb) = (va as f64, vb as f64);
                    m[0] += va;
                    m[1] += vb;
                    m[2] += va * va;
                    m[3] += vb * vb;
                    m[4] += va * vb;
                }
            }
            // Horizontal 3-sums, then SSIM.
            for x in 0..w {
                let xs = [-1isize, 0, 1].map(|dx| reflect_torch(x as isize + dx, w));
                for ch in 0..c {
                    let mut m = [0.0f64; 5];
                    for &xx in &xs {
                        let s = &col[xx * c + ch];
                        for (mq, sq) in m.iter_mut().zip(s) {
                            *mq += sq;
                        }
                    }
                    let m = m.map(|v| v / 9.0);
                    out[x * c + ch] = ssim_from_moments(&m, c1, c2, 1.0) as f32;
                }
            }
        },
    );
    Image::new(w, h, c, data)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Deterministic pseudo-random values in [0, 1) (64-bit LCG, top bits).
    fn noise(n: usize, seed: u64) -> Vec<f32> {
        let mut s = seed;
        (0..n)
            .map(|_| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (s >> 40) as f32 / (1u64 << 24) as f32
            })
            .collect()
    }

    /// Straightforward SSIM at one pixel: 11×11 loop, weights from the formula, reflection by
    /// repeated folding. Shares nothing with the separable implementation.
    fn naive_gaussian_at(a: &Image, b: &Image, x: usize, y: usize, ch: usize, l: f64) -> f64 {
        let (w, h) = (a.width() as i64, a.height() as i64);
        let fold = |mut i: i64, n: i64| loop {
            if i < 0 {
                i = -i - 1;
            } else if i >= n {
                i = 2 * n - 1 - i;
            } else {
                return i as usize;
            }
        };
        let mut wsum = 0.0;
        for dy in -5i64..=5 {
            for dx in -5i64..=5 {
                wsum += (-((dx * dx + dy * dy) as f64) / (2.0 * 1.5 * 1.5)).exp();
            }
        }
        let (mut ma, mut mb, mut maa, mut mbb, mut mab) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for dy in -5i64..=5 {
            for dx in -5i64..=5 {
                let wt = (-((dx * dx + dy * dy) as f64) / (2.0 * 1.5 * 1.5)).exp() / wsum;
                let xx = fold(x as i64 + dx, w);
                let yy = fold(y as i64 + dy, h);
                let va = a.get(xx, yy, ch) as f64;
                let vb = b.get(xx, yy, ch) as f64;
                ma += wt * va;
                mb += wt * vb;
                maa += wt * va * va;
                mbb += wt * vb * vb;
                mab += wt * va * vb;
            }
        }
        let (c1, c2) = ((0.01 * l) * (0.01 * l), (0.03 * l) * (0.03 * l));
        let (va, vb, cov) = (maa - ma * ma, mbb - mb * mb, mab - ma * mb);
        (2.0 * ma * mb + c1) * (2.0 * cov + c2) / ((ma * ma + mb * mb + c1) * (va + vb + c2))
    }

    #[test]
    fn identical_images_give_one() {
        let a = Image::new(16, 13, 3, noise(16 * 13 * 3, 7)).unwrap();
        let s = ssim_gaussian(&a, &a, 1.0).unwrap();
        assert!((s - 1.0).abs() < 1e-12, "{s}");
        let m = ssim_box3(&a, &a).unwrap();
        assert!(m.data().iter().all(|&v| (v - 1.0).abs() < 1e-6));
    }

    #[test]
    fn constant_images_closed_form() {
        let (c1v, c2v) = (0.3f32, 0.7f32);
        let a = Image::filled(12, 11, 1, c1v);
        let b = Image::filled(12, 11, 1, c2v);
        // Variances and covariance vanish: SSIM = (2 c1 c2 + C1) / (c1² + c2² + C1).
        for l in [1.0f32, 255.0] {
            let cc1 = (0.01 * l as f64).powi(2);
            let (x, y) = (c1v as f64, c2v as f64);
            let expected = (2.0 * x * y + cc1) / (x * x + y * y + cc1);
            let s = ssim_gaussian(&a, &b, l).unwrap();
            assert!((s - expected).abs() < 1e-9, "L={l}: {s} vs {expected}");
        }
        // L = 1: (0.42 + 1e-4) / (0.58 + 1e-4)
        let s = ssim_gaussian(&a, &b, 1.0).unwrap();
        assert!((s - 0.42010 / 0.58010).abs() < 1e-6);
        let bx = ssim_box3(&a, &b).unwrap();
        let expected = ((0.42010 / 0.58010) as f32, 1e-5);
        assert!(bx
            .data()
            .iter()
            .all(|&v| (v - expected.0).abs() < expected.1));
    }

    #[test]
    fn gaussian_matches_naive() {
        let (w, h, c) = (17, 14, 2);
        let a = Image::new(w, h, c, noise(w * h * c, 1)).unwrap();
        // b: a blurred / shifted, noisy copy so the score is far from 0 and 1.
        let nb = noise(w * h * c, 2);
        let bdata: Vec<f32> = a
            .data()
            .iter()
            .zip(&nb)
            .map(|(&v, &n)| 0.6 * v + 0.4 * n + 0.05)
            .collect();
        let b = Image::new(w, h, c, bdata).unwrap();
        let l = 1.0;
        let map = ssim_gaussian_map(&a, &b, l as f32).unwrap();
        let mut total = 0.0;
        for ch in 0..c {
            let mut s = 0.0;
            for y in 5..h - 5 {
                for x in 5..w - 5 {
                    s += naive_gaussian_at(&a, &b, x, y, ch, l);
                }
            }
            total += s / ((w - 10) * (h - 10)) as f64;
        }
        let expected = total / c as f64;
        let got = ssim_gaussian(&a, &b, l as f32).unwrap();
        assert!((got - expected).abs() < 1e-6, "{got} vs {expected}");
        assert!(
            expected > 0.2 && expected < 0.9,
            "test data too easy: {expected}"
        );
        // Border pixels of the map (reflected windows) too.
        for &(x, y) in &[(0, 0), (16, 13), (3, 9), (8, 0)] {
            for ch in 0..c {
                let e = naive_gaussian_at(&a, &b, x, y, ch, l);
                assert!(
                    (map.get(x, y, ch) as f64 - e).abs() < 1e-5,
                    "({x},{y},{ch})"
                );
            }
        }
        // Masked mean over the interior = the global score.
        let mask = Mask::from_fn(w, h, |x, y| {
            (5..w - 5).contains(&x) && (5..h - 5).contains(&y)
        });
        let m = ssim_gaussian_masked(&a, &b, &mask, 1.0).unwrap().unwrap();
        assert!((m - expected).abs() < 1e-6);
        assert_eq!(
            ssim_gaussian_masked(&a, &b, &Mask::filled(w, h, false), 1.0).unwrap(),
            None
        );
    }

    #[test]
    fn box3_by_hand() {
        // 3×3 images: at the centre the pool is the plain 3×3 mean, no padding involved.
        let av = [0.1f32, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9];
        let bv = [0.9f32, 0.1, 0.2, 0.3, 0.6, 0.5, 0.4, 0.8, 0.7];
        let a = Image::new(3, 3, 1, av.to_vec()).unwrap();
        let b = Image::new(3, 3, 1, bv.to_vec()).unwrap();
        let s = ssim_box3(&a, &b).unwrap();
        // Σa = 4.5, Σb = 4.5, Σa² = 2.85, Σb² = 2.85,
        // Σab = .09+.02+.06+.12+.30+.30+.28+.64+.63 = 2.44.
        let (ma, mb) = (0.5f64, 0.5f64);
        let (va, vb) = (2.85 / 9.0 - 0.25, 2.85 / 9.0 - 0.25);
        let cov = 2.44 / 9.0 - 0.25;
        let (c1, c2) = (1e-4, 9e-4);
        let expected =
            (2.0 * ma * mb + c1) * (2.0 * cov + c2) / ((ma * ma + mb * mb + c1) * (va + vb + c2));
        // = (0.5001 · 0.043122) / (0.5001 · 0.134233)
        assert!((expected - 0.321247).abs() < 1e-5, "{expected}");
        assert!((s.get(1, 1, 0) as f64 - expected).abs() < 1e-6);
        // Corner (0, 0): reflection padding picks rows/columns {1, 0, 1}.
        let idx = [1usize, 0, 1];
        let (mut sa, mut sb, mut saa, mut sbb, mut sab) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for &yy in &idx {
            for &xx in &idx {
                let (u, v) = (av[yy * 3 + xx] as f64, bv[yy * 3 + xx] as f64);
                sa += u;
                sb += v;
                saa += u * u;
                sbb += v * v;
                sab += u * v;
            }
        }
        let (ma, mb) = (sa / 9.0, sb / 9.0);
        let e0 = (2.0 * ma * mb + c1) * (2.0 * (sab / 9.0 - ma * mb) + c2)
            / ((ma * ma + mb * mb + c1) * (saa / 9.0 - ma * ma + sbb / 9.0 - mb * mb + c2));
        assert!(
            (s.get(0, 0, 0) as f64 - e0).abs() < 1e-6,
            "{} vs {e0}",
            s.get(0, 0, 0)
        );
    }

    #[test]
    fn errors_and_nan() {
        let a = Image::filled(12, 12, 1, 0.5);
        assert!(ssim_gaussian(&a, &Image::filled(12, 11, 1, 0.5), 1.0).is_err());
        assert!(ssim_gaussian(&a, &Image::filled(12, 12, 3, 0.5), 1.0).is_err());
        assert!(ssim_gaussian(
            &Image::filled(10, 12, 1, 0.5),
            &Image::filled(10, 12, 1, 0.5),
            1.0
        )
        .is_err());
        assert!(ssim_gaussian(&a, &a, 0.0).is_err());
        assert!(ssim_box3(&a, &Image::filled(11, 12, 1, 0.5)).is_err());
        assert!(ssim_box3(&Image::filled(1, 3, 1, 0.5), &Image::filled(1, 3, 1, 0.5)).is_err());
        let mut b = a.clone();
        b.set(0, 0, 0, f32::NAN);
        let m = ssim_box3(&a, &b).unwrap();
        assert!(m.get(1, 1, 0).is_nan());
        assert!(!m.get(2, 2, 0).is_nan());
    }

    /// SSIM at one pixel straight from the definition: 7×7 reflected window, sample
    /// covariances. Shares nothing with the separable implementation.
    fn naive_uniform_at(a: &Image, b: &Image, x: usize, y: usize, l: f64) -> f64 {
        let (w, h) = a.size();
        let mut va = Vec::new();
        let mut vb = Vec::new();
        for dy in -3..=3isize {
            for dx in -3..=3isize {
                let (xx, yy) = (
                    reflect_scipy(x as isize + dx, w),
                    reflect_scipy(y as isize + dy, h),
                );
                va.push(a.get(xx, yy, 0) as f64);
                vb.push(b.get(xx, yy, 0) as f64);
            }
        }
        let n = va.len() as f64;
        let ma = va.iter().sum::<f64>() / n;
        let mb = vb.iter().sum::<f64>() / n;
        let sa = va.iter().map(|v| (v - ma).powi(2)).sum::<f64>() / (n - 1.0);
        let sb = vb.iter().map(|v| (v - mb).powi(2)).sum::<f64>() / (n - 1.0);
        let sab = va
            .iter()
            .zip(&vb)
            .map(|(p, q)| (p - ma) * (q - mb))
            .sum::<f64>()
            / (n - 1.0);
        let (c1, c2) = ((0.01 * l).powi(2), (0.03 * l).powi(2));
        ((2.0 * ma * mb + c1) * (2.0 * sab + c2)) / ((ma * ma + mb * mb + c1) * (sa + sb + c2))
    }

    #[test]
    fn uniform_matches_the_definition_everywhere_including_borders() {
        let a = Image::from_fn(11, 9, |x, y| ((x * 37 + y * 91) % 255) as f32);
        let b = Image::from_fn(11, 9, |x, y| ((x * 13 + y * 7 + 40) % 200) as f32);
        let map = ssim_uniform_map(&a, &b, 255.0).unwrap();
        for y in 0..9 {
            for x in 0..11 {
                let want = naive_uniform_at(&a, &b, x, y, 255.0);
                assert!((map.get(x, y, 0) as f64 - want).abs() < 1e-5, "({x},{y})");
            }
        }
        let same = ssim_uniform_map(&a, &a, 255.0).unwrap();
        assert!(same.data().iter().all(|&v| (v - 1.0).abs() < 1e-6));
        let mask = Mask::from_fn(11, 9, |x, _| x < 3);
        let m = ssim_uniform_masked(&a, &b, &mask, 255.0).unwrap().unwrap();
        let want: f64 = (0..9)
            .flat_map(|y| (0..3).map(move |x| (x, y)))
            .map(|(x, y)| naive_uniform_at(&a, &b, x, y, 255.0))
            .sum::<f64>()
            / 27.0;
        assert!((m - want).abs() < 1e-5);
        assert!(
            ssim_uniform_masked(&a, &b, &Mask::filled(11, 9, false), 255.0)
                .unwrap()
                .is_none()
        );
        let small = Image::filled(6, 9, 1, 0.0);
        assert!(ssim_uniform_map(&small, &small, 255.0).is_err());
    }
}

//! Per-pixel features of the offline segmenter: colour, vegetation and water indices, and local
//! texture at two scales. Every feature is a plain function of the 8-bit RGB image, so the
//! classifier trained on the procedural world applies to any image of the same kind.

use raster::Image;
use rayon::prelude::*;

/// Number of features per pixel.
pub const FEATURES: usize = 12;

/// Feature names, for reports.
pub const NAMES: [&str; FEATURES] = [
    "red",
    "green",
    "blue",
    "brightness",
    "excess green",
    "blueness",
    "log local std 5x5",
    "log local std 15x15",
    "local contrast 15x15",
    "mean excess green 15x15",
    "log mean gradient 7x7",
    "mean blueness 15x15",
];

/// Means over `(2r+1)²` windows truncated at the borders (summed-area table).
pub(crate) fn box_mean(plane: &[f64], w: usize, h: usize, r: usize) -> Vec<f64> {
    let mut sat = vec![0.0f64; (w + 1) * (h + 1)];
    for y in 0..h {
        let mut row = 0.0;
        for x in 0..w {
            row += plane[y * w + x];
            sat[(y + 1) * (w + 1) + x + 1] = sat[y * (w + 1) + x + 1] + row;
        }
    }
    let mut out = vec![0.0; w * h];
    out.par_chunks_mut(w.max(1)).enumerate().for_each(|(y, o)| {
        let (y0, y1) = (y.saturating_sub(r), (y + r + 1).min(h));
        for (x, v) in o.iter_mut().enumerate() {
            let (x0, x1) = (x.saturating_sub(r), (x + r + 1).min(w));
            let s = sat[y1 * (w + 1) + x1] - sat[y0 * (w + 1) + x1] - sat[y1 * (w + 1) + x0]
                + sat[y0 * (w + 1) + x0];
            *v = s / ((y1 - y0) * (x1 - x0)) as f64;
        }
    });
    out
}

fn local_log_std(v: &[f64], v2: &[f64], w: usize, h: usize, r: usize) -> Vec<f64> {
    let m = box_mean(v, w, h, r);
    let m2 = box_mean(v2, w, h, r);
    m.iter()
        .zip(&m2)
        .map(|(a, b)| (b - a * a).max(0.0).sqrt().max(1e-3).ln())
        .collect()
}

/// Features of every pixel, pixel-major (`FEATURES` values per pixel), from RGB values 0–255
/// (grey images are repeated; NaN counts as 0).
pub fn pixel_features(image: &Image) -> Vec<[f64; FEATURES]> {
    let (w, h) = image.size();
    let c = image.channels();
    let n = w * h;
    let rgb: Vec<[f64; 3]> = image
        .data()
        .chunks_exact(c)
        .map(|p| {
            let g = |i: usize| {
                let v = p[i.min(c - 1).min(if c >= 3 { 2 } else { 0 })] as f64;
                if v.is_finite() {
                    v.clamp(0.0, 255.0) / 255.0
                } else {
                    0.0
                }
            };
            [g(0), g(1), g(2)]
        })
        .collect();
    let v: Vec<f64> = rgb.iter().map(|p| (p[0] + p[1] + p[2]) / 3.0).collect();
    let v2: Vec<f64> = v.iter().map(|a| a * a).collect();
    let exg: Vec<f64> = rgb.iter().map(|p| 2.0 * p[1] - p[0] - p[2]).collect();
    let blue: Vec<f64> = rgb.iter().map(|p| p[2] - 0.5 * (p[0] + p[1])).collect();
    let grad: Vec<f64> = (0..n)
        .map(|i| {
            let (x, y) = (i % w, i / w);
            let gx = v[y * w + (x + 1).min(w - 1)] - v[y * w + x.saturating_sub(1)];
            let gy = v[(y + 1).min(h - 1) * w + x] - v[y.saturating_sub(1) * w + x];
            (gx * gx + gy * gy).sqrt()
        })
        .collect();
    let std5 = local_log_std(&v, &v2, w, h, 2);
    let std15 = local_log_std(&v, &v2, w, h, 7);
    let mean15 = box_mean(&v, w, h, 7);
    let exg15 = box_mean(&exg, w, h, 7);
    let grad7 = box_mean(&grad, w, h, 3);
    let blue15 = box_mean(&blue, w, h, 7);
    (0..n)
        .map(|i| {
            [
                rgb[i][0],
                rgb[i][1],
                rgb[i][2],
                v[i],
                exg[i],
                blue[i],
                std5[i],
                std15[i],
                v[i] - mean15[i],
                exg15[i],
                grad7[i].max(1e-3).ln(),
                blue15[i],
            ]
        })
        .collect()
}

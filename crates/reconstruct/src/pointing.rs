//! Cameras as delivered: the pointing error of vendor RPCs removed and the scene's altitudes
//! found, from tie points between the images — before any tile is matched.
//!
//! A vendor RPC points a few to tens of pixels off, the same translation over the whole image.
//! Two such cameras put the rectified views' rows out of line, which no 1-D matcher survives, and
//! every pair of a many-date run at another height. This module:
//!
//! 1. reads a window of each image (the whole image up to [`MAX_TIE_SIDE`] pixels a side, else
//!    its centre), and picks its textured points ([`matching::tie::keypoints`]);
//! 2. for each pair to tie, resamples the second image onto the first through the cameras at
//!    one altitude, finds their coarse offset, then each point's match in a band along the
//!    parallax direction, refined to a fraction of a pixel ([`matching::tie`]);
//! 3. tracks the points over the images (a point of an image and its matches in every image it
//!    was tied to) and adjusts one translation per image by a robust bundle adjustment
//!    ([`camera::adjust`]);
//! 4. takes the scene's altitudes from the adjusted tie points (robust percentiles plus a
//!    margin).
//!
//! `reconstruct` adjusts its pair with the left camera fixed; `reconstruct-many` adjusts all
//! images at once (translations of mean zero) and writes the corrected cameras as RPC JSON.

use std::collections::HashMap;
use std::path::Path;

use anyhow::{bail, Context, Result};
use camera::{adjust_translations, AdjustParams, Gauge, ImageFit, Observation, RpcModel, Track};
use matching::tie::{downsample, global_shift, keypoints, TieSearch};
use raster::geometry::sample_bilinear;
use raster::Image;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::raw::RawImage;

/// The largest side of the window of an image searched for tie points, pixels: the pointing
/// error is one translation, so a central window tells it for the whole image.
pub const MAX_TIE_SIDE: usize = 2048;
/// Spacing of the tie points, pixels of the first image of a pair.
const TIE_SPACING: usize = 40;
/// Largest relative pointing error searched for, pixels (vendor RPCs of one area reach 40 px
/// each).
const MAX_POINTING_PX: f64 = 100.0;
/// The scene's ground is searched this far, metres, around the cameras' reference altitude.
const GROUND_SEARCH_M: f64 = 150.0;
/// Heights above and below the ground searched for each tie point, metres.
const ABOVE_GROUND_M: f64 = 120.0;
const BELOW_GROUND_M: f64 = 40.0;
/// Level of the per-point band search (pixels per coarse pixel) and its patch radius.
const BAND_LEVEL: usize = 4;
const BAND_RADIUS: usize = 3;
/// Patch radius and search radius of the full-resolution refinement.
const FINE_RADIUS: usize = 7;
/// Least ZNCC of a band match and of its refinement, and how far above the runner-up a band
/// match must score.
const MIN_BAND_SCORE: f32 = 0.5;
const MIN_FINE_SCORE: f32 = 0.6;
const MIN_BAND_MARGIN: f32 = 0.05;
/// Share of the adjusted tie points' altitudes cut off at each end, and the margin added to the
/// rest: metres plus a share of their span.
const ALT_PERCENTILE: f64 = 0.005;
/// Metres within which an altitude needs two other tie points' to count.
const ALT_NEIGHBOUR_M: f64 = 2.0;
/// The same for the points of a pair, seen twice each.
const PAIR_ALT_PERCENTILE: f64 = 0.03;
const ALT_MARGIN_M: f64 = 5.0;
const ALT_MARGIN_SHARE: f64 = 0.1;

/// Whether cameras are to be corrected: those that carry the scene's altitudes (`min_alt`/
/// `max_alt` of a SatNeRF/rpcm JSON: a curated, bundle-adjusted set such as SatNeRF's, or the
/// cameras `reconstruct-many` writes) are used as given; vendor cameras are corrected.
pub fn needs_adjustment<'a>(cameras: impl IntoIterator<Item = &'a RpcModel>) -> bool {
    cameras
        .into_iter()
        .any(|c| c.min_alt.is_none() || c.max_alt.is_none())
}

/// A camera leaves its image's tie points at most this far after the correction, pixels, RMS:
/// on the 45 dev pairs (vendor cameras) the line separates every pair with each image's camera
/// from every pair with the right camera of another image of the area (BENCHMARKS.md, "Images
/// as delivered", "A camera that does not fit").
pub const MAX_RESIDUAL_PX: f64 = 1.2;

/// A camera that no translation makes fit its image: an error of its own, never taken for a
/// failure to find tie points (which a run with known altitudes may go on without).
#[derive(Debug)]
pub struct Misfit(String);

impl std::fmt::Display for Misfit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for Misfit {}

/// Refuses a camera that no translation makes fit its image: `fit` of image `image`, whose
/// camera came from `camera` (a file, or the image's own tag).
pub fn check_fit(fit: &ImageFit, image: &Path, camera: &str) -> Result<()> {
    if fit.rms_px > MAX_RESIDUAL_PX {
        return Err(Misfit(format!(
            "the camera {camera} does not fit {}: after correcting its pointing, its {} tie points \
             still miss by {:.2} px RMS (a camera of this image leaves under {MAX_RESIDUAL_PX} px): \
             give the image its own camera (swapped with another image's?)",
            image.display(),
            fit.observations,
            fit.rms_px
        ))
        .into());
    }
    Ok(())
}

/// Where an image's camera came from, for the messages: the given file, the vendor sidecar
/// beside it, or its own RPC tag.
pub fn camera_source(image: &Path, given: Option<&Path>) -> String {
    match given
        .map(Path::to_path_buf)
        .or_else(|| camera::find_camera_file(image))
    {
        Some(p) => p.display().to_string(),
        None => format!("(the RPC tag of {})", image.display()),
    }
}

/// One image as the tie points see it: a grey window, where it lies in the image, its camera
/// and its textured points.
pub struct TieView {
    gray: Image,
    origin: (usize, usize),
    rpc: RpcModel,
    keypoints: Vec<(usize, usize)>,
}

impl TieView {
    /// Reads the tie window of `raw` (its centre when larger than [`MAX_TIE_SIDE`]).
    pub fn read(raw: &RawImage, rpc: &RpcModel) -> Result<TieView> {
        let (w, h) = raw.size();
        let (tw, th) = (w.min(MAX_TIE_SIDE), h.min(MAX_TIE_SIDE));
        let origin = ((w - tw) / 2, (h - th) / 2);
        let gray = raw
            .window(origin.0, origin.1, tw, th)
            .with_context(|| format!("reading tie points of {}", raw.path().display()))?
            .to_gray();
        let keypoints = keypoints(&gray, TIE_SPACING, FINE_RADIUS + 2);
        Ok(TieView {
            gray,
            origin,
            rpc: rpc.clone(),
            keypoints,
        })
    }
}

/// A tie point of view `a` (its keypoint index) found in view `b` at the raw pixel `(col, row)`.
#[derive(Clone, Copy, Debug)]
struct Tie {
    keypoint: usize,
    col: f64,
    row: f64,
}

/// The pixel of raw image `b` that sees what raw pixel `(x, y)` of `a` sees at altitude `alt`.
fn transfer(a: &RpcModel, b: &RpcModel, x: f64, y: f64, alt: f64) -> Option<(f64, f64)> {
    let (lon, lat) = a.localization(x, y, alt).ok()?;
    let p = b.projection(lon, lat, alt);
    (p.0.is_finite() && p.1.is_finite()).then_some(p)
}

/// `b`'s window resampled onto `a`'s through the cameras at altitude `alt` (the transfer
/// computed exactly on a 16-pixel lattice and interpolated between).
fn resample_onto(a: &TieView, b: &TieView, alt: f64) -> Image {
    const STEP: usize = 16;
    let (w, h) = a.gray.size();
    let (nx, ny) = (w / STEP + 2, h / STEP + 2);
    let lattice: Vec<Option<(f64, f64)>> = (0..nx * ny)
        .into_par_iter()
        .map(|k| {
            let (gx, gy) = ((k % nx) * STEP, (k / nx) * STEP);
            let (x, y) = ((a.origin.0 + gx) as f64, (a.origin.1 + gy) as f64);
            transfer(&a.rpc, &b.rpc, x, y, alt)
                .map(|(c, r)| (c - b.origin.0 as f64, r - b.origin.1 as f64))
        })
        .collect();
    let mut out = Image::filled(w, h, 1, f32::NAN);
    let mut v = [0.0f32];
    for y in 0..h {
        let (gy, fy) = (y / STEP, (y % STEP) as f64 / STEP as f64);
        for x in 0..w {
            let (gx, fx) = (x / STEP, (x % STEP) as f64 / STEP as f64);
            let corners = [
                lattice[gy * nx + gx],
                lattice[gy * nx + gx + 1],
                lattice[(gy + 1) * nx + gx],
                lattice[(gy + 1) * nx + gx + 1],
            ];
            let [Some(p00), Some(p10), Some(p01), Some(p11)] = corners else {
                continue;
            };
            let lerp = |a: f64, b: f64, c: f64, d: f64| {
                (1.0 - fy) * ((1.0 - fx) * a + fx * b) + fy * ((1.0 - fx) * c + fx * d)
            };
            let (bx, by) = (
                lerp(p00.0, p10.0, p01.0, p11.0),
                lerp(p00.1, p10.1, p01.1, p11.1),
            );
            if sample_bilinear(&b.gray, bx, by, &mut v) {
                out.set(x, y, 0, v[0]);
            }
        }
    }
    out
}

/// Pixels of `a` a point moves per metre of altitude when `b` is resampled onto `a` at `alt`,
/// at the centre of `a`'s window: `(dx, dy)`.
fn parallax_per_metre(a: &TieView, b: &TieView, alt: f64) -> Option<(f64, f64)> {
    let (w, h) = a.gray.size();
    let (cx, cy) = ((a.origin.0 + w / 2) as f64, (a.origin.1 + h / 2) as f64);
    const RISE: f64 = 10.0;
    let m = transfer(&a.rpc, &b.rpc, cx, cy, alt)?;
    let mx = transfer(&a.rpc, &b.rpc, cx + 1.0, cy, alt)?;
    let my = transfer(&a.rpc, &b.rpc, cx, cy + 1.0, alt)?;
    let (lon, lat) = a.rpc.localization(cx, cy, alt + RISE).ok()?;
    let m1 = b.rpc.projection(lon, lat, alt + RISE);
    // Solve J d = (m1 − m) with J = [mx − m, my − m] (columns).
    let (j00, j10, j01, j11) = (mx.0 - m.0, mx.1 - m.1, my.0 - m.0, my.1 - m.1);
    let (u, v) = (m1.0 - m.0, m1.1 - m.1);
    let det = j00 * j11 - j01 * j10;
    if det.is_nan() || det.abs() <= 1e-12 {
        return None;
    }
    Some((
        (j11 * u - j01 * v) / det / RISE,
        (j00 * v - j10 * u) / det / RISE,
    ))
}

/// The tie points of `a`'s keypoints in `b`.
fn tie_pair(a: &TieView, b: &TieView, alt: f64) -> Vec<Tie> {
    let warped = resample_onto(a, b, alt);
    let Some(e) = parallax_per_metre(a, b, alt) else {
        return Vec::new();
    };
    let k = e.0.hypot(e.1);
    // Coarse: the offset of the whole scene (pointing error plus the ground's parallax).
    let (w, h) = a.gray.size();
    let coarse = (w.min(h) / 64).clamp(1, 8);
    let radius = ((MAX_POINTING_PX + k * GROUND_SEARCH_M) / coarse as f64).ceil() as usize;
    let (ca, cb) = (downsample(&a.gray, coarse), downsample(&warped, coarse));
    let Some((gx, gy, _)) = global_shift(&ca, &cb, radius) else {
        return Vec::new();
    };
    let ground = ((gx * coarse as i32) as f64, (gy * coarse as i32) as f64);
    // Each point in a band along the parallax, at an intermediate level, then refined.
    let level = BAND_LEVEL.min(coarse).max(1);
    let (la, lb) = (downsample(&a.gray, level), downsample(&warped, level));
    let band = TieSearch {
        a: &la,
        b: &lb,
        radius: BAND_RADIUS,
    };
    let fine = TieSearch {
        a: &a.gray,
        b: &warped,
        radius: FINE_RADIUS,
    };
    let l = level as f64;
    let slack = coarse as f64;
    let along = (
        (-BELOW_GROUND_M * k - slack) / l,
        (ABOVE_GROUND_M * k + slack) / l,
    );
    let across = slack / l + 1.0;
    a.keypoints
        .par_iter()
        .enumerate()
        .filter_map(|(i, &(x, y))| {
            let m = band.band(
                (x / level, y / level),
                (ground.0 / l, ground.1 / l),
                e,
                along,
                across,
            )?;
            if m.score < MIN_BAND_SCORE || m.runner_up > m.score - MIN_BAND_MARGIN {
                return None;
            }
            let start = ((m.dx * l).round() as i32, (m.dy * l).round() as i32);
            let f = fine.refine((x, y), start, level as i32)?;
            if f.score < MIN_FINE_SCORE {
                return None;
            }
            let (wx, wy) = (
                (a.origin.0 + x) as f64 + f.dx,
                (a.origin.1 + y) as f64 + f.dy,
            );
            let (col, row) = transfer(&a.rpc, &b.rpc, wx, wy, alt)?;
            Some(Tie {
                keypoint: i,
                col,
                row,
            })
        })
        .collect()
}

/// What the adjustment found, for the logs and the reports.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Pointing {
    /// Per image: the translation added to its camera, pixels, and the residuals.
    pub images: Vec<ImageFit>,
    /// Pairs tied and the tie points each gave.
    pub pairs: Vec<(usize, usize, usize)>,
    /// Tracks adjusted, observations kept and rejected.
    pub tracks: usize,
    pub inliers: usize,
    pub outliers: usize,
    /// The scene's altitudes from the adjusted tie points, metres (robust percentiles and a
    /// margin).
    pub alt_range: (f64, f64),
    pub seconds: f64,
}

impl Pointing {
    /// The cameras with their translations applied.
    pub fn corrected(&self, cameras: &[RpcModel]) -> Vec<RpcModel> {
        cameras
            .iter()
            .zip(&self.images)
            .map(|(c, f)| c.translated(f.col_shift, f.row_shift))
            .collect()
    }
}

/// Ties the `pairs` of `views` (each pair's first view's points searched in the second), tracks
/// the points and adjusts one translation per view.
pub fn adjust_views(
    views: &[TieView],
    pairs: &[(usize, usize)],
    gauge: Gauge,
    alt: f64,
) -> Result<Pointing> {
    let start = std::time::Instant::now();
    let ties: Vec<Vec<Tie>> = pairs
        .par_iter()
        .map(|&(a, b)| tie_pair(&views[a], &views[b], alt))
        .collect();
    // A track per keypoint of a pair's first view: the point and its matches in every view.
    let mut tracks: HashMap<(usize, usize), Track> = HashMap::new();
    for (&(a, b), found) in pairs.iter().zip(&ties) {
        for t in found {
            let track = tracks.entry((a, t.keypoint)).or_insert_with(|| {
                let (x, y) = views[a].keypoints[t.keypoint];
                Track {
                    observations: vec![Observation {
                        image: a,
                        col: (views[a].origin.0 + x) as f64,
                        row: (views[a].origin.1 + y) as f64,
                    }],
                }
            });
            track.observations.push(Observation {
                image: b,
                col: t.col,
                row: t.row,
            });
        }
    }
    let mut keys: Vec<(usize, usize)> = tracks.keys().copied().collect();
    keys.sort_unstable();
    let tracks: Vec<Track> = keys.iter().map(|k| tracks[k].clone()).collect();
    let tied: Vec<(usize, usize, usize)> = pairs
        .iter()
        .zip(&ties)
        .map(|(&(a, b), t)| (a, b, t.len()))
        .collect();
    let seen: Vec<bool> = (0..views.len())
        .map(|i| tied.iter().any(|&(a, b, n)| n > 0 && (a == i || b == i)))
        .collect();
    if let Some(i) = seen.iter().position(|s| !s) {
        bail!(
            "no tie point found between image {} and the others: the images may not overlap, \
             or its camera points further off than {MAX_POINTING_PX} px",
            i + 1
        );
    }
    let cameras: Vec<RpcModel> = views.iter().map(|v| v.rpc.clone()).collect();
    let params = AdjustParams {
        gauge,
        ..AdjustParams::default()
    };
    let adjustment = adjust_translations(&cameras, &tracks, alt, params)
        .context("adjusting the cameras on the tie points")?;
    // Points seen three times and more when the set has them, else (a pair) every point, cut
    // harder at both ends: a point seen twice may sit anywhere along its parallax (a wrong match
    // there leaves no residual).
    let checked = adjustment.altitudes(3);
    let (altitudes, tail) = if checked.len() >= 100 {
        (checked, ALT_PERCENTILE)
    } else {
        (adjustment.altitudes(2), PAIR_ALT_PERCENTILE)
    };
    let alt_range = altitude_range(&altitudes, tail)
        .context("too few tie points to tell the scene's altitudes")?;
    Ok(Pointing {
        images: adjustment.images,
        pairs: tied,
        tracks: tracks.len(),
        inliers: adjustment.inliers,
        outliers: adjustment.outliers,
        alt_range,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// The tie points' altitudes between their `tail` and `1 − tail` quantiles, widened by a margin;
/// `None` with fewer than ten points. An altitude that no two others come within
/// [`ALT_NEIGHBOUR_M`] of is a lone mismatch along the parallax and is dropped first: the ground
/// and the roofs each gather many points.
pub fn altitude_range(altitudes: &[f64], tail: f64) -> Option<(f64, f64)> {
    let mut a: Vec<f64> = altitudes
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .collect();
    a.sort_by(f64::total_cmp);
    let near = |i: usize| {
        let lo = a.partition_point(|&v| v < a[i] - ALT_NEIGHBOUR_M);
        let hi = a.partition_point(|&v| v <= a[i] + ALT_NEIGHBOUR_M);
        hi - lo - 1
    };
    let a: Vec<f64> = (0..a.len())
        .filter(|&i| near(i) >= 2)
        .map(|i| a[i])
        .collect();
    if a.len() < 10 {
        return None;
    }
    let at = |q: f64| a[((a.len() - 1) as f64 * q).round() as usize];
    let (lo, hi) = (at(tail), at(1.0 - tail));
    let margin = ALT_MARGIN_M + ALT_MARGIN_SHARE * (hi - lo);
    Some((lo - margin, hi + margin))
}

/// Adjusts a pair (`left` fixed, the right camera translated) and finds the scene's altitudes.
pub fn adjust_pair(
    left: (&RawImage, &RpcModel),
    right: (&RawImage, &RpcModel),
    alt: f64,
) -> Result<Pointing> {
    let views = [
        TieView::read(left.0, left.1)?,
        TieView::read(right.0, right.1)?,
    ];
    adjust_views(&views, &[(0, 1)], Gauge::Fixed(0), alt)
}

/// One line per image for the log: its translation and residuals.
pub fn describe(pointing: &Pointing, names: &[String]) -> Vec<String> {
    pointing
        .images
        .iter()
        .zip(names)
        .map(|(f, name)| {
            format!(
                "{name}: pointing corrected by ({:+.2}, {:+.2}) px (col, row); {} tie points, \
                 residual {:.2} px (was {:.2})",
                f.col_shift, f.row_shift, f.observations, f.rms_px, f.rms_before_px
            )
        })
        .collect()
}

/// Writes a corrected camera as a SatNeRF/rpcm JSON: the RPC, the scene's altitudes, the
/// acquisition's date and sun when known, and the correction applied.
pub fn write_camera_json(
    path: &Path,
    rpc: &RpcModel,
    fit: &ImageFit,
    alt_range: (f64, f64),
    date: Option<&str>,
    sun: Option<(f64, f64)>,
) -> Result<()> {
    let mut value = serde_json::json!({
        "rpc": rpc.to_rpcm_json(),
        "min_alt": alt_range.0,
        "max_alt": alt_range.1,
        "pointing_correction": fit,
    });
    if let Some(d) = date {
        value["acquisition_date"] = d.into();
    }
    if let Some((el, az)) = sun {
        value["sun_elevation"] = el.into();
        value["sun_azimuth"] = az.into();
    }
    workflow::stage::write_json(path, &value)
}

/// The pairs tied in a many-date set, each `(anchor, other)`: the anchor's points are searched
/// in the other, and a point found in several others is one track over all of them.
///
/// Tracks seen by two images only leave the translations along each pair's parallax free (the
/// altitude takes them): images must share tracks of three and more, over the whole set. So
/// every image is tied to two hubs (the images at the first and third quarters of the dates),
/// whose points thus reach every image, and to its nearest neighbour in date (the pair that
/// ties best). `days[i]` is image `i`'s date (unknown: as if in the order given); `overlap(i,
/// j)` whether two footprints meet.
pub fn tie_pairs(
    days: &[Option<f64>],
    overlap: impl Fn(usize, usize) -> bool,
) -> Vec<(usize, usize)> {
    let n = days.len();
    let day = |i: usize| days[i].unwrap_or(i as f64);
    let mut by_date: Vec<usize> = (0..n).collect();
    by_date.sort_by(|&a, &b| day(a).total_cmp(&day(b)).then(a.cmp(&b)));
    let mut hubs: Vec<usize> = [n / 4, (3 * n) / 4]
        .iter()
        .map(|&k| by_date[k.min(n.saturating_sub(1))])
        .collect();
    hubs.dedup();
    let mut chosen: Vec<(usize, usize)> = Vec::new();
    let add = |a: usize, b: usize, chosen: &mut Vec<(usize, usize)>| {
        let known = chosen
            .iter()
            .any(|&(x, y)| (x, y) == (a, b) || (x, y) == (b, a));
        if a != b && !known && overlap(a, b) {
            chosen.push((a, b));
        }
    };
    for &h in &hubs {
        for i in 0..n {
            add(h, i, &mut chosen);
        }
    }
    for i in 0..n {
        let nearest = (0..n)
            .filter(|&j| j != i && overlap(i, j))
            .min_by(|&a, &b| (day(a) - day(i)).abs().total_cmp(&(day(b) - day(i)).abs()));
        if let Some(j) = nearest {
            add(i.min(j), i.max(j), &mut chosen);
        }
    }
    chosen
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tie_pairs_reach_every_image_from_two_hubs_and_its_nearest_date() {
        let days = [
            Some(0.0),
            Some(5.0),
            Some(200.0),
            Some(203.0),
            Some(400.0),
            Some(410.0),
        ];
        let pairs = tie_pairs(&days, |_, _| true);
        // Hubs: the images at the first and third quarters of the dates, 1 and 4.
        for i in [0, 2, 3, 5] {
            assert!(
                pairs.contains(&(1, i)) && pairs.contains(&(4, i)),
                "{i}: {pairs:?}"
            );
        }
        assert!(
            pairs.contains(&(2, 3)) && pairs.contains(&(4, 5)),
            "{pairs:?}"
        );
        let mut unique = pairs.clone();
        unique.sort_unstable();
        unique.dedup();
        assert_eq!(unique.len(), pairs.len());
        assert_eq!(tie_pairs(&days, |_, _| false), vec![]);
    }

    #[test]
    fn altitudes_drop_the_extremes_and_keep_a_margin() {
        let mut a: Vec<f64> = (0..1000).map(|i| i as f64 / 10.0).collect();
        // Lone mismatches beyond the ends are dropped whatever the quantile.
        a.extend([5000.0, -300.0, 400.0]);
        let (lo, hi) = altitude_range(&a, 0.0).unwrap();
        assert!(lo < 0.0 - 5.0 && lo > -20.0, "{lo}");
        assert!(hi > 100.0 + 5.0 && hi < 120.0, "{hi}");
        assert!(altitude_range(&a[..5], 0.005).is_none());
    }
}

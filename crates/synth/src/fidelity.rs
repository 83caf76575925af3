//! Geometry-fidelity check of a generated image against its real source.
//!
//! A seasonal variant is only useful if the teacher disparity of the real pair still holds for
//! it, i.e. if it registers to its source at zero disparity, edge for edge. Colours may change
//! completely (snow on a dark field, red foliage), so the check compares *structure*: both images
//! are turned into normalised gradient-magnitude maps (the colour gradient norm `g` mapped
//! through `g / (g + k)`, `k` the image's own 70th percentile of `g`, so strong and moderate
//! edges weigh alike whatever their contrast). Then:
//! - **registration**: the integer shift maximising the normalised cross-correlation (NCC) of the
//!   two maps over ±`search_radius` px, refined to sub-pixel by a parabola through the peak and
//!   its neighbours; it must be below `max_shift_px` (the whole image moved);
//! - **edge score**: the NCC of the two maps at zero shift: blurring, warping or hallucinated
//!   structures lower it even when the global shift is zero;
//! - **sharpness**: the ratio of the variant's to the source's detail (mean |Laplacian| over mean
//!   |gradient| of the grey image, a contrast-free measure); blurring lowers it;
//! - **tiles**: the same registration on tiles of `tile_size` px with enough structure; a share of
//!   misaligned tiles above `max_misaligned_tile_share` reveals local warps.

use std::fmt;

use raster::Image;

use crate::SynthError;

/// Thresholds of [`check`].
#[derive(Clone, Debug, PartialEq)]
pub struct FidelityParams {
    /// Largest accepted global shift (Euclidean norm, px).
    pub max_shift_px: f64,
    /// Half-width of the integer shift search (px).
    pub search_radius: usize,
    /// Smallest accepted edge score (NCC of the structure maps at zero shift).
    pub min_edge_score: f64,
    /// Smallest accepted sharpness ratio (variant / source).
    pub min_sharpness_ratio: f64,
    /// Tile side for the local registration (px); images smaller than two tiles skip it.
    pub tile_size: usize,
    /// A tile is misaligned when its shift reaches this many px.
    pub max_tile_shift_px: f64,
    /// Largest accepted share of misaligned tiles.
    pub max_misaligned_tile_share: f64,
}

impl Default for FidelityParams {
    fn default() -> Self {
        Self {
            max_shift_px: 0.5,
            search_radius: 3,
            min_edge_score: 0.5,
            min_sharpness_ratio: 0.7,
            tile_size: 64,
            max_tile_shift_px: 1.0,
            max_misaligned_tile_share: 0.1,
        }
    }
}

/// Measured alignment of a variant with its source.
#[derive(Clone, Debug, PartialEq)]
pub struct FidelityReport {
    /// Global shift of the variant relative to the source (variant(x + shift) ≈ source(x)), px.
    pub shift_x: f64,
    pub shift_y: f64,
    /// NCC of the structure maps at the best integer shift.
    pub peak_ncc: f64,
    /// NCC of the structure maps at zero shift.
    pub edge_score: f64,
    /// Detail of the variant relative to the source (1 = as sharp, < 1 softer).
    pub sharpness_ratio: f64,
    /// Tiles with enough structure to register, and how many of them are misaligned.
    pub tiles_checked: usize,
    pub tiles_misaligned: usize,
    /// Largest tile shift found (px).
    pub worst_tile_shift: f64,
    /// Whether every criterion holds.
    pub passed: bool,
    /// One line per failed criterion (empty when passed).
    pub failures: Vec<String>,
}

impl FidelityReport {
    /// Norm of the global shift, px.
    pub fn shift(&self) -> f64 {
        self.shift_x.hypot(self.shift_y)
    }
}

impl fmt::Display for FidelityReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}: shift ({:+.2}, {:+.2}) px, edge score {:.3}, sharpness {:.2}, {}/{} tiles misaligned (worst {:.2} px)",
            if self.passed { "passed" } else { "REJECTED" },
            self.shift_x,
            self.shift_y,
            self.edge_score,
            self.sharpness_ratio,
            self.tiles_misaligned,
            self.tiles_checked,
            self.worst_tile_shift
        )?;
        if !self.failures.is_empty() {
            write!(f, " [{}]", self.failures.join("; "))?;
        }
        Ok(())
    }
}

/// Checks that `variant` keeps the geometry of `source` (same size, any channel count).
pub fn check(
    source: &Image,
    variant: &Image,
    params: &FidelityParams,
) -> Result<FidelityReport, SynthError> {
    source.check_same_size(variant, "generated variant vs its source")?;
    let (w, h) = source.size();
    let r = params.search_radius;
    if w < 2 * r + 8 || h < 2 * r + 8 {
        return Err(SynthError::Input(format!(
            "fidelity check needs an image larger than {0}x{0} px, got {w}x{h}",
            2 * r + 8
        )));
    }
    let a = Structure::of(source);
    let b = Structure::of(variant);
    if a.valid == 0 || b.valid == 0 {
        return Err(SynthError::Input(
            "fidelity check: one of the images has no valid (finite) pixels".into(),
        ));
    }
    let whole = Rect {
        x0: r + 1,
        y0: r + 1,
        x1: w - r - 1,
        y1: h - r - 1,
    };
    let global = register(&a, &b, whole, r);
    let edge_score = ncc(&a, &b, whole, 0, 0).unwrap_or(0.0);
    let sharpness_ratio = match (sharpness(source), sharpness(variant)) {
        (Some(s), Some(v)) if s > 0.0 => v / s,
        _ => 1.0,
    };

    let tiles = tile_shifts(&a, &b, (w, h), params);
    let (shift_x, shift_y, peak_ncc) = global
        .as_ref()
        .map_or((f64::NAN, f64::NAN, 0.0), |g| (g.dx, g.dy, g.peak));
    let mut report = FidelityReport {
        shift_x,
        shift_y,
        peak_ncc,
        edge_score,
        sharpness_ratio,
        tiles_checked: tiles.checked,
        tiles_misaligned: tiles.misaligned,
        worst_tile_shift: tiles.worst,
        passed: false,
        failures: Vec::new(),
    };
    report.failures = failed_criteria(&report, global.is_some(), params);
    report.passed = report.failures.is_empty();
    Ok(report)
}

/// How the tiles of an image register on their own: a local warp moves some tiles while the
/// whole image stays in place.
struct TileShifts {
    /// Tiles with enough structure to register.
    checked: usize,
    /// Of those, the tiles shifted by at least `max_tile_shift_px`.
    misaligned: usize,
    /// Largest tile shift, px.
    worst: f64,
}

/// Registers each tile of the `(w, h)` structure maps (none when the image is under two tiles
/// wide or high).
fn tile_shifts(
    a: &Structure,
    b: &Structure,
    (w, h): (usize, usize),
    params: &FidelityParams,
) -> TileShifts {
    let r = params.search_radius;
    let mut tiles = TileShifts {
        checked: 0,
        misaligned: 0,
        worst: 0.0,
    };
    let t = params.tile_size.max(4 * r + 8);
    if w < 2 * t || h < 2 * t {
        return tiles;
    }
    for ty in 0..h / t {
        for tx in 0..w / t {
            let rect = Rect {
                x0: (tx * t).max(r + 1),
                y0: (ty * t).max(r + 1),
                x1: ((tx + 1) * t).min(w - r - 1),
                y1: ((ty + 1) * t).min(h - r - 1),
            };
            if !a.has_structure(rect) {
                continue;
            }
            let Some(reg) = register(a, b, rect, r) else {
                continue;
            };
            tiles.checked += 1;
            let s = reg.dx.hypot(reg.dy);
            tiles.worst = tiles.worst.max(s);
            if s >= params.max_tile_shift_px {
                tiles.misaligned += 1;
            }
        }
    }
    tiles
}

/// One line per criterion the measurements of `report` fail (`registered`: whether the whole
/// images overlapped enough to register).
fn failed_criteria(
    report: &FidelityReport,
    registered: bool,
    params: &FidelityParams,
) -> Vec<String> {
    let mut failures = Vec::new();
    if !registered {
        failures.push("no overlap of valid pixels to register".to_string());
    }
    let shift = report.shift();
    if shift.is_finite() && shift >= params.max_shift_px {
        failures.push(format!(
            "moved by {shift:.2} px (limit {:.2})",
            params.max_shift_px
        ));
    }
    let edge_score = report.edge_score;
    if edge_score < params.min_edge_score {
        failures.push(format!(
            "edges disagree: score {edge_score:.3} < {:.3}",
            params.min_edge_score
        ));
    }
    let sharpness_ratio = report.sharpness_ratio;
    if sharpness_ratio < params.min_sharpness_ratio {
        failures.push(format!(
            "blurred: sharpness ratio {sharpness_ratio:.2} < {:.2}",
            params.min_sharpness_ratio
        ));
    }
    let (checked, misaligned) = (report.tiles_checked, report.tiles_misaligned);
    if checked > 0 && misaligned as f64 / checked as f64 > params.max_misaligned_tile_share {
        failures.push(format!(
            "locally warped: {misaligned} of {checked} tiles shifted by ≥ {:.2} px",
            params.max_tile_shift_px
        ));
    }
    failures
}

/// Mean |4-neighbour Laplacian| over mean |central-difference gradient| of the grey image: how
/// much of the structure is fine detail, whatever the contrast. `None` on a flat image.
fn sharpness(image: &Image) -> Option<f64> {
    let grey = image.to_gray();
    let (w, h) = grey.size();
    let (mut lap, mut grad) = (0f64, 0f64);
    for y in 1..h.saturating_sub(1) {
        for x in 1..w - 1 {
            let p = |dx: isize, dy: isize| {
                f64::from(grey.get((x as isize + dx) as usize, (y as isize + dy) as usize, 0))
            };
            let l = 4.0 * p(0, 0) - p(-1, 0) - p(1, 0) - p(0, -1) - p(0, 1);
            let g = 0.5 * ((p(1, 0) - p(-1, 0)).abs() + (p(0, 1) - p(0, -1)).abs());
            if l.is_finite() && g.is_finite() {
                lap += l.abs();
                grad += g;
            }
        }
    }
    (grad > 0.0).then(|| lap / grad)
}

/// Half-open pixel rectangle `[x0, x1) × [y0, y1)`.
#[derive(Clone, Copy, Debug)]
struct Rect {
    x0: usize,
    y0: usize,
    x1: usize,
    y1: usize,
}

/// Normalised gradient-magnitude map (NaN where undefined).
struct Structure {
    width: usize,
    values: Vec<f32>,
    valid: usize,
}

impl Structure {
    fn of(image: &Image) -> Self {
        let (w, h) = image.size();
        let c = image.channels();
        let data = image.data();
        let mut g = vec![f32::NAN; w * h];
        for y in 1..h.saturating_sub(1) {
            for x in 1..w - 1 {
                let mut sum = 0.0f32;
                for k in 0..c {
                    let p = |dx: isize, dy: isize| {
                        data[((y as isize + dy) as usize * w + (x as isize + dx) as usize) * c + k]
                    };
                    let gx = (p(1, -1) + 2.0 * p(1, 0) + p(1, 1))
                        - (p(-1, -1) + 2.0 * p(-1, 0) + p(-1, 1));
                    let gy = (p(-1, 1) + 2.0 * p(0, 1) + p(1, 1))
                        - (p(-1, -1) + 2.0 * p(0, -1) + p(1, -1));
                    sum += gx * gx + gy * gy;
                }
                g[y * w + x] = sum.sqrt();
            }
        }
        let mut finite: Vec<f32> = g.iter().copied().filter(|v| v.is_finite()).collect();
        let valid = finite.len();
        let k = if finite.is_empty() {
            1.0
        } else {
            let i = (finite.len() * 7 / 10).min(finite.len() - 1);
            let (_, kth, _) = finite.select_nth_unstable_by(i, f32::total_cmp);
            kth.max(1e-6)
        };
        for v in &mut g {
            *v /= *v + k;
        }
        Self {
            width: w,
            values: g,
            valid,
        }
    }

    fn at(&self, x: usize, y: usize) -> f32 {
        self.values[y * self.width + x]
    }

    /// Enough edges to register: at least 5 % of the tile above 0.6 (strong edges).
    fn has_structure(&self, r: Rect) -> bool {
        let mut strong = 0usize;
        for y in r.y0..r.y1 {
            for x in r.x0..r.x1 {
                strong += usize::from(self.at(x, y) > 0.6);
            }
        }
        strong * 20 >= (r.x1 - r.x0) * (r.y1 - r.y0)
    }
}

/// NCC of `a` over `rect` with `b` shifted by `(dx, dy)`; `None` without enough valid pairs or
/// without variance.
fn ncc(a: &Structure, b: &Structure, rect: Rect, dx: isize, dy: isize) -> Option<f64> {
    let (mut n, mut sa, mut sb, mut saa, mut sbb, mut sab) = (0usize, 0f64, 0f64, 0f64, 0f64, 0f64);
    for y in rect.y0..rect.y1 {
        let yb = (y as isize + dy) as usize;
        for x in rect.x0..rect.x1 {
            let (p, q) = (a.at(x, y), b.at((x as isize + dx) as usize, yb));
            if p.is_finite() && q.is_finite() {
                let (p, q) = (f64::from(p), f64::from(q));
                n += 1;
                sa += p;
                sb += q;
                saa += p * p;
                sbb += q * q;
                sab += p * q;
            }
        }
    }
    if n < 16 {
        return None;
    }
    let nf = n as f64;
    let cov = sab - sa * sb / nf;
    let va = saa - sa * sa / nf;
    let vb = sbb - sb * sb / nf;
    (va > 1e-12 && vb > 1e-12).then(|| cov / (va * vb).sqrt())
}

struct Registration {
    dx: f64,
    dy: f64,
    peak: f64,
}

/// Best shift of `b` against `a` over `rect` within ±`r`, refined to sub-pixel.
fn register(a: &Structure, b: &Structure, rect: Rect, r: usize) -> Option<Registration> {
    let side = 2 * r + 1;
    let ri = r as isize;
    let mut scores = vec![f64::NEG_INFINITY; side * side];
    let mut best: Option<(usize, usize)> = None;
    for j in 0..side {
        for i in 0..side {
            if let Some(s) = ncc(a, b, rect, i as isize - ri, j as isize - ri) {
                scores[j * side + i] = s;
                if best.is_none_or(|(bi, bj)| s > scores[bj * side + bi]) {
                    best = Some((i, j));
                }
            }
        }
    }
    let (i, j) = best?;
    let peak = scores[j * side + i];
    let refine = |l: f64, c: f64, r: f64| {
        let denom = l - 2.0 * c + r;
        if l.is_finite() && r.is_finite() && denom < 0.0 {
            (0.5 * (l - r) / denom).clamp(-0.5, 0.5)
        } else {
            0.0
        }
    };
    let score = |i: usize, j: usize| scores[j * side + i];
    let fx = if i > 0 && i + 1 < side {
        refine(score(i - 1, j), peak, score(i + 1, j))
    } else {
        0.0
    };
    let fy = if j > 0 && j + 1 < side {
        refine(score(i, j - 1), peak, score(i, j + 1))
    } else {
        0.0
    };
    Some(Registration {
        dx: i as f64 - r as f64 + fx,
        dy: j as f64 - r as f64 + fy,
        peak,
    })
}

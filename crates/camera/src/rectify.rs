//! Stereo rectification of a satellite pair from its cameras.
//!
//! Over a region of interest a pushbroom camera is very nearly affine, so the epipolar geometry of
//! the pair is that of two affine cameras: an affine fundamental matrix
//! `F = [[0, 0, a], [0, 0, b], [c, d, e]]` with `a x₂ + b y₂ + c x₁ + d y₁ + e = 0` for every
//! match `(x₁, y₁) ↔ (x₂, y₂)`. The rectification follows the classical satellite recipe:
//!
//! 1. [`matches_from_cameras`]: a grid of points of the left region of interest is localised on
//!    the ground at several altitudes with the left camera and projected into the right image,
//!    giving exact virtual matches whose altitude is known;
//! 2. [`affine_fundamental`]: `F` by the Gold Standard for affine cameras (orthogonal regression
//!    on the centred matches, Hartley & Zisserman §14.3);
//! 3. [`rectifying_similarities`]: one rotation per image that makes the epipolar lines
//!    horizontal, and a vertical zoom and offset that put matching lines on the same row;
//! 4. [`rectifying_homographies`]: a left/right flip when needed so that disparity (`x_L − x_R`)
//!    grows with altitude, a horizontal shift of the right image so that the lowest altitude has a
//!    small positive disparity, and a common translation so that the rectified frame starts at the
//!    region of interest (with a left margin as wide as the largest disparity, so that every pixel
//!    of the region has its match inside the frame).
//!
//! [`rectify_pair`] chains all of it and warps both raw images into the common frame. The
//! disparity search range comes from the cameras and an altitude range ([`disparity_range`]), not
//! from image matches, which miss tall buildings on multi-date pairs.
//!
//! Homographies map RAW image coordinates to RECTIFIED coordinates, as `Hleft`/`Hright` of the
//! public release do; pixel centres are at integer coordinates.

use raster::geometry::warp_homography;
use raster::{Homography, Image};

use crate::RpcModel;

/// A match between the left and the right raw images: `((x_L, y_L), (x_R, y_R))`, in pixels.
pub type Match = ((f64, f64), (f64, f64));

/// Points per side of the grid of the region of interest that [`matches_from_cameras`] localises.
pub const GRID_POINTS: usize = 11;
/// Altitudes, evenly spaced over the altitude range (both ends included), at which each grid
/// point is localised.
pub const GRID_ALTITUDES: usize = 5;
/// Disparity, in pixels, given to the lowest point of the altitude range by the horizontal shift
/// of the right image: strictly positive, so that the benchmark's `d > 0` filter keeps it.
pub const LOWEST_DISPARITY: f64 = 2.0;

/// A camera that maps the ground to its image and back. Longitude/latitude are whatever planar or
/// geographic coordinates the camera uses (degrees for RPCs); altitudes are metres.
pub trait Camera {
    /// Image point `(col, row)` of the ground point `(lon, lat, alt)`.
    fn project(&self, lon: f64, lat: f64, alt: f64) -> (f64, f64);
    /// Ground point `(lon, lat)` at altitude `alt` seen at `(col, row)`.
    fn localize(&self, col: f64, row: f64, alt: f64) -> (f64, f64);
}

/// RPC cameras: rpcm's projection and localisation (a point whose localisation does not converge
/// comes out as NaN, and [`matches_from_cameras`] skips it).
impl Camera for RpcModel {
    fn project(&self, lon: f64, lat: f64, alt: f64) -> (f64, f64) {
        self.projection(lon, lat, alt)
    }
    fn localize(&self, col: f64, row: f64, alt: f64) -> (f64, f64) {
        self.localization(col, row, alt)
            .unwrap_or((f64::NAN, f64::NAN))
    }
}

impl<C: Camera + ?Sized> Camera for &C {
    fn project(&self, lon: f64, lat: f64, alt: f64) -> (f64, f64) {
        (**self).project(lon, lat, alt)
    }
    fn localize(&self, col: f64, row: f64, alt: f64) -> (f64, f64) {
        (**self).localize(col, row, alt)
    }
}

/// What can go wrong while rectifying.
#[derive(Debug, thiserror::Error)]
pub enum RectifyError {
    /// An affine fundamental matrix has 4 degrees of freedom.
    #[error("{0} matches are too few to estimate an affine fundamental matrix (at least 4 are needed, in general position)")]
    TooFewMatches(usize),
    /// The matches do not determine the epipolar geometry (collinear points, a single plane of the
    /// scene, identical cameras, …).
    #[error("degenerate configuration: {0}")]
    Degenerate(String),
    /// A parameter is out of its domain (empty region, region outside the image, bad range).
    #[error("{0}")]
    Invalid(String),
    /// Warping the images failed.
    #[error(transparent)]
    Raster(#[from] raster::RasterError),
}

/// Result type of this module.
pub type Result<T, E = RectifyError> = std::result::Result<T, E>;

/// A region of interest of the left raw image: `width × height` pixels from `(x, y)`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Roi {
    pub x: usize,
    pub y: usize,
    pub width: usize,
    pub height: usize,
}

impl Roi {
    pub fn new(x: usize, y: usize, width: usize, height: usize) -> Self {
        Roi {
            x,
            y,
            width,
            height,
        }
    }

    /// The whole `width × height` image.
    pub fn full(width: usize, height: usize) -> Self {
        Roi::new(0, 0, width, height)
    }

    /// The centres of the four corner pixels.
    pub fn corners(&self) -> [(f64, f64); 4] {
        let (x0, y0) = (self.x as f64, self.y as f64);
        let (x1, y1) = (
            x0 + self.width.saturating_sub(1) as f64,
            y0 + self.height.saturating_sub(1) as f64,
        );
        [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
    }

    /// An error unless the region is non-empty and inside a `width × height` image.
    pub fn check_inside(&self, width: usize, height: usize) -> Result<()> {
        if self.width == 0 || self.height == 0 {
            return Err(RectifyError::Invalid(format!(
                "the region of interest {self} is empty"
            )));
        }
        if self.x + self.width > width || self.y + self.height > height {
            return Err(RectifyError::Invalid(format!(
                "the region of interest {self} does not fit in the {width}x{height} left image"
            )));
        }
        Ok(())
    }
}

impl std::fmt::Display for Roi {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "x={}, y={}, {}x{}",
            self.x, self.y, self.width, self.height
        )
    }
}

/// A virtual match made by the cameras: the ground point and its two images.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GroundMatch {
    /// `(lon, lat, alt)`.
    pub ground: (f64, f64, f64),
    /// Its image in the left raw image.
    pub left: (f64, f64),
    /// Its image in the right raw image.
    pub right: (f64, f64),
}

impl GroundMatch {
    /// The image pair alone.
    pub fn pair(&self) -> Match {
        (self.left, self.right)
    }

    /// The altitude of the ground point.
    pub fn alt(&self) -> f64 {
        self.ground.2
    }
}

fn check_alt_range(alt_range: (f64, f64)) -> Result<()> {
    let (lo, hi) = alt_range;
    if !(lo.is_finite() && hi.is_finite() && lo < hi) {
        return Err(RectifyError::Invalid(format!(
            "the altitude range must be finite with MIN < MAX, got {lo}:{hi}"
        )));
    }
    Ok(())
}

/// Virtual matches of the left region of interest, the s2p way: a [`GRID_POINTS`]² grid of the
/// region, each point localised with the left camera at [`GRID_ALTITUDES`] altitudes spanning
/// `alt_range` (metres, `MIN < MAX`), then projected with both cameras (the left projection is
/// recomputed so that an inexact localisation cannot bias the match). Points that a camera cannot
/// map (non-finite result) are skipped.
pub fn matches_from_cameras(
    left: &impl Camera,
    right: &impl Camera,
    roi: Roi,
    alt_range: (f64, f64),
) -> Result<Vec<GroundMatch>> {
    check_alt_range(alt_range)?;
    if roi.width == 0 || roi.height == 0 {
        return Err(RectifyError::Invalid(format!(
            "the region of interest {roi} is empty"
        )));
    }
    let [(x0, y0), _, (x1, y1), _] = roi.corners();
    let lerp = |a: f64, b: f64, i: usize, n: usize| a + (b - a) * i as f64 / (n - 1) as f64;
    let mut out = Vec::with_capacity(GRID_POINTS * GRID_POINTS * GRID_ALTITUDES);
    for k in 0..GRID_ALTITUDES {
        let alt = lerp(alt_range.0, alt_range.1, k, GRID_ALTITUDES);
        for j in 0..GRID_POINTS {
            let row = lerp(y0, y1, j, GRID_POINTS);
            for i in 0..GRID_POINTS {
                let col = lerp(x0, x1, i, GRID_POINTS);
                let (lon, lat) = left.localize(col, row, alt);
                let l = left.project(lon, lat, alt);
                let r = right.project(lon, lat, alt);
                if [lon, lat, l.0, l.1, r.0, r.1].iter().all(|v| v.is_finite()) {
                    out.push(GroundMatch {
                        ground: (lon, lat, alt),
                        left: l,
                        right: r,
                    });
                }
            }
        }
    }
    Ok(out)
}

/// [`matches_from_cameras`] for a pair of RPC cameras.
pub fn matches_from_rpcs(
    rpc_left: &RpcModel,
    rpc_right: &RpcModel,
    roi: Roi,
    alt_range: (f64, f64),
) -> Result<Vec<GroundMatch>> {
    matches_from_cameras(rpc_left, rpc_right, roi, alt_range)
}

/// The affine fundamental matrix `[[0, 0, a], [0, 0, b], [c, d, e]]` of the matches, such that
/// `(x_R, y_R, 1) F (x_L, y_L, 1)ᵀ = a x_R + b y_R + c x_L + d y_L + e ≈ 0`, by the Gold Standard
/// for affine cameras (Hartley & Zisserman, algorithm 14.1): `(a, b, c, d)` is the direction of
/// least variance of the centred 4-vectors `(x_R, y_R, x_L, y_L)` (unit norm), and `e` puts the
/// centroid on the hyperplane. This minimises the geometric distance of the matches to the
/// epipolar geometry under isotropic pixel noise.
///
/// Errors: fewer than 4 matches, non-finite coordinates, and degenerate configurations where the
/// direction of least variance is not unique (all points on a line or a plane of the scene, i.e.
/// the matches are explained by an affinity) or does not define epipolar lines in both images.
pub fn affine_fundamental(matches: &[Match]) -> Result<[[f64; 3]; 3]> {
    let n = matches.len();
    if n < 4 {
        return Err(RectifyError::TooFewMatches(n));
    }
    let rows: Vec<[f64; 4]> = matches
        .iter()
        .map(|&((xl, yl), (xr, yr))| [xr, yr, xl, yl])
        .collect();
    if rows.iter().flatten().any(|v| !v.is_finite()) {
        return Err(RectifyError::Invalid(
            "a match has a non-finite coordinate".into(),
        ));
    }
    let mut mean = [0.0; 4];
    for r in &rows {
        for (m, v) in mean.iter_mut().zip(r) {
            *m += v / n as f64;
        }
    }
    let mut cov = [[0.0; 4]; 4];
    for r in &rows {
        let c: [f64; 4] = std::array::from_fn(|i| r[i] - mean[i]);
        for i in 0..4 {
            for j in 0..4 {
                cov[i][j] += c[i] * c[j];
            }
        }
    }
    let (values, vectors) = symmetric_eigen4(cov);
    let mut order = [0usize, 1, 2, 3];
    order.sort_by(|&i, &j| values[j].total_cmp(&values[i]));
    let largest = values[order[0]].max(0.0);
    if largest <= 0.0 {
        return Err(RectifyError::Degenerate(
            "all matches are the same point".into(),
        ));
    }
    // The centred data must span a 3-dimensional subspace exactly: a second (near-)null direction
    // means that the matches are explained by an affinity and the epipolar lines are undetermined.
    let second_smallest = values[order[2]];
    if second_smallest <= 1e-10 * largest {
        return Err(RectifyError::Degenerate(format!(
            "the matches span fewer than 3 dimensions (variances {:.3e}, {:.3e}, {:.3e}, {:.3e}): \
             they lie on a line or follow an affinity (e.g. a single altitude), which leaves the \
             epipolar geometry undetermined",
            values[order[0]], values[order[1]], values[order[2]], values[order[3]]
        )));
    }
    let v: [f64; 4] = std::array::from_fn(|i| vectors[i][order[3]]);
    let (a, b, c, d) = (v[0], v[1], v[2], v[3]);
    if a.hypot(b) < 1e-9 || c.hypot(d) < 1e-9 {
        return Err(RectifyError::Degenerate(format!(
            "the estimated epipolar geometry does not constrain both images \
             (a, b, c, d = {a:.3e}, {b:.3e}, {c:.3e}, {d:.3e})"
        )));
    }
    let e = -(0..4).map(|i| v[i] * mean[i]).sum::<f64>();
    Ok([[0.0, 0.0, a], [0.0, 0.0, b], [c, d, e]])
}

/// Eigen-decomposition of a symmetric 4×4 matrix by cyclic Jacobi rotations: the eigenvalues and
/// the matrix whose COLUMNS are the unit eigenvectors.
fn symmetric_eigen4(mut a: [[f64; 4]; 4]) -> ([f64; 4], [[f64; 4]; 4]) {
    let mut v = [[0.0; 4]; 4];
    for (i, row) in v.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    for _sweep in 0..100 {
        let off: f64 = (0..4)
            .flat_map(|i| (0..4).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| a[i][j] * a[i][j])
            .sum();
        let diag: f64 = (0..4).map(|i| a[i][i] * a[i][i]).sum();
        if off <= 1e-30 * diag || off == 0.0 {
            break;
        }
        for p in 0..3 {
            for q in p + 1..4 {
                if a[p][q] == 0.0 {
                    continue;
                }
                let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for row in a.iter_mut() {
                    let (akp, akq) = (row[p], row[q]);
                    row[p] = c * akp - s * akq;
                    row[q] = s * akp + c * akq;
                }
                let (row_p, row_q) = (a[p], a[q]);
                for k in 0..4 {
                    a[p][k] = c * row_p[k] - s * row_q[k];
                    a[q][k] = s * row_p[k] + c * row_q[k];
                }
                for row in v.iter_mut() {
                    let (vkp, vkq) = (row[p], row[q]);
                    row[p] = c * vkp - s * vkq;
                    row[q] = s * vkp + c * vkq;
                }
            }
        }
    }
    ([a[0][0], a[1][1], a[2][2], a[3][3]], v)
}

/// The rectifying similarities of an affine fundamental matrix (the s2p construction): a rotation
/// of each image that makes its epipolar lines horizontal, a zoom `z = √(r/s)` of the left image
/// and `1/z` of the right one (`r = |(c, d)|`, `s = |(a, b)|`) so both share one scale, and
/// opposite vertical offsets `±e / (2√(rs))` so that matching epipolar lines land on the same
/// row: `y'_L − y'_R = (a x_R + b y_R + c x_L + d y_L + e) / √(rs)`.
///
/// `F` is only defined up to sign; the sign is chosen so that the left rotation is within ±90° of
/// the identity. No flip and no horizontal alignment yet: see [`rectifying_homographies`].
pub fn rectifying_similarities(f: &[[f64; 3]; 3]) -> Result<(Homography, Homography)> {
    let (mut a, mut b, mut c, mut d, mut e) = (f[0][2], f[1][2], f[2][0], f[2][1], f[2][2]);
    let r = c.hypot(d);
    let s = a.hypot(b);
    let scale = r.max(s);
    if !(r.is_finite() && s.is_finite() && e.is_finite())
        || r <= 1e-12 * scale
        || s <= 1e-12 * scale
    {
        return Err(RectifyError::Degenerate(format!(
            "not an affine fundamental matrix with epipolar lines in both images: {f:?}"
        )));
    }
    if d < 0.0 || (d == 0.0 && c < 0.0) {
        (a, b, c, d, e) = (-a, -b, -c, -d, -e);
    }
    let z = (r / s).sqrt();
    let t = 0.5 * e / (r * s).sqrt();
    let (zl, zr) = (z / r, 1.0 / (z * s));
    let left = Homography([[zl * d, -zl * c, 0.0], [zl * c, zl * d, t], [0.0, 0.0, 1.0]]);
    let right = Homography([
        [-zr * b, zr * a, 0.0],
        [-zr * a, -zr * b, -t],
        [0.0, 0.0, 1.0],
    ]);
    Ok((left, right))
}

/// Disparities `x'_L − x'_R` of the matches through the homographies, paired with altitudes.
fn disparities(h_left: &Homography, h_right: &Homography, ground: &[GroundMatch]) -> Vec<f64> {
    ground
        .iter()
        .map(|g| h_left.apply(g.left.0, g.left.1).0 - h_right.apply(g.right.0, g.right.1).0)
        .collect()
}

/// Whether the right rectified image is sheared to level the ground ([`level_shear`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Shear {
    /// One altitude, one disparity: the search range is the altitudes' alone (the default).
    #[default]
    Level,
    /// The rectifying similarities only: the ground's disparity may tilt across the frame.
    None,
}

/// The horizontal shear of the right rectified image, `x_R' = (1 + s)·x_R + t·y`, after which a
/// ground altitude has one disparity over the whole region: the least-squares plane
/// `d = a·x_L + b·y + γ·alt + c` of the camera matches loses its `a` and `b`. Rows stay rows; the
/// disparity range is then what the altitudes span, not that plus the tilt of the ground's
/// disparity across the frame (tens of pixels on a 1000-pixel tile of a narrow pair), which every
/// matcher would otherwise search. s2p shears its right image for the same reason. The identity
/// when the matches do not determine the plane.
fn level_shear(hl: &Homography, hr: &Homography, ground: &[GroundMatch]) -> Homography {
    let d = disparities(hl, hr, ground);
    let rows: Vec<[f64; 3]> = ground
        .iter()
        .map(|g| {
            let (x, y) = hl.apply(g.left.0, g.left.1);
            [x, y, g.alt()]
        })
        .collect();
    let n = rows.len() as f64;
    let mean: [f64; 3] = std::array::from_fn(|i| rows.iter().map(|r| r[i]).sum::<f64>() / n);
    let d_mean = d.iter().sum::<f64>() / n;
    let (mut m, mut v) = ([[0.0; 3]; 3], [0.0; 3]);
    for (r, di) in rows.iter().zip(&d) {
        let c: [f64; 3] = std::array::from_fn(|i| r[i] - mean[i]);
        for i in 0..3 {
            v[i] += c[i] * (di - d_mean);
            for j in 0..3 {
                m[i][j] += c[i] * c[j];
            }
        }
    }
    let identity = Homography([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]);
    let Some([a, b, _]) = solve3(m, v) else {
        return identity;
    };
    if !(a.is_finite() && b.is_finite()) || (1.0 - a).abs() < 0.5 {
        return identity;
    }
    // d' = d − s·x_R − t·y with x_R = x_L − d: no x_L or y term when s = a / (1 − a), t = b / (1 − a).
    let (s, t) = (a / (1.0 - a), b / (1.0 - a));
    Homography([[1.0 + s, t, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
}

/// The solution of the 3×3 system `m·x = v` (Cramer's rule); `None` when `m` is singular.
fn solve3(m: [[f64; 3]; 3], v: [f64; 3]) -> Option<[f64; 3]> {
    let det = |m: &[[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det(&m);
    let scale = m.iter().flatten().fold(0.0f64, |a, b| a.max(b.abs()));
    if !(d.is_finite() && d.abs() > 1e-12 * scale.powi(3)) {
        return None;
    }
    Some(std::array::from_fn(|k| {
        let mut mk = m;
        for (row, vi) in mk.iter_mut().zip(&v) {
            row[k] = *vi;
        }
        det(&mk) / d
    }))
}

/// A rectification of a pair: the homographies (raw → rectified, flip included), the rectified
/// frame and what the cameras say about it.
#[derive(Clone, Debug, PartialEq)]
pub struct Rectification {
    /// Left raw → rectified.
    pub h_left: Homography,
    /// Right raw → rectified.
    pub h_right: Homography,
    /// Inclusive disparity range `[MIN, MAX]` of the altitude range over the region of interest
    /// (see [`disparity_range`]); `MIN ≥ 1`.
    pub disparity_range: (i32, i32),
    /// `(width, height)` of the rectified frame.
    pub size: (usize, usize),
    /// Where the region of interest lies in the frame: `(x, y, width, height)` of the bounding box
    /// of its image by `h_left`, integer-aligned.
    pub roi_in_frame: (usize, usize, usize, usize),
    /// Whether x was flipped so that disparity grows with altitude.
    pub flipped: bool,
    /// Largest `|y'_L − y'_R|` over the camera matches, pixels: how far the pair is from the affine
    /// model over the region (the accuracy of the rectification, before any pointing error).
    pub max_row_error: f64,
    /// Disparity per metre of altitude, pixels (positive).
    pub pixels_per_metre: f64,
    /// How many times the frame is stretched along the rows ([`Rectification::stretched`]; 1:
    /// not stretched): one rectified pixel along a row is `1 / stretch` raw pixels.
    pub stretch: f64,
}

impl Rectification {
    /// The same rectification with the rectified frame stretched `zoom` times along the rows
    /// (epipolar lines): disparities come in steps of `1 / zoom` raw pixels, which keeps the
    /// height per disparity step small on narrow baselines. Rows are unchanged.
    pub fn stretched(&self, zoom: f64) -> Rectification {
        let s = Homography([[zoom, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]);
        let (lo, hi) = self.disparity_range;
        let (x, y, w, h) = self.roi_in_frame;
        Rectification {
            h_left: s.compose(&self.h_left),
            h_right: s.compose(&self.h_right),
            disparity_range: (
                ((lo as f64 * zoom).floor() as i32).max(1),
                (hi as f64 * zoom).ceil() as i32,
            ),
            size: ((self.size.0 as f64 * zoom).ceil() as usize, self.size.1),
            roi_in_frame: (
                (x as f64 * zoom).floor() as usize,
                y,
                (w as f64 * zoom).ceil() as usize,
                h,
            ),
            flipped: self.flipped,
            max_row_error: self.max_row_error,
            pixels_per_metre: self.pixels_per_metre * zoom,
            stretch: self.stretch * zoom,
        }
    }
}

/// The inclusive integer disparity range `[floor(min) − 1, ceil(max) + 1]` of the camera matches
/// through the homographies (`d = x'_L − x'_R`). An error when no match is given.
pub fn disparity_range_of_matches(
    h_left: &Homography,
    h_right: &Homography,
    ground: &[GroundMatch],
) -> Result<(i32, i32)> {
    let d = disparities(h_left, h_right, ground);
    let lo = d.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = d.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if !(lo.is_finite() && hi.is_finite()) {
        return Err(RectifyError::TooFewMatches(0));
    }
    Ok(((lo.floor() - 1.0) as i32, (hi.ceil() + 1.0) as i32))
}

/// The disparity range in a rectified frame implied by the cameras and an altitude range (metres):
/// the extreme disparities of [`matches_from_cameras`] over the region of interest (grid points ×
/// altitudes from `MIN` to `MAX`), widened by one pixel each side. The altitude range is what the
/// user knows (the `min_alt`/`max_alt` of a SatNeRF JSON, the RPCs' altitude offset ± scale, or a
/// value of their own): a range estimated from image matches misses tall buildings on
/// multi-date pairs, where matches are few.
pub fn disparity_range(
    left: &impl Camera,
    right: &impl Camera,
    h_left: &Homography,
    h_right: &Homography,
    roi: Roi,
    alt_range: (f64, f64),
) -> Result<(i32, i32)> {
    let ground = matches_from_cameras(left, right, roi, alt_range)?;
    disparity_range_of_matches(h_left, h_right, &ground)
}

/// The rectifying homographies of a pair from its affine fundamental matrix and camera matches
/// with known altitudes (from [`matches_from_cameras`], at two altitudes at least):
///
/// 1. the [`rectifying_similarities`] of `f`;
/// 2. a flip of x in both images when disparity `x'_L − x'_R` decreases with altitude (fitted
///    over all matches), so that it grows with altitude;
/// 3. with [`Shear::Level`], a horizontal shear of the right image after which one altitude
///    has one disparity over the region ([`level_shear`]);
/// 4. a horizontal shift of the right image that gives the lowest disparity of the matches the
///    value [`LOWEST_DISPARITY`];
/// 5. a common integer translation (it changes neither rows nor disparities) that puts the
///    bounding box of the region of interest's image at `(D, 0)`, `D = max(0, MAX)` of the
///    disparity range, so that every pixel of the region finds its match, `D` pixels to its left at
///    most, inside the frame.
pub fn rectifying_homographies(
    f: &[[f64; 3]; 3],
    ground: &[GroundMatch],
    roi: Roi,
    shear: Shear,
) -> Result<Rectification> {
    if ground.len() < 2 {
        return Err(RectifyError::TooFewMatches(ground.len()));
    }
    if roi.width == 0 || roi.height == 0 {
        return Err(RectifyError::Invalid(format!(
            "the region of interest {roi} is empty"
        )));
    }
    let (mut hl, mut hr) = rectifying_similarities(f)?;

    // Slope of disparity against altitude, by least squares.
    let alts: Vec<f64> = ground.iter().map(GroundMatch::alt).collect();
    let n = alts.len() as f64;
    let alt_mean = alts.iter().sum::<f64>() / n;
    let sxx: f64 = alts.iter().map(|a| (a - alt_mean) * (a - alt_mean)).sum();
    if sxx.is_nan() || sxx <= 0.0 {
        return Err(RectifyError::Degenerate(
            "the camera matches are all at one altitude: the disparity direction is undetermined"
                .into(),
        ));
    }
    let slope_of = |hl: &Homography, hr: &Homography| {
        let d = disparities(hl, hr, ground);
        let d_mean = d.iter().sum::<f64>() / n;
        let sxy: f64 = alts
            .iter()
            .zip(&d)
            .map(|(a, di)| (a - alt_mean) * (di - d_mean))
            .sum();
        sxy / sxx
    };
    let mut slope = slope_of(&hl, &hr);
    if !slope.is_finite() || slope == 0.0 {
        return Err(RectifyError::Degenerate(
            "disparity does not change with altitude: the two views have the same direction (no \
             stereo baseline)"
                .into(),
        ));
    }
    let flipped = slope < 0.0;
    if flipped {
        let flip = Homography([[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]);
        hl = flip.compose(&hl);
        hr = flip.compose(&hr);
    }
    if shear == Shear::Level {
        hr = level_shear(&hl, &hr, ground).compose(&hr);
        slope = slope_of(&hl, &hr);
    }

    // Relative horizontal shift: the lowest disparity becomes LOWEST_DISPARITY.
    let d_low = disparities(&hl, &hr, ground)
        .into_iter()
        .fold(f64::INFINITY, f64::min);
    hr = Homography::translation(d_low - LOWEST_DISPARITY, 0.0).compose(&hr);
    let range = disparity_range_of_matches(&hl, &hr, ground)?;

    // The frame: the region of interest's bounding box, with a left margin of MAX pixels.
    let corners = roi.corners().map(|(x, y)| hl.apply(x, y));
    let x0 = corners.iter().map(|p| p.0).fold(f64::INFINITY, f64::min);
    let x1 = corners
        .iter()
        .map(|p| p.0)
        .fold(f64::NEG_INFINITY, f64::max);
    let y0 = corners.iter().map(|p| p.1).fold(f64::INFINITY, f64::min);
    let y1 = corners
        .iter()
        .map(|p| p.1)
        .fold(f64::NEG_INFINITY, f64::max);
    let margin = range.1.max(0) as f64;
    let (bx, by) = (x0.floor(), y0.floor());
    let t = Homography::translation(margin - bx, -by);
    hl = t.compose(&hl);
    hr = t.compose(&hr);
    let roi_w = (x1.ceil() - bx) as usize + 1;
    let roi_h = (y1.ceil() - by) as usize + 1;
    let size = (roi_w + margin as usize, roi_h);

    let mut max_row_error = 0.0f64;
    for g in ground {
        let dy = hl.apply(g.left.0, g.left.1).1 - hr.apply(g.right.0, g.right.1).1;
        max_row_error = max_row_error.max(dy.abs());
    }
    Ok(Rectification {
        h_left: hl,
        h_right: hr,
        disparity_range: range,
        size,
        roi_in_frame: (margin as usize, 0, roi_w, roi_h),
        flipped,
        max_row_error,
        pixels_per_metre: slope.abs(),
        stretch: 1.0,
    })
}

/// A rectified pair: both images warped into a common frame where epipolar lines are rows and
/// disparity `x_L − x_R` is positive and grows with altitude.
#[derive(Clone, Debug)]
pub struct RectifiedPair {
    /// Left image in the rectified frame; NaN outside the raw image.
    pub left: Image,
    /// Right image in the rectified frame; NaN outside the raw image.
    pub right: Image,
    /// Left raw → rectified.
    pub h_left: Homography,
    /// Right raw → rectified.
    pub h_right: Homography,
    /// Inclusive disparity search range implied by the cameras and the altitude range.
    pub disparity_range: (i32, i32),
    /// `(width, height)` of both rectified images.
    pub size: (usize, usize),
    /// The full geometry (frame, flip, accuracy).
    pub rectification: Rectification,
}

/// Warps `image` through `h` into a `size` frame, NaN where the source point is outside it.
pub fn warp_nan(image: &Image, h: &Homography, size: (usize, usize)) -> Result<Image> {
    let (mut out, mask) = warp_homography(image, h, size.0, size.1)?;
    let c = out.channels();
    for (px, &valid) in out.data_mut().chunks_exact_mut(c).zip(mask.data()) {
        if !valid {
            px.fill(f32::NAN);
        }
    }
    Ok(out)
}

/// The rectification of a pair over a region of interest of the left raw image, from its cameras
/// and an altitude range (metres, `MIN < MAX`; it should contain every altitude of the scene: the
/// disparity search range is derived from it). Both images are warped with bilinear
/// interpolation into the common frame of [`rectifying_homographies`]; pixels outside a raw image
/// are NaN, so the matcher ignores them.
pub fn rectify_pair(
    left: &Image,
    right: &Image,
    left_camera: &impl Camera,
    right_camera: &impl Camera,
    roi: Roi,
    alt_range: (f64, f64),
) -> Result<RectifiedPair> {
    let rect = rectification(left_camera, right_camera, roi, alt_range)?;
    roi.check_inside(left.width(), left.height())?;
    let (l, r) = rayon::join(
        || warp_nan(left, &rect.h_left, rect.size),
        || warp_nan(right, &rect.h_right, rect.size),
    );
    Ok(RectifiedPair {
        left: l?,
        right: r?,
        h_left: rect.h_left,
        h_right: rect.h_right,
        disparity_range: rect.disparity_range,
        size: rect.size,
        rectification: rect,
    })
}

/// The geometry of [`rectify_pair`] without warping any image: camera matches, affine
/// fundamental matrix, rectifying homographies (ground levelled) and frame.
pub fn rectification(
    left_camera: &impl Camera,
    right_camera: &impl Camera,
    roi: Roi,
    alt_range: (f64, f64),
) -> Result<Rectification> {
    rectification_with(left_camera, right_camera, roi, alt_range, Shear::Level)
}

/// [`rectification`] with the right image's shear chosen.
pub fn rectification_with(
    left_camera: &impl Camera,
    right_camera: &impl Camera,
    roi: Roi,
    alt_range: (f64, f64),
    shear: Shear,
) -> Result<Rectification> {
    let ground = matches_from_cameras(left_camera, right_camera, roi, alt_range)?;
    let pairs: Vec<Match> = ground.iter().map(GroundMatch::pair).collect();
    let f = affine_fundamental(&pairs)?;
    rectifying_homographies(&f, &ground, roi, shear)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jacobi_diagonalises() {
        let m = [
            [4.0, 1.0, 0.5, 0.0],
            [1.0, 3.0, 0.2, 0.1],
            [0.5, 0.2, 2.0, 0.3],
            [0.0, 0.1, 0.3, 1.0],
        ];
        let (vals, vecs) = symmetric_eigen4(m);
        for k in 0..4 {
            for i in 0..4 {
                let mv: f64 = (0..4).map(|j| m[i][j] * vecs[j][k]).sum();
                assert!((mv - vals[k] * vecs[i][k]).abs() < 1e-12);
            }
        }
    }
}

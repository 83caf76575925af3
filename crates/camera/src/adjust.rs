//! Bundle adjustment of RPC cameras by one image-space translation each.
//!
//! # Why
//!
//! A vendor RPC points a few pixels to tens of pixels off; the error of a modern satellite
//! camera is, to a small fraction of a pixel, the same translation at every point of the image
//! (Marí et al., IPOL 2021; SatNeRF's bundle-adjusted cameras differ from the vendor ones by
//! exactly that). Given tie points tracked over several images, this module finds one
//! `(Δcol, Δrow)` per image and one ground point per track that minimise the reprojection
//! errors, robustly:
//!
//! ```text
//!   min  Σ_tracks Σ_obs  ρ(‖ x_obs − (P_image(X_track) + t_image) ‖)
//! ```
//!
//! with `ρ` Huber's loss, solved by Gauss–Newton on the reduced camera system (the ground
//! points eliminated track by track, their 3×3 blocks inverted), outliers rejected between
//! rounds. Translations are defined up to a common one (a common shift of every image is
//! nearly a shift of the ground): the gauge is fixed by [`Gauge`].
//!
//! Ground points are `(lon, lat, alt)` but solved for in metres (east, north, up) so that the
//! system is well scaled.

use crate::{CameraError, Result, RpcModel};

/// One observation of a track: image index and pixel (col, row) in that image.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Observation {
    pub image: usize,
    pub col: f64,
    pub row: f64,
}

/// The images' views of one ground point (at least two images).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Track {
    pub observations: Vec<Observation>,
}

/// How the common translation of all images is fixed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Gauge {
    /// The translations sum to zero: no image is privileged.
    MeanZero,
    /// This image keeps its camera.
    Fixed(usize),
}

/// Parameters of [`adjust_translations`].
#[derive(Clone, Copy, Debug)]
pub struct AdjustParams {
    pub gauge: Gauge,
    /// Residuals beyond this many pixels weigh less (Huber's threshold).
    pub huber_px: f64,
    /// An observation whose residual exceeds `max(reject_floor_px, 5 · 1.4826 · MAD)` after a
    /// round is dropped, and the adjustment solved again.
    pub reject_floor_px: f64,
    pub rounds: usize,
    pub iterations: usize,
}

impl Default for AdjustParams {
    fn default() -> Self {
        AdjustParams {
            gauge: Gauge::MeanZero,
            huber_px: 0.5,
            reject_floor_px: 1.5,
            rounds: 3,
            iterations: 15,
        }
    }
}

/// The fit of one image.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ImageFit {
    /// The translation to add to the camera's image coordinates, pixels.
    pub col_shift: f64,
    pub row_shift: f64,
    /// Inlier observations of the image and their root-mean-square residual, pixels.
    pub observations: usize,
    pub rms_px: f64,
    /// Root-mean-square residual of the same observations before the adjustment, pixels.
    pub rms_before_px: f64,
}

/// What [`adjust_translations`] found.
#[derive(Clone, Debug)]
pub struct Adjustment {
    pub images: Vec<ImageFit>,
    /// `(lon, lat, alt)` of every track kept, `None` for a rejected one.
    pub points: Vec<Option<[f64; 3]>>,
    /// Observations kept of every track.
    pub views: Vec<usize>,
    /// Observations kept and rejected.
    pub inliers: usize,
    pub outliers: usize,
}

impl Adjustment {
    /// The altitudes of the kept tracks seen by at least `views` images, metres (a point seen
    /// twice has no check on its altitude: a match off along the parallax moves it unseen).
    pub fn altitudes(&self, views: usize) -> Vec<f64> {
        self.points
            .iter()
            .zip(&self.views)
            .filter(|(_, v)| **v >= views)
            .filter_map(|(p, _)| p.map(|p| p[2]))
            .collect()
    }
}

impl RpcModel {
    /// The same camera with `(col_shift, row_shift)` added to every image point it projects.
    pub fn translated(&self, col_shift: f64, row_shift: f64) -> RpcModel {
        let mut rpc = self.clone();
        rpc.col_offset += col_shift;
        rpc.row_offset += row_shift;
        rpc
    }
}

/// Metres per degree of latitude (a local tangent plane is all the solver needs).
const METRES_PER_DEGREE: f64 = 111_320.0;

/// A ground point in metres around a reference (lon, lat): the solver's unknowns.
#[derive(Clone, Copy)]
struct Frame {
    lon0: f64,
    lat0: f64,
    east: f64,
    north: f64,
}

impl Frame {
    fn new(lon0: f64, lat0: f64) -> Self {
        Frame {
            lon0,
            lat0,
            east: METRES_PER_DEGREE * lat0.to_radians().cos(),
            north: METRES_PER_DEGREE,
        }
    }
    fn metres_of(self, lon: f64, lat: f64, alt: f64) -> [f64; 3] {
        [
            (lon - self.lon0) * self.east,
            (lat - self.lat0) * self.north,
            alt,
        ]
    }
    fn ground_of(self, m: [f64; 3]) -> [f64; 3] {
        [
            self.lon0 + m[0] / self.east,
            self.lat0 + m[1] / self.north,
            m[2],
        ]
    }
}

/// Projection of a point in metres through camera `rpc` shifted by `t`, with its 2×3 Jacobian
/// (forward differences of 0.5 m: the RPC is smooth at that scale).
fn project(frame: &Frame, rpc: &RpcModel, t: [f64; 2], x: [f64; 3]) -> ([f64; 2], [[f64; 3]; 2]) {
    let at = |m: [f64; 3]| {
        let g = frame.ground_of(m);
        let (c, r) = rpc.projection(g[0], g[1], g[2]);
        [c + t[0], r + t[1]]
    };
    let p = at(x);
    let mut j = [[0.0; 3]; 2];
    const STEP: f64 = 0.5;
    for k in 0..3 {
        let mut a = x;
        a[k] += STEP;
        let pa = at(a);
        j[0][k] = (pa[0] - p[0]) / STEP;
        j[1][k] = (pa[1] - p[1]) / STEP;
    }
    (p, j)
}

fn huber_weight(r: f64, k: f64) -> f64 {
    if r <= k {
        1.0
    } else {
        k / r
    }
}

/// Solves `a x = b` (n×n, row-major) by Gaussian elimination with partial pivoting; `None` if
/// singular.
fn solve_dense(mut a: Vec<f64>, mut b: Vec<f64>) -> Option<Vec<f64>> {
    let n = b.len();
    for col in 0..n {
        let pivot =
            (col..n).max_by(|&i, &j| a[i * n + col].abs().total_cmp(&a[j * n + col].abs()))?;
        if a[pivot * n + col].abs() < 1e-300 {
            return None;
        }
        if pivot != col {
            for k in 0..n {
                a.swap(pivot * n + k, col * n + k);
            }
            b.swap(pivot, col);
        }
        for i in col + 1..n {
            let f = a[i * n + col] / a[col * n + col];
            if f != 0.0 {
                for k in col..n {
                    a[i * n + k] -= f * a[col * n + k];
                }
                b[i] -= f * b[col];
            }
        }
    }
    let mut x = vec![0.0; n];
    for i in (0..n).rev() {
        let s: f64 = (i + 1..n).map(|k| a[i * n + k] * x[k]).sum();
        x[i] = (b[i] - s) / a[i * n + i];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// Inverse of a symmetric 3×3 matrix, `None` when (nearly) singular.
fn invert3(m: [[f64; 3]; 3]) -> Option<[[f64; 3]; 3]> {
    let c = |i: usize, j: usize| {
        let (i1, i2) = ((i + 1) % 3, (i + 2) % 3);
        let (j1, j2) = ((j + 1) % 3, (j + 2) % 3);
        m[i1][j1] * m[i2][j2] - m[i1][j2] * m[i2][j1]
    };
    let det = m[0][0] * c(0, 0) + m[0][1] * c(0, 1) + m[0][2] * c(0, 2);
    let scale = m[0][0].abs() + m[1][1].abs() + m[2][2].abs();
    if det.is_nan() || det.abs() <= 1e-12 * scale * scale * scale {
        return None;
    }
    let mut inv = [[0.0; 3]; 3];
    for (i, row) in inv.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = c(j, i) / det;
        }
    }
    Some(inv)
}

fn mat3_vec(m: &[[f64; 3]; 3], v: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|i| m[i][0] * v[0] + m[i][1] * v[1] + m[i][2] * v[2])
}

/// One observation's part of the normal equations: image, weight, Jacobian, residual.
type Term = (usize, f64, [[f64; 3]; 2], [f64; 2]);

/// The state of the adjustment.
struct Problem<'a> {
    cameras: &'a [RpcModel],
    tracks: &'a [Track],
    frame: Frame,
    params: AdjustParams,
    shifts: Vec<[f64; 2]>,
    points: Vec<[f64; 3]>,
    /// Per track and observation: kept?
    kept: Vec<Vec<bool>>,
    alive: Vec<bool>,
    /// The middle of the tie points (metres), where the gauge's parallax directions are taken.
    centre: [f64; 3],
}

impl Problem<'_> {
    fn observations(&self, j: usize) -> impl Iterator<Item = &Observation> + '_ {
        self.tracks[j]
            .observations
            .iter()
            .zip(&self.kept[j])
            .filter(|(_, k)| **k)
            .map(|(o, _)| o)
    }

    /// Track `j`'s part of the normal equations: the point's block `JᵀWJ` and gradient `JᵀWr`
    /// (Huber weights), and each observation's image, weight, Jacobian and residual.
    fn point_system(&self, j: usize) -> ([[f64; 3]; 3], [f64; 3], Vec<Term>) {
        let mut h = [[0.0; 3]; 3];
        let mut g = [0.0; 3];
        let mut terms = Vec::new();
        for o in self.observations(j) {
            let (p, jac) = project(
                &self.frame,
                &self.cameras[o.image],
                self.shifts[o.image],
                self.points[j],
            );
            let r = [o.col - p[0], o.row - p[1]];
            let w = huber_weight(r[0].hypot(r[1]), self.params.huber_px);
            for a in 0..3 {
                g[a] += w * (jac[0][a] * r[0] + jac[1][a] * r[1]);
                for b in 0..3 {
                    h[a][b] += w * (jac[0][a] * jac[0][b] + jac[1][a] * jac[1][b]);
                }
            }
            terms.push((o.image, w, jac, r));
        }
        (h, g, terms)
    }

    /// Gauss–Newton on one track's point with the translations fixed.
    fn refine_point(&mut self, j: usize, iterations: usize) {
        for _ in 0..iterations {
            let (h, g, _) = self.point_system(j);
            let Some(inv) = invert3(h) else {
                self.alive[j] = false;
                return;
            };
            let d = mat3_vec(&inv, g);
            for (p, step) in self.points[j].iter_mut().zip(d) {
                *p += step;
            }
            if d.iter().map(|v| v * v).sum::<f64>() < 1e-8 {
                break;
            }
        }
    }

    /// One Gauss–Newton step of the translations (points eliminated), then the points again.
    /// Returns the largest change of a translation, pixels.
    fn step(&mut self) -> Result<f64> {
        let n = self.cameras.len();
        let m = 2 * n;
        let mut s = vec![0.0; m * m];
        let mut b = vec![0.0; m];
        for j in 0..self.tracks.len() {
            if !self.alive[j] {
                continue;
            }
            // Blocks of this track: V (3×3), W_i (3×2, identity Jacobian of t), g_X.
            let (v, gx, terms) = self.point_system(j);
            for &(i, w, _, r) in &terms {
                s[(2 * i) * m + 2 * i] += w;
                s[(2 * i + 1) * m + 2 * i + 1] += w;
                b[2 * i] += w * r[0];
                b[2 * i + 1] += w * r[1];
            }
            let Some(vinv) = invert3(v) else {
                self.alive[j] = false;
                continue;
            };
            // S −= W_iᵀ V⁻¹ W_k, with W_i = w_i J_iᵀ (3×2); b −= W_iᵀ V⁻¹ g_X.
            let vg = mat3_vec(&vinv, gx);
            let wcols: Vec<[[f64; 3]; 2]> = terms
                .iter()
                .map(|(_, w, jac, _)| [jac[0].map(|x| w * x), jac[1].map(|x| w * x)])
                .collect();
            for (ti, (i, ..)) in terms.iter().enumerate() {
                for u in 0..2 {
                    let vw: [f64; 3] = mat3_vec(&vinv, wcols[ti][u]);
                    b[2 * i + u] -= (0..3).map(|a| wcols[ti][u][a] * vg[a]).sum::<f64>();
                    for (tk, (k, ..)) in terms.iter().enumerate() {
                        for q in 0..2 {
                            let val: f64 = (0..3).map(|a| vw[a] * wcols[tk][q][a]).sum();
                            s[(2 * i + u) * m + 2 * k + q] -= val;
                        }
                    }
                }
            }
        }
        // The gauge, then a light damping of what is left unseen.
        let trace: f64 = (0..m).map(|i| s[i * m + i]).sum::<f64>() / m as f64;
        let lambda = trace.max(1.0);
        for c in self.gauge_constraints() {
            let lambda = 100.0 * lambda;
            // Penalty λ (c·(t + δt))²: S += λ c cᵀ, b −= λ c (c·t).
            let ct: f64 = (0..n)
                .map(|i| c[2 * i] * self.shifts[i][0] + c[2 * i + 1] * self.shifts[i][1])
                .sum();
            for a in 0..m {
                if c[a] == 0.0 {
                    continue;
                }
                for q in 0..m {
                    s[a * m + q] += lambda * c[a] * c[q];
                }
                b[a] -= lambda * c[a] * ct;
            }
        }
        for i in 0..m {
            s[i * m + i] += 1e-6 * lambda;
        }
        let delta = solve_dense(s, b).ok_or_else(|| {
            CameraError::NoConvergence(
                "bundle adjustment: singular system (too few tie points)".into(),
            )
        })?;
        let mut largest = 0.0f64;
        for i in 0..n {
            for u in 0..2 {
                self.shifts[i][u] += delta[2 * i + u];
                largest = largest.max(delta[2 * i + u].abs());
            }
        }
        for j in 0..self.tracks.len() {
            if self.alive[j] {
                self.refine_point(j, 1);
            }
        }
        Ok(largest)
    }

    /// Rows `c` (over the 2n translation unknowns) with `c·t = 0` fixing the gauge. Moving every
    /// ground point by one 3-D step moves image `i` by `A_i · step` (`A_i` its camera's Jacobian
    /// at the tie points' centre), which no tie point can tell from translations: with
    /// [`Gauge::MeanZero`] the translations are held orthogonal to those three moves (the
    /// smallest translations that explain the tie points, their mean zero on a nadir-like set);
    /// with [`Gauge::Fixed`] the reference image is held and the other images' moves along their
    /// parallax (the scene's altitude) summed to zero.
    fn gauge_constraints(&self) -> Vec<Vec<f64>> {
        let n = self.cameras.len();
        let m = 2 * n;
        let jacobians: Vec<[[f64; 3]; 2]> = self
            .cameras
            .iter()
            .map(|c| project(&self.frame, c, [0.0; 2], self.centre).1)
            .collect();
        let unit = |mut c: Vec<f64>| {
            let norm = c.iter().map(|v| v * v).sum::<f64>().sqrt();
            if norm > 0.0 {
                c.iter_mut().for_each(|v| *v /= norm);
            }
            c
        };
        match self.params.gauge {
            Gauge::MeanZero => (0..3)
                .map(|k| {
                    let mut c = vec![0.0; m];
                    for (i, j) in jacobians.iter().enumerate() {
                        c[2 * i] = j[0][k];
                        c[2 * i + 1] = j[1][k];
                    }
                    unit(c)
                })
                .collect(),
            Gauge::Fixed(r) => {
                let mut rows = Vec::new();
                for u in 0..2 {
                    let mut c = vec![0.0; m];
                    c[2 * r + u] = 1.0;
                    rows.push(c);
                }
                let mut c = vec![0.0; m];
                for (i, j) in jacobians.iter().enumerate().filter(|(i, _)| *i != r) {
                    c[2 * i] = j[0][2];
                    c[2 * i + 1] = j[1][2];
                }
                rows.push(unit(c));
                rows
            }
        }
    }

    fn residual(&self, j: usize, o: &Observation, shifts: &[[f64; 2]]) -> f64 {
        let (p, _) = project(
            &self.frame,
            &self.cameras[o.image],
            shifts[o.image],
            self.points[j],
        );
        (o.col - p[0]).hypot(o.row - p[1])
    }

    /// Drops the observations far beyond the spread of all residuals; tracks left with fewer
    /// than two images die. Returns how many were dropped.
    fn reject(&mut self) -> usize {
        let mut residuals = Vec::new();
        for j in 0..self.tracks.len() {
            if self.alive[j] {
                for o in self.observations(j) {
                    residuals.push(self.residual(j, o, &self.shifts));
                }
            }
        }
        if residuals.is_empty() {
            return 0;
        }
        residuals.sort_by(f64::total_cmp);
        let mad = residuals[residuals.len() / 2];
        let limit = (5.0 * 1.4826 * mad).max(self.params.reject_floor_px);
        let mut dropped = 0;
        for j in 0..self.tracks.len() {
            if !self.alive[j] {
                continue;
            }
            for (k, o) in self.tracks[j].observations.iter().enumerate() {
                if self.kept[j][k] && self.residual(j, o, &self.shifts) > limit {
                    self.kept[j][k] = false;
                    dropped += 1;
                }
            }
            if self.kept[j].iter().filter(|k| **k).count() < 2 {
                self.alive[j] = false;
            }
        }
        dropped
    }
}

/// Finds one image translation per camera and one ground point per track (see the module
/// documentation). `initial_alt` seeds the ground points (the scene's middle altitude).
pub fn adjust_translations(
    cameras: &[RpcModel],
    tracks: &[Track],
    initial_alt: f64,
    params: AdjustParams,
) -> Result<Adjustment> {
    let n = cameras.len();
    if n < 2 {
        return Err(CameraError::Input(
            "bundle adjustment needs two or more images".into(),
        ));
    }
    if let Gauge::Fixed(r) = params.gauge {
        if r >= n {
            return Err(CameraError::Input(format!("reference image {r} of {n}")));
        }
    }
    for o in tracks.iter().flat_map(|t| &t.observations) {
        if o.image >= n || !(o.col.is_finite() && o.row.is_finite()) {
            return Err(CameraError::Input(format!(
                "tie point ({}, {}) in image {} of {n}",
                o.col, o.row, o.image
            )));
        }
    }
    let frame = Frame::new(cameras[0].lon_offset, cameras[0].lat_offset);
    let mut points = Vec::with_capacity(tracks.len());
    let mut alive = Vec::with_capacity(tracks.len());
    for t in tracks {
        let first = t.observations.first();
        let seed = first.and_then(|o| {
            cameras[o.image]
                .localization(o.col, o.row, initial_alt)
                .ok()
        });
        alive.push(seed.is_some() && t.observations.len() >= 2);
        let (lon, lat) = seed.unwrap_or((frame.lon0, frame.lat0));
        points.push(frame.metres_of(lon, lat, initial_alt));
    }
    let mut problem = Problem {
        cameras,
        tracks,
        frame,
        params,
        shifts: vec![[0.0; 2]; n],
        points,
        kept: tracks
            .iter()
            .map(|t| vec![true; t.observations.len()])
            .collect(),
        alive,
        centre: [0.0, 0.0, initial_alt],
    };
    for j in 0..tracks.len() {
        if problem.alive[j] {
            problem.refine_point(j, 10);
        }
    }
    let alive: Vec<usize> = (0..tracks.len()).filter(|&j| problem.alive[j]).collect();
    if alive.is_empty() {
        return Err(CameraError::NoConvergence(
            "bundle adjustment: no tie point seen by two images".into(),
        ));
    }
    let mut xs: Vec<f64> = alive.iter().map(|&j| problem.points[j][0]).collect();
    let mut ys: Vec<f64> = alive.iter().map(|&j| problem.points[j][1]).collect();
    problem.centre = [median(&mut xs), median(&mut ys), initial_alt];
    for round in 0..params.rounds.max(1) {
        for _ in 0..params.iterations {
            if problem.step()? < 1e-3 {
                break;
            }
        }
        if round + 1 < params.rounds && problem.reject() == 0 {
            break;
        }
    }
    problem.reject();
    Ok(summarise(&problem, n))
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn summarise(problem: &Problem, n: usize) -> Adjustment {
    let zero = vec![[0.0; 2]; n];
    let mut fits = vec![ImageFit::default(); n];
    let (mut sq, mut sq0) = (vec![0.0; n], vec![0.0; n]);
    let (mut inliers, mut outliers) = (0, 0);
    for j in 0..problem.tracks.len() {
        for (k, o) in problem.tracks[j].observations.iter().enumerate() {
            if !(problem.alive[j] && problem.kept[j][k]) {
                outliers += 1;
                continue;
            }
            inliers += 1;
            fits[o.image].observations += 1;
            sq[o.image] += problem.residual(j, o, &problem.shifts).powi(2);
            sq0[o.image] += problem.residual(j, o, &zero).powi(2);
        }
    }
    for (i, f) in fits.iter_mut().enumerate() {
        f.col_shift = problem.shifts[i][0];
        f.row_shift = problem.shifts[i][1];
        let count = f.observations.max(1) as f64;
        f.rms_px = (sq[i] / count).sqrt();
        f.rms_before_px = (sq0[i] / count).sqrt();
    }
    let points = (0..problem.tracks.len())
        .map(|j| problem.alive[j].then(|| problem.frame.ground_of(problem.points[j])))
        .collect();
    let views = (0..problem.tracks.len())
        .map(|j| problem.kept[j].iter().filter(|k| **k).count())
        .collect();
    Adjustment {
        images: fits,
        points,
        views,
        inliers,
        outliers,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Three oblique cameras over one area (affine RPCs with an altitude term, like the
    /// procedural world's).
    fn cameras() -> Vec<RpcModel> {
        // (parallax per metre in col, in row; image rotation, degrees; scale).
        let views = [
            (0.0, 0.0, 0.0, 1.0),
            (0.25, -0.1, 35.0, 1.1),
            (-0.2, 0.15, -60.0, 0.9),
            (0.05, 0.3, 95.0, 1.2),
        ];
        views
            .iter()
            .map(|&(tx, ty, angle, scale): &(f64, f64, f64, f64)| {
                let mut c = RpcModel::nadir(
                    [500.0, 500.0, 30.0, -81.0, 0.0],
                    [500.0, 500.0, 0.0015, 0.0015, 100.0],
                );
                let (s, k) = angle.to_radians().sin_cos();
                // Normalised pixels per normalised metre: up to 1.5 px of parallax a metre.
                c.col_num[1] = scale * k;
                c.col_num[2] = scale * s;
                c.row_num[1] = scale * s;
                c.row_num[2] = -scale * k;
                c.col_num[3] = tx;
                c.row_num[3] = ty;
                c.col_num[7] = 0.002;
                c
            })
            .collect()
    }

    fn tracks(cams: &[RpcModel], shifts: &[[f64; 2]]) -> Vec<Track> {
        let mut out = Vec::new();
        let mut seed = 7u64;
        let mut rand = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..300 {
            let lon = -81.0 + (rand() - 0.5) * 0.002;
            let lat = 30.0 + (rand() - 0.5) * 0.002;
            let alt = -10.0 + 40.0 * rand();
            let mut t = Track::default();
            for (i, c) in cams.iter().enumerate() {
                if rand() < 0.8 {
                    let (col, row) = c.projection(lon, lat, alt);
                    t.observations.push(Observation {
                        image: i,
                        col: col + shifts[i][0] + (rand() - 0.5) * 0.1,
                        row: row + shifts[i][1] + (rand() - 0.5) * 0.1,
                    });
                }
            }
            if t.observations.len() >= 2 {
                out.push(t);
            }
        }
        out
    }

    /// The largest difference between the found and the true translations once the gauge (a
    /// common translation and a common change of altitude) is taken out by least squares.
    fn off_gauge(cams: &[RpcModel], found: &[ImageFit], truth: &[[f64; 2]]) -> f64 {
        let n = cams.len();
        let d: Vec<[f64; 2]> = (0..n)
            .map(|i| {
                [
                    found[i].col_shift - truth[i][0],
                    found[i].row_shift - truth[i][1],
                ]
            })
            .collect();
        // Each image's move for a 3-D move of the scene: d_i ≈ A_i x.
        let jac: Vec<[[f64; 3]; 2]> = cams
            .iter()
            .map(|c| {
                let p = c.projection(-81.0, 30.0, 0.0);
                let q = [
                    c.projection(-81.0 + 1e-5, 30.0, 0.0),
                    c.projection(-81.0, 30.0 + 1e-5, 0.0),
                    c.projection(-81.0, 30.0, 1.0),
                ];
                [q.map(|v| v.0 - p.0), q.map(|v| v.1 - p.1)]
            })
            .collect();
        let mut a = vec![0.0; 9];
        let mut r = vec![0.0; 3];
        for i in 0..n {
            for u in 0..2 {
                for p in 0..3 {
                    r[p] += jac[i][u][p] * d[i][u];
                    for q in 0..3 {
                        a[p * 3 + q] += jac[i][u][p] * jac[i][u][q];
                    }
                }
            }
        }
        let x = solve_dense(a, r).unwrap();
        (0..n)
            .map(|i| {
                let e = [0, 1].map(|u| d[i][u] - (0..3).map(|k| jac[i][u][k] * x[k]).sum::<f64>());
                e[0].hypot(e[1])
            })
            .fold(0.0, f64::max)
    }

    #[test]
    fn recovers_the_translations_up_to_the_gauge_and_rejects_outliers() {
        let cams = cameras();
        let shifts = [[12.0, -30.0], [-75.0, 4.0], [3.5, 78.0], [-7.0, -2.5]];
        let mut t = tracks(&cams, &shifts);
        // A few gross mismatches.
        for k in (0..t.len()).step_by(23) {
            t[k].observations[0].col += 15.0;
        }
        let adj = adjust_translations(&cams, &t, 0.0, AdjustParams::default()).unwrap();
        let off = off_gauge(&cams, &adj.images, &shifts);
        assert!(off < 0.05, "{off} px off: {:?}", adj.images);
        assert!(
            adj.images.iter().all(|f| f.rms_px < 0.1),
            "{:?}",
            adj.images
        );
        assert!(
            adj.images.iter().any(|f| f.rms_before_px > 5.0),
            "{:?}",
            adj.images
        );
        assert!(adj.outliers >= t.len() / 23, "{} outliers", adj.outliers);
        let alts = adj.altitudes(2);
        let lo = alts.iter().cloned().fold(f64::INFINITY, f64::min);
        let hi = alts.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
        assert!(hi - lo > 35.0 && hi - lo < 45.0, "{lo}..{hi}");
        // Shifting every camera changes nothing but the gauge.
        let moved: Vec<[f64; 2]> = shifts
            .iter()
            .enumerate()
            .map(|(i, s)| [s[0] + 3.0 * i as f64, s[1] - 7.0])
            .collect();
        let again =
            adjust_translations(&cams, &tracks(&cams, &moved), 0.0, AdjustParams::default())
                .unwrap();
        assert!(off_gauge(&cams, &again.images, &moved) < 0.05);
    }

    #[test]
    fn a_fixed_image_keeps_its_camera() {
        let cams = cameras()[..2].to_vec();
        let shifts = [[5.0, 5.0], [-3.0, 20.0]];
        let t = tracks(&cams, &shifts);
        let params = AdjustParams {
            gauge: Gauge::Fixed(0),
            ..AdjustParams::default()
        };
        let adj = adjust_translations(&cams, &t, 0.0, params).unwrap();
        assert!(adj.images[0].col_shift.abs() < 1e-3 && adj.images[0].row_shift.abs() < 1e-3);
        // Two views see the relative error across their epipolar direction only; the rest is
        // the altitude's. The residuals vanish all the same.
        assert!(adj.images[1].rms_px < 0.1, "{:?}", adj.images[1]);
    }

    #[test]
    fn bad_input_is_an_error() {
        let cams = cameras();
        assert!(adjust_translations(&cams[..1], &[], 0.0, AdjustParams::default()).is_err());
        let bad = Track {
            observations: vec![
                Observation {
                    image: 9,
                    col: 0.0,
                    row: 0.0
                };
                2
            ],
        };
        assert!(adjust_translations(&cams, &[bad], 0.0, AdjustParams::default()).is_err());
        // No tie point at all: the system is singular.
        assert!(adjust_translations(&cams, &[], 0.0, AdjustParams::default()).is_err());
    }
}

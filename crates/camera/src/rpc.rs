//! The RPC00B rational function camera model, read from the SatNeRF/rpcm JSON of the public
//! benchmark or from the GeoTIFF RPC tag, with rpcm's projection and iterative localisation.
//!
//! Coordinates are normalised as `(v − offset) / scale` before the polynomials are evaluated.
//! The 20 terms follow RPC00B (the order of rpcm's `apply_poly` and of the GeoTIFF tag):
//! 1, L, P, H, LP, LH, PH, L², P², H², PLH, L³, LP², LH², L²P, P³, PH², L²H, P²H, H³ with
//! L = longitude, P = latitude, H = altitude.

use std::path::Path;

use raster::formats::{read_tiff, RpcTag};
use serde_json::Value;

use crate::{CameraError, Result};

/// rpcm's convergence test: squared distance in normalised image coordinates.
const LOC_TOLERANCE_SQ: f64 = 1e-18;
/// Iteration cap of the localisation solvers (rpcm raises after 100).
const LOC_MAX_ITERATIONS: usize = 100;
/// A Newton step shorter than this (normalised ground units) leaves an error of order its square:
/// far below rpcm's tolerance, so the solver can stop without one more evaluation.
const NEWTON_FINAL_STEP: f64 = 1e-8;
/// Newton's residual test: much tighter than rpcm's, because a warm start often begins just
/// inside rpcm's tolerance and stopping there would leave errors of 1e-6 m in triangulated
/// altitudes; one more step costs one evaluation and removes them.
const NEWTON_TOLERANCE_SQ: f64 = 1e-30;

/// An RPC camera: ground (lon, lat, alt) → image (col, row).
#[derive(Clone, Debug, PartialEq)]
pub struct RpcModel {
    pub row_offset: f64,
    pub col_offset: f64,
    pub lat_offset: f64,
    pub lon_offset: f64,
    pub alt_offset: f64,
    pub row_scale: f64,
    pub col_scale: f64,
    pub lat_scale: f64,
    pub lon_scale: f64,
    pub alt_scale: f64,
    pub row_num: [f64; 20],
    pub row_den: [f64; 20],
    pub col_num: [f64; 20],
    pub col_den: [f64; 20],
    /// Altitude bounds of the scene when the SatNeRF JSON gives them (`min_alt`, `max_alt`).
    pub min_alt: Option<f64>,
    pub max_alt: Option<f64>,
}

/// The 20 RPC00B monomials of normalised (lon, lat, alt).
#[inline(always)]
fn monomials(l: f64, p: f64, h: f64) -> [f64; 20] {
    [
        1.0,
        l,
        p,
        h,
        l * p,
        l * h,
        p * h,
        l * l,
        p * p,
        h * h,
        p * l * h,
        l * l * l,
        l * p * p,
        l * h * h,
        l * l * p,
        p * p * p,
        p * h * h,
        l * l * h,
        p * p * h,
        h * h * h,
    ]
}

/// Derivatives of [`monomials`] with respect to l and p.
#[inline(always)]
fn monomial_gradients(l: f64, p: f64, h: f64) -> ([f64; 20], [f64; 20]) {
    let dl = [
        0.0,
        1.0,
        0.0,
        0.0,
        p,
        h,
        0.0,
        2.0 * l,
        0.0,
        0.0,
        p * h,
        3.0 * l * l,
        p * p,
        h * h,
        2.0 * l * p,
        0.0,
        0.0,
        2.0 * l * h,
        0.0,
        0.0,
    ];
    let dp = [
        0.0,
        0.0,
        1.0,
        0.0,
        l,
        0.0,
        h,
        0.0,
        2.0 * p,
        0.0,
        l * h,
        0.0,
        2.0 * l * p,
        0.0,
        l * l,
        3.0 * p * p,
        h * h,
        0.0,
        2.0 * p * h,
        0.0,
    ];
    (dl, dp)
}

#[inline(always)]
fn dot(a: &[f64; 20], b: &[f64; 20]) -> f64 {
    // Four partial sums: shorter dependency chains, same result for every caller.
    let mut s = [0.0; 4];
    for i in 0..5 {
        for k in 0..4 {
            s[k] += a[4 * i + k] * b[4 * i + k];
        }
    }
    (s[0] + s[1]) + (s[2] + s[3])
}

fn json_error(origin: &str, key: &str, message: impl Into<String>) -> CameraError {
    CameraError::Rpc {
        origin: origin.to_string(),
        key: key.to_string(),
        message: message.into(),
    }
}

impl RpcModel {
    /// An affine nadir camera: normalised column = normalised longitude, row = − normalised
    /// latitude, no altitude term. `offsets` and `scales` are `[row, col, lat, lon, alt]` as in
    /// the RPC00B tags. Synthetic scenes and tests start from it and add terms.
    pub fn nadir(offsets: [f64; 5], scales: [f64; 5]) -> Self {
        let (mut col_num, mut row_num, mut den) = ([0.0; 20], [0.0; 20], [0.0; 20]);
        col_num[1] = 1.0;
        row_num[2] = -1.0;
        den[0] = 1.0;
        let [row_offset, col_offset, lat_offset, lon_offset, alt_offset] = offsets;
        let [row_scale, col_scale, lat_scale, lon_scale, alt_scale] = scales;
        RpcModel {
            row_offset,
            col_offset,
            lat_offset,
            lon_offset,
            alt_offset,
            row_scale,
            col_scale,
            lat_scale,
            lon_scale,
            alt_scale,
            row_num,
            row_den: den,
            col_num,
            col_den: den,
            min_alt: None,
            max_alt: None,
        }
    }

    /// From rpcm's dictionary, either a whole SatNeRF image JSON (the model under `"rpc"`, the
    /// altitude bounds in `min_alt`/`max_alt`) or the bare `rpc` dictionary.
    pub fn from_rpcm_json(value: &Value) -> Result<Self> {
        Self::parse_json(value, "<json>")
    }

    /// Reads a SatNeRF/rpcm JSON file.
    pub fn read_rpcm_json(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let origin = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| raster::RasterError::io(path, e))?;
        let value: Value = serde_json::from_str(&text)
            .map_err(|e| json_error(&origin, "", format!("not valid JSON: {e}")))?;
        Self::parse_json(&value, &origin)
    }

    fn parse_json(value: &Value, origin: &str) -> Result<Self> {
        let root = value
            .as_object()
            .ok_or_else(|| json_error(origin, "", "expected a JSON object"))?;
        let dict = match root.get("rpc") {
            Some(Value::Object(d)) => d,
            Some(_) => return Err(json_error(origin, "rpc", "expected an object")),
            None => root,
        };
        let scalar = |key: &str| -> Result<f64> {
            let v = dict
                .get(key)
                .ok_or_else(|| json_error(origin, key, "missing"))?;
            let x = v
                .as_f64()
                .ok_or_else(|| json_error(origin, key, format!("expected a number, got {v}")))?;
            if !x.is_finite() {
                return Err(json_error(origin, key, "not finite"));
            }
            Ok(x)
        };
        let scale = |key: &str| -> Result<f64> {
            let x = scalar(key)?;
            if x == 0.0 {
                return Err(json_error(origin, key, "a scale cannot be zero"));
            }
            Ok(x)
        };
        let poly = |key: &str| -> Result<[f64; 20]> {
            let v = dict
                .get(key)
                .ok_or_else(|| json_error(origin, key, "missing"))?;
            let a = v
                .as_array()
                .ok_or_else(|| json_error(origin, key, "expected an array of 20 numbers"))?;
            if a.len() != 20 {
                return Err(json_error(
                    origin,
                    key,
                    format!("expected 20 coefficients, got {}", a.len()),
                ));
            }
            let mut out = [0.0; 20];
            for (o, x) in out.iter_mut().zip(a) {
                *o = x
                    .as_f64()
                    .filter(|x| x.is_finite())
                    .ok_or_else(|| json_error(origin, key, format!("not a finite number: {x}")))?;
            }
            Ok(out)
        };
        let bound = |key: &str| -> Result<Option<f64>> {
            match root.get(key) {
                None | Some(Value::Null) => Ok(None),
                Some(v) => v
                    .as_f64()
                    .filter(|x| x.is_finite())
                    .map(Some)
                    .ok_or_else(|| json_error(origin, key, format!("not a finite number: {v}"))),
            }
        };
        let model = RpcModel {
            row_offset: scalar("row_offset")?,
            col_offset: scalar("col_offset")?,
            lat_offset: scalar("lat_offset")?,
            lon_offset: scalar("lon_offset")?,
            alt_offset: scalar("alt_offset")?,
            row_scale: scale("row_scale")?,
            col_scale: scale("col_scale")?,
            lat_scale: scale("lat_scale")?,
            lon_scale: scale("lon_scale")?,
            alt_scale: scale("alt_scale")?,
            row_num: poly("row_num")?,
            row_den: poly("row_den")?,
            col_num: poly("col_num")?,
            col_den: poly("col_den")?,
            min_alt: bound("min_alt")?,
            max_alt: bound("max_alt")?,
        };
        Ok(model)
    }

    /// From GeoTIFF tag 50844 (LINE = row, SAMP = col, LONG = lon, HEIGHT = alt).
    pub fn from_tiff_tag(tag: &RpcTag) -> Result<Self> {
        let model = RpcModel {
            row_offset: tag.line_off,
            col_offset: tag.samp_off,
            lat_offset: tag.lat_off,
            lon_offset: tag.lon_off,
            alt_offset: tag.height_off,
            row_scale: tag.line_scale,
            col_scale: tag.samp_scale,
            lat_scale: tag.lat_scale,
            lon_scale: tag.lon_scale,
            alt_scale: tag.height_scale,
            row_num: tag.line_num,
            row_den: tag.line_den,
            col_num: tag.samp_num,
            col_den: tag.samp_den,
            min_alt: None,
            max_alt: None,
        };
        model.check("<RPC tag 50844>")?;
        Ok(model)
    }

    /// The RPC model stored in a GeoTIFF's tag 50844.
    pub fn read_geotiff_rpc(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let origin = path.display().to_string();
        let raster = read_tiff(path)?;
        let tag = raster
            .rpc
            .ok_or_else(|| json_error(&origin, "50844", "the TIFF has no RPC tag"))?;
        Self::from_tiff_tag(&tag).map_err(|e| match e {
            CameraError::Rpc { key, message, .. } => json_error(&origin, &key, message),
            e => e,
        })
    }

    pub(crate) fn check(&self, origin: &str) -> Result<()> {
        let scalars = [
            ("row_offset", self.row_offset, false),
            ("col_offset", self.col_offset, false),
            ("lat_offset", self.lat_offset, false),
            ("lon_offset", self.lon_offset, false),
            ("alt_offset", self.alt_offset, false),
            ("row_scale", self.row_scale, true),
            ("col_scale", self.col_scale, true),
            ("lat_scale", self.lat_scale, true),
            ("lon_scale", self.lon_scale, true),
            ("alt_scale", self.alt_scale, true),
        ];
        for (key, v, is_scale) in scalars {
            if !v.is_finite() {
                return Err(json_error(origin, key, "not finite"));
            }
            if is_scale && v == 0.0 {
                return Err(json_error(origin, key, "a scale cannot be zero"));
            }
        }
        for (key, p) in [
            ("row_num", &self.row_num),
            ("row_den", &self.row_den),
            ("col_num", &self.col_num),
            ("col_den", &self.col_den),
        ] {
            if p.iter().any(|v| !v.is_finite()) {
                return Err(json_error(origin, key, "non-finite coefficient"));
            }
        }
        Ok(())
    }

    /// rpcm's dictionary of the model (the keys [`RpcModel::from_rpcm_json`] reads), with the
    /// altitude bounds when known: what the corrected cameras are written as.
    pub fn to_rpcm_json(&self) -> Value {
        let mut v = serde_json::json!({
            "row_offset": self.row_offset, "col_offset": self.col_offset,
            "lat_offset": self.lat_offset, "lon_offset": self.lon_offset,
            "alt_offset": self.alt_offset,
            "row_scale": self.row_scale, "col_scale": self.col_scale,
            "lat_scale": self.lat_scale, "lon_scale": self.lon_scale,
            "alt_scale": self.alt_scale,
            "row_num": self.row_num.to_vec(), "row_den": self.row_den.to_vec(),
            "col_num": self.col_num.to_vec(), "col_den": self.col_den.to_vec(),
        });
        if let (Some(lo), Some(hi)) = (self.min_alt, self.max_alt) {
            v["min_alt"] = lo.into();
            v["max_alt"] = hi.into();
        }
        v
    }

    /// The model's altitude validity range, `alt_offset ± alt_scale`: a safe bound when deriving
    /// a disparity search range from the cameras.
    pub fn altitude_range(&self) -> (f64, f64) {
        let s = self.alt_scale.abs();
        (self.alt_offset - s, self.alt_offset + s)
    }

    /// The scene's altitude bounds: `min_alt`/`max_alt` of the SatNeRF JSON when present (much
    /// tighter than the RPC's validity range), else [`RpcModel::altitude_range`].
    pub fn scene_altitude_range(&self) -> (f64, f64) {
        let (lo, hi) = self.altitude_range();
        (self.min_alt.unwrap_or(lo), self.max_alt.unwrap_or(hi))
    }

    /// Normalised image (col, row) of normalised ground (lon, lat, alt).
    #[inline]
    fn apply_normalised(&self, l: f64, p: f64, h: f64) -> (f64, f64) {
        let m = monomials(l, p, h);
        (
            dot(&self.col_num, &m) / dot(&self.col_den, &m),
            dot(&self.row_num, &m) / dot(&self.row_den, &m),
        )
    }

    /// Normalised image point and its Jacobian with respect to normalised (lon, lat):
    /// `(col, row, [[dcol/dl, dcol/dp], [drow/dl, drow/dp]])`.
    #[inline]
    fn apply_with_jacobian(&self, l: f64, p: f64, h: f64) -> (f64, f64, [[f64; 2]; 2]) {
        let m = monomials(l, p, h);
        let (gl, gp) = monomial_gradients(l, p, h);
        let ratio = |num: &[f64; 20], den: &[f64; 20]| {
            let (n, d) = (dot(num, &m), dot(den, &m));
            let r = n / d;
            let dl = (dot(num, &gl) - r * dot(den, &gl)) / d;
            let dp = (dot(num, &gp) - r * dot(den, &gp)) / d;
            (r, dl, dp)
        };
        let (c, cl, cp) = ratio(&self.col_num, &self.col_den);
        let (r, rl, rp) = ratio(&self.row_num, &self.row_den);
        (c, r, [[cl, cp], [rl, rp]])
    }

    /// Image (col, row) of the ground point (lon, lat in degrees, alt in metres).
    #[inline]
    pub fn projection(&self, lon: f64, lat: f64, alt: f64) -> (f64, f64) {
        let (c, r) = self.apply_normalised(
            (lon - self.lon_offset) / self.lon_scale,
            (lat - self.lat_offset) / self.lat_scale,
            (alt - self.alt_offset) / self.alt_scale,
        );
        (
            c * self.col_scale + self.col_offset,
            r * self.row_scale + self.row_offset,
        )
    }

    /// Ground (lon, lat) seen at image (col, row) at altitude `alt`, by rpcm's iterative scheme:
    /// start at normalised (−1, −1), take a local basis of finite differences (step 2, then 0.1)
    /// and move by the projections of the residual on it until the normalised image residual is
    /// below 1e-9. Errors after 100 iterations, as rpcm does.
    pub fn localization(&self, col: f64, row: f64, alt: f64) -> Result<(f64, f64)> {
        let tc = (col - self.col_offset) / self.col_scale;
        let tr = (row - self.row_offset) / self.row_scale;
        let h = (alt - self.alt_offset) / self.alt_scale;
        let (mut l, mut p) = (-1.0, -1.0);
        let mut eps = 2.0;
        for _ in 0..=LOC_MAX_ITERATIONS {
            let (x0, y0) = self.apply_normalised(l, p, h);
            let (ux, uy) = (tc - x0, tr - y0);
            if ux * ux + uy * uy < LOC_TOLERANCE_SQ {
                return Ok(self.denormalise_ground(l, p));
            }
            let (x1, y1) = self.apply_normalised(l + eps, p, h);
            let (x2, y2) = self.apply_normalised(l, p + eps, h);
            let (e1x, e1y) = (x1 - x0, y1 - y0);
            let (e2x, e2y) = (x2 - x0, y2 - y0);
            let a1 = (ux * e1x + uy * e1y) / (e1x * e1x + e1y * e1y);
            let a2 = (ux * e2x + uy * e2y) / (e2x * e2x + e2y * e2y);
            l += a1 * eps;
            p += a2 * eps;
            eps = 0.1;
            if !(l.is_finite() && p.is_finite()) {
                break;
            }
        }
        Err(self.no_convergence(col, row, alt))
    }

    /// [`RpcModel::localization`] started from a nearby answer (lon0, lat0), e.g. the solution
    /// of the neighbouring pixel: Newton's method with the exact Jacobian, so one or two
    /// polynomial evaluations instead of tens. It converges to the same point, only tighter: it
    /// stops on a residual below 1e-15 or after a step so short that the error left is its
    /// square, ≪ rpcm's 1e-9.
    pub fn localization_from(
        &self,
        col: f64,
        row: f64,
        alt: f64,
        lon0: f64,
        lat0: f64,
    ) -> Result<(f64, f64)> {
        let tc = (col - self.col_offset) / self.col_scale;
        let tr = (row - self.row_offset) / self.row_scale;
        let h = (alt - self.alt_offset) / self.alt_scale;
        let l0 = (lon0 - self.lon_offset) / self.lon_scale;
        let p0 = (lat0 - self.lat_offset) / self.lat_scale;
        match self.newton_normalised(tc, tr, h, l0, p0) {
            Some((l, p)) => Ok(self.denormalise_ground(l, p)),
            // A start too far away for Newton: rpcm's globally convergent scheme.
            None => self.localization(col, row, alt),
        }
    }

    /// Newton iterations in normalised coordinates; `None` if they do not converge.
    #[inline]
    pub(crate) fn newton_normalised(
        &self,
        tc: f64,
        tr: f64,
        h: f64,
        mut l: f64,
        mut p: f64,
    ) -> Option<(f64, f64)> {
        for _ in 0..LOC_MAX_ITERATIONS {
            let (x, y, j) = self.apply_with_jacobian(l, p, h);
            let (ux, uy) = (tc - x, tr - y);
            if ux * ux + uy * uy < NEWTON_TOLERANCE_SQ {
                return Some((l, p));
            }
            let det = j[0][0] * j[1][1] - j[0][1] * j[1][0];
            let dl = (j[1][1] * ux - j[0][1] * uy) / det;
            let dp = (j[0][0] * uy - j[1][0] * ux) / det;
            l += dl;
            p += dp;
            if !(l.is_finite() && p.is_finite()) || l.abs() > 10.0 || p.abs() > 10.0 {
                return None;
            }
            if dl * dl + dp * dp < NEWTON_FINAL_STEP * NEWTON_FINAL_STEP {
                return Some((l, p));
            }
        }
        None
    }

    #[inline]
    fn denormalise_ground(&self, l: f64, p: f64) -> (f64, f64) {
        (
            l * self.lon_scale + self.lon_offset,
            p * self.lat_scale + self.lat_offset,
        )
    }

    /// Normalised image and altitude coordinates, for the triangulation's inner loop.
    #[inline]
    pub(crate) fn normalise_image(&self, col: f64, row: f64, alt: f64) -> (f64, f64, f64) {
        (
            (col - self.col_offset) / self.col_scale,
            (row - self.row_offset) / self.row_scale,
            (alt - self.alt_offset) / self.alt_scale,
        )
    }

    #[inline]
    pub(crate) fn normalise_ground(&self, lon: f64, lat: f64) -> (f64, f64) {
        (
            (lon - self.lon_offset) / self.lon_scale,
            (lat - self.lat_offset) / self.lat_scale,
        )
    }

    #[inline]
    pub(crate) fn ground_from_normalised(&self, l: f64, p: f64) -> (f64, f64) {
        self.denormalise_ground(l, p)
    }

    fn no_convergence(&self, col: f64, row: f64, alt: f64) -> CameraError {
        CameraError::NoConvergence(format!(
            "RPC localisation of image point ({col}, {row}) at altitude {alt} m did not converge \
             in {LOC_MAX_ITERATIONS} iterations"
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A mildly non-linear synthetic camera.
    fn camera() -> RpcModel {
        let mut c = RpcModel::nadir(
            [500.0, 500.0, 30.0, -81.0, 0.0],
            [500.0, 500.0, 0.01, 0.01, 100.0],
        );
        c.col_num[3] = 0.05;
        c.col_num[7] = 0.01;
        c.row_num[1] = 0.02;
        c.row_num[8] = 0.005;
        c.row_den[3] = 0.001;
        c.col_den[3] = 0.001;
        c
    }

    #[test]
    fn jacobian_matches_finite_differences() {
        let c = camera();
        let (l, p, h) = (0.3, -0.2, 0.4);
        let (_, _, j) = c.apply_with_jacobian(l, p, h);
        let e = 1e-6;
        let (a, b) = c.apply_normalised(l + e, p, h);
        let (a0, b0) = c.apply_normalised(l - e, p, h);
        assert!(((a - a0) / (2.0 * e) - j[0][0]).abs() < 1e-8);
        assert!(((b - b0) / (2.0 * e) - j[1][0]).abs() < 1e-8);
        let (a, b) = c.apply_normalised(l, p + e, h);
        let (a0, b0) = c.apply_normalised(l, p - e, h);
        assert!(((a - a0) / (2.0 * e) - j[0][1]).abs() < 1e-8);
        assert!(((b - b0) / (2.0 * e) - j[1][1]).abs() < 1e-8);
    }

    #[test]
    fn the_rpcm_dictionary_reads_back_as_the_same_model() {
        let mut c = camera();
        c.min_alt = Some(-5.0);
        c.max_alt = Some(40.0);
        let back = RpcModel::from_rpcm_json(&serde_json::json!({
            "rpc": c.to_rpcm_json(), "min_alt": -5.0, "max_alt": 40.0
        }))
        .unwrap();
        assert_eq!(back, c);
    }

    #[test]
    fn localisations_agree() {
        let c = camera();
        let (lon, lat) = c.localization(310.0, 720.0, 35.0).unwrap();
        let (col, row) = c.projection(lon, lat, 35.0);
        assert!((col - 310.0).abs() < 1e-6 && (row - 720.0).abs() < 1e-6);
        let (lon2, lat2) = c
            .localization_from(310.0, 720.0, 35.0, lon + 0.003, lat - 0.002)
            .unwrap();
        assert!((lon - lon2).abs() < 1e-9 && (lat - lat2).abs() < 1e-9);
    }
}

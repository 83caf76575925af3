//! The map projection of a DSM grid: any EPSG code. WGS84/UTM zones use the exact series of
//! [`crate::utm`] (the default, and what the benchmark grids on); every other code is read from
//! the EPSG definitions and projected with a pure-Rust PROJ.4 (`proj4rs`).

use std::collections::HashMap;
use std::sync::{Mutex, OnceLock};

use proj4rs::Proj;

use crate::utm::{A, E2};
use crate::{CameraError, Result, UtmZone};

/// A coordinate reference system of the ground: longitude and latitude (degrees, WGS84) ↔ the
/// CRS's own coordinates (metres for projected systems, degrees for geographic ones).
pub enum Crs {
    /// A WGS84 UTM zone (EPSG 326zz or 327zz).
    Utm(UtmZone),
    /// Any other EPSG code.
    Proj {
        epsg: u32,
        proj: Box<Proj>,
        wgs84: Box<Proj>,
    },
}

impl std::fmt::Debug for Crs {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "EPSG:{}", self.epsg())
    }
}

/// The CRS of each EPSG code asked for, built once: a definition is parsed per code, not per
/// point, and grids hand out `&'static` references.
fn cache() -> &'static Mutex<HashMap<u32, &'static Crs>> {
    static CACHE: OnceLock<Mutex<HashMap<u32, &'static Crs>>> = OnceLock::new();
    CACHE.get_or_init(Default::default)
}

impl Crs {
    /// The CRS of an EPSG code; an error naming the code when it is unknown or cannot be
    /// projected to and from.
    pub fn from_epsg(epsg: u32) -> Result<&'static Crs> {
        let mut known = cache().lock().unwrap_or_else(|e| e.into_inner());
        if let Some(crs) = known.get(&epsg) {
            return Ok(crs);
        }
        let crs: &'static Crs = Box::leak(Box::new(Self::build(epsg)?));
        known.insert(epsg, crs);
        Ok(crs)
    }

    fn build(epsg: u32) -> Result<Crs> {
        if let Ok(zone) = UtmZone::from_epsg(epsg) {
            return Ok(Crs::Utm(zone));
        }
        let unknown = |why: String| {
            CameraError::Georeference(format!(
                "EPSG:{epsg}: {why} (give a projected or geographic EPSG code, e.g. 32617 for \
                 UTM 17N, 4326 for longitude/latitude, 3857 for Web Mercator)"
            ))
        };
        let code = u16::try_from(epsg).map_err(|_| unknown("no such code".into()))?;
        let proj = Proj::from_epsg_code(code).map_err(|e| unknown(format!("{e}")))?;
        if proj.is_geocent() {
            return Err(unknown("a geocentric system is not a map".into()));
        }
        let wgs84 = Proj::from_epsg_code(4326).map_err(|e| unknown(format!("{e}")))?;
        let crs = Crs::Proj {
            epsg,
            proj: Box::new(proj),
            wgs84: Box::new(wgs84),
        };
        // A definition that parses but cannot project (a missing grid file, an unsupported
        // method) fails here, once, rather than as NaN cells later.
        let probe = crs
            .try_forward(0.0, 0.0)
            .or_else(|_| crs.try_forward(10.0, 45.0));
        if !probe.is_ok_and(|(x, y)| x.is_finite() && y.is_finite()) {
            return Err(unknown("its projection cannot be computed here".into()));
        }
        Ok(crs)
    }

    /// The EPSG code.
    pub fn epsg(&self) -> u32 {
        match self {
            Crs::Utm(zone) => zone.epsg(),
            Crs::Proj { epsg, .. } => *epsg,
        }
    }

    /// Whether the coordinates are longitude and latitude (degrees) rather than metres.
    pub fn is_geographic(&self) -> bool {
        match self {
            Crs::Utm(_) => false,
            Crs::Proj { proj, .. } => proj.is_latlong(),
        }
    }

    /// A length of `value` in the CRS's units, as people write it: `0.5 m`, `4.51e-6°`,
    /// `1.64 us-ft`.
    pub fn length(&self, value: f64) -> String {
        let unit = match self {
            Crs::Utm(_) => "m",
            Crs::Proj { proj, .. } if proj.is_latlong() => return format!("{value:.3e}°"),
            Crs::Proj { proj, .. } => proj.units(),
        };
        let digits = if value >= 1.0 { 3 } else { 4 };
        let text = format!("{value:.digits$}");
        let text = text.trim_end_matches('0').trim_end_matches('.');
        format!("{text} {unit}")
    }

    /// The UTM zone, for a UTM CRS.
    pub fn utm_zone(&self) -> Option<UtmZone> {
        match self {
            Crs::Utm(zone) => Some(*zone),
            Crs::Proj { .. } => None,
        }
    }

    /// (x, y) of WGS84 (lon, lat) in degrees; NaN where the projection is undefined.
    #[inline]
    pub fn forward(&self, lon: f64, lat: f64) -> (f64, f64) {
        match self {
            Crs::Utm(zone) => zone.forward(lon, lat),
            Crs::Proj { .. } => self.try_forward(lon, lat).unwrap_or((f64::NAN, f64::NAN)),
        }
    }

    /// WGS84 (lon, lat) in degrees of (x, y); NaN where the projection is undefined.
    #[inline]
    pub fn inverse(&self, x: f64, y: f64) -> (f64, f64) {
        match self {
            Crs::Utm(zone) => zone.inverse(x, y),
            Crs::Proj { proj, wgs84, .. } => {
                let scale = if proj.is_latlong() {
                    1f64.to_radians()
                } else {
                    1.0
                };
                let mut p = (x * scale, y * scale, 0.0);
                match proj4rs::transform::transform(proj, wgs84, &mut p) {
                    Ok(()) => (p.0.to_degrees(), p.1.to_degrees()),
                    Err(_) => (f64::NAN, f64::NAN),
                }
            }
        }
    }

    /// The cell size in this CRS's units of cells `metres` wide on the ground near (lon, lat):
    /// as given where the CRS's unit is within 1 % of a ground metre (UTM, national grids in
    /// metres), converted where it is not (degrees, Web Mercator away from the equator, feet).
    pub fn cell_size(&self, metres: f64, lon: f64, lat: f64) -> f64 {
        let k = self.units_per_metre(lon, lat);
        if (k - 1.0).abs() <= 0.01 {
            metres
        } else {
            metres * k
        }
    }

    /// The bounds (x_min, y_min, x_max, y_max) in this CRS of the rectangle `b` of `from`'s
    /// coordinates: its outline, sampled, through longitude and latitude. `b` itself when both
    /// are one CRS.
    pub fn bounds_of(&self, from: &Crs, b: [f64; 4]) -> [f64; 4] {
        if self.epsg() == from.epsg() {
            return b;
        }
        const STEPS: usize = 16;
        let mut out = [
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        ];
        for k in 0..=STEPS {
            let f = k as f64 / STEPS as f64;
            let (xs, ys) = (b[0] + f * (b[2] - b[0]), b[1] + f * (b[3] - b[1]));
            for (x, y) in [(xs, b[1]), (xs, b[3]), (b[0], ys), (b[2], ys)] {
                let (lon, lat) = from.inverse(x, y);
                let (u, v) = self.forward(lon, lat);
                out = [out[0].min(u), out[1].min(v), out[2].max(u), out[3].max(v)];
            }
        }
        out
    }

    fn try_forward(&self, lon: f64, lat: f64) -> std::result::Result<(f64, f64), ()> {
        match self {
            Crs::Utm(zone) => Ok(zone.forward(lon, lat)),
            Crs::Proj { proj, wgs84, .. } => {
                let mut p = (lon.to_radians(), lat.to_radians(), 0.0);
                proj4rs::transform::transform(wgs84, proj, &mut p).map_err(|_| ())?;
                let scale = if proj.is_latlong() {
                    1f64.to_degrees()
                } else {
                    1.0
                };
                Ok((p.0 * scale, p.1 * scale))
            }
        }
    }

    /// The CRS units of one metre on the ground at (lon, lat), along the meridian: what a
    /// resolution in metres becomes (degrees of latitude per metre for a geographic CRS, the
    /// projection's north–south scale for a projected one).
    pub fn units_per_metre(&self, lon: f64, lat: f64) -> f64 {
        const STEP_M: f64 = 100.0;
        // Metres per degree of latitude at `lat` (WGS84 meridian radius of curvature).
        let s = lat.to_radians().sin();
        let m_per_deg = (A * (1.0 - E2) / (1.0 - E2 * s * s).powf(1.5)).to_radians();
        let dlat = STEP_M / m_per_deg;
        let (x0, y0) = self.forward(lon, lat - dlat / 2.0);
        let (x1, y1) = self.forward(lon, lat + dlat / 2.0);
        (x1 - x0).hypot(y1 - y0) / STEP_M
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn utm_codes_use_the_exact_series() {
        let crs = Crs::from_epsg(32617).unwrap();
        assert_eq!(crs.utm_zone(), UtmZone::new(17, true).ok());
        assert!(!crs.is_geographic());
        let (lon, lat) = (-81.66, 30.31);
        assert_eq!(
            crs.forward(lon, lat),
            UtmZone::new(17, true).unwrap().forward(lon, lat)
        );
    }

    #[test]
    fn web_mercator_and_geographic_match_their_formulas() {
        let (lon, lat) = (-81.66_f64, 30.31_f64);
        let merc = Crs::from_epsg(3857).unwrap();
        let (x, y) = merc.forward(lon, lat);
        let r = 6_378_137.0;
        assert!((x - r * lon.to_radians()).abs() < 1e-6, "{x}");
        let y_ref = r
            * (std::f64::consts::FRAC_PI_4 + lat.to_radians() / 2.0)
                .tan()
                .ln();
        assert!((y - y_ref).abs() < 1e-6, "{y} {y_ref}");
        let (lon2, lat2) = merc.inverse(x, y);
        assert!((lon2 - lon).abs() < 1e-10 && (lat2 - lat).abs() < 1e-10);
        // A ground metre is about 1/cos(lat) Web Mercator metres (to the ellipsoid's 1 %).
        let k = merc.units_per_metre(lon, lat);
        assert!((k * lat.to_radians().cos() - 1.0).abs() < 0.01, "{k}");

        let geo = Crs::from_epsg(4326).unwrap();
        assert!(geo.is_geographic());
        let (x, y) = geo.forward(lon, lat);
        assert!((x - lon).abs() < 1e-12 && (y - lat).abs() < 1e-12);
        assert_eq!(geo.inverse(x, y), (x, y));
        // About 110.85 km per degree of latitude at 30°N.
        let k = geo.units_per_metre(lon, lat);
        assert!((1.0 / k - 110_853.0).abs() < 20.0, "{}", 1.0 / k);
    }

    #[test]
    fn a_national_grid_projects_as_published() {
        // EPSG:2236, NAD83 / Florida East (US survey feet): the benchmark's city in its state
        // plane. Round trip only (the datum shift of NAD83 to WGS84 is zero in PROJ.4's terms).
        let crs = Crs::from_epsg(2236).unwrap();
        let (lon, lat) = (-81.66, 30.31);
        let (x, y) = crs.forward(lon, lat);
        assert!(x.is_finite() && y.is_finite());
        let (lon2, lat2) = crs.inverse(x, y);
        assert!(
            (lon2 - lon).abs() < 1e-9 && (lat2 - lat).abs() < 1e-9,
            "{lon2} {lat2}"
        );
    }

    #[test]
    fn cells_keep_their_ground_size_in_any_crs() {
        let (lon, lat) = (-81.66, 30.31);
        let utm = Crs::from_epsg(32617).unwrap();
        assert_eq!(utm.cell_size(0.5, lon, lat), 0.5);
        let merc = Crs::from_epsg(3857).unwrap();
        let s = merc.cell_size(0.5, lon, lat);
        assert!((s * lat.to_radians().cos() - 0.5).abs() < 0.005, "{s}");
        let geo = Crs::from_epsg(4326).unwrap();
        assert!((geo.cell_size(0.5, lon, lat) * 110_853.0 - 0.5).abs() < 1e-3);
        assert_eq!(utm.length(0.5), "0.5 m");
        assert_eq!(merc.length(0.58152392), "0.5815 m");
        assert_eq!(geo.length(4.5103e-6), "4.510e-6°");
        // A 1 km UTM square seen in lon/lat, and back: it contains the square.
        let (e, n) = utm.forward(lon, lat);
        let square = [e, n, e + 1000.0, n + 1000.0];
        assert_eq!(utm.bounds_of(utm, square), square);
        let b = geo.bounds_of(utm, square);
        let back = utm.bounds_of(geo, b);
        assert!(back[0] <= e + 1e-6 && back[1] <= n + 1e-6);
        assert!(back[2] >= e + 1000.0 - 1e-6 && back[3] >= n + 1000.0 - 1e-6);
        assert!(back[2] - back[0] < 1020.0, "{back:?}");
    }

    #[test]
    fn unknown_codes_are_refused_with_the_code() {
        for code in [0, 1, 99_999_999] {
            let err = Crs::from_epsg(code).unwrap_err().to_string();
            assert!(err.contains(&format!("EPSG:{code}")), "{err}");
        }
    }
}

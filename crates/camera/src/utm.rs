//! WGS84 longitude/latitude ↔ UTM easting/northing.
//!
//! Krüger's series to order n⁶ (Karney, "Transverse Mercator with an accuracy of a few
//! nanometers", J. Geodesy 2011): nanometre-exact within a zone and well beyond it, which the
//! DSM gridding needs (a centimetre error moves points across 0.5 m cells). Written here rather
//! than taken from a crate so the accuracy is known; it is checked against pyproj in the tests.

use crate::{CameraError, Result};

/// WGS84 semi-major axis, metres.
pub(crate) const A: f64 = 6_378_137.0;
const F: f64 = 1.0 / 298.257_223_563;
const K0: f64 = 0.9996;
const FALSE_EASTING: f64 = 500_000.0;
const FALSE_NORTHING_SOUTH: f64 = 10_000_000.0;

/// Third flattening.
const N: f64 = F / (2.0 - F);
/// First eccentricity and its square.
pub(crate) const E2: f64 = F * (2.0 - F);

/// Rectifying radius times k0.
const K0_A: f64 =
    K0 * A / (1.0 + N) * (1.0 + N * N / 4.0 + N * N * N * N / 64.0 + N * N * N * N * N * N / 256.0);

const fn pow(x: f64, k: u32) -> f64 {
    let mut r = 1.0;
    let mut i = 0;
    while i < k {
        r *= x;
        i += 1;
    }
    r
}

/// Forward series coefficients α₁…α₆.
const ALPHA: [f64; 6] = [
    N / 2.0 - 2.0 / 3.0 * pow(N, 2) + 5.0 / 16.0 * pow(N, 3) + 41.0 / 180.0 * pow(N, 4)
        - 127.0 / 288.0 * pow(N, 5)
        + 7891.0 / 37800.0 * pow(N, 6),
    13.0 / 48.0 * pow(N, 2) - 3.0 / 5.0 * pow(N, 3)
        + 557.0 / 1440.0 * pow(N, 4)
        + 281.0 / 630.0 * pow(N, 5)
        - 1983433.0 / 1935360.0 * pow(N, 6),
    61.0 / 240.0 * pow(N, 3) - 103.0 / 140.0 * pow(N, 4)
        + 15061.0 / 26880.0 * pow(N, 5)
        + 167603.0 / 181440.0 * pow(N, 6),
    49561.0 / 161280.0 * pow(N, 4) - 179.0 / 168.0 * pow(N, 5) + 6601661.0 / 7257600.0 * pow(N, 6),
    34729.0 / 80640.0 * pow(N, 5) - 3418889.0 / 1995840.0 * pow(N, 6),
    212378941.0 / 319334400.0 * pow(N, 6),
];

/// Inverse series coefficients β₁…β₆.
const BETA: [f64; 6] = [
    N / 2.0 - 2.0 / 3.0 * pow(N, 2) + 37.0 / 96.0 * pow(N, 3)
        - 1.0 / 360.0 * pow(N, 4)
        - 81.0 / 512.0 * pow(N, 5)
        + 96199.0 / 604800.0 * pow(N, 6),
    1.0 / 48.0 * pow(N, 2) + 1.0 / 15.0 * pow(N, 3) - 437.0 / 1440.0 * pow(N, 4)
        + 46.0 / 105.0 * pow(N, 5)
        - 1118711.0 / 3870720.0 * pow(N, 6),
    17.0 / 480.0 * pow(N, 3) - 37.0 / 840.0 * pow(N, 4) - 209.0 / 4480.0 * pow(N, 5)
        + 5569.0 / 90720.0 * pow(N, 6),
    4397.0 / 161280.0 * pow(N, 4) - 11.0 / 504.0 * pow(N, 5) - 830251.0 / 7257600.0 * pow(N, 6),
    4583.0 / 161280.0 * pow(N, 5) - 108847.0 / 3991680.0 * pow(N, 6),
    20648693.0 / 638668800.0 * pow(N, 6),
];

/// A UTM zone of WGS84 (EPSG 326zz north, 327zz south).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct UtmZone {
    /// 1..=60.
    pub zone: u8,
    pub north: bool,
}

impl UtmZone {
    /// A zone checked to lie in 1..=60.
    pub fn new(zone: u8, north: bool) -> Result<Self> {
        if !(1..=60).contains(&zone) {
            return Err(CameraError::Input(format!(
                "UTM zone {zone} is outside 1..=60"
            )));
        }
        Ok(UtmZone { zone, north })
    }

    /// The zone of a WGS84/UTM EPSG code: 32601–32660 (north) or 32701–32760 (south).
    pub fn from_epsg(epsg: u32) -> Result<Self> {
        let (base, north) = match epsg {
            32601..=32660 => (32600, true),
            32701..=32760 => (32700, false),
            _ => {
                return Err(CameraError::Georeference(format!(
                    "EPSG:{epsg} is not a WGS84 UTM zone (32601–32660, 32701–32760)"
                )))
            }
        };
        Ok(UtmZone {
            zone: (epsg - base) as u8,
            north,
        })
    }

    /// The standard 6° zone containing (lon, lat) (without the Norway/Svalbard exceptions);
    /// latitude 0 counts as north.
    pub fn from_lonlat(lon: f64, lat: f64) -> Self {
        let lon = (lon + 180.0).rem_euclid(360.0);
        let zone = ((lon / 6.0).floor() as i64).clamp(0, 59) as u8 + 1;
        UtmZone {
            zone,
            north: lat >= 0.0,
        }
    }

    pub fn epsg(&self) -> u32 {
        if self.north {
            32600 + self.zone as u32
        } else {
            32700 + self.zone as u32
        }
    }

    /// Central meridian, degrees.
    pub fn central_meridian(&self) -> f64 {
        6.0 * self.zone as f64 - 183.0
    }

    fn false_northing(&self) -> f64 {
        if self.north {
            0.0
        } else {
            FALSE_NORTHING_SOUTH
        }
    }

    /// (easting, northing) in metres of WGS84 (lon, lat) in degrees.
    #[inline]
    pub fn forward(&self, lon: f64, lat: f64) -> (f64, f64) {
        let phi = lat.to_radians();
        let mut dlam = lon - self.central_meridian();
        dlam -= 360.0 * ((dlam + 180.0) / 360.0).floor();
        let lam = dlam.to_radians();
        let e = E2.sqrt();
        // Conformal latitude, as its tangent.
        let s = phi.sin();
        let t = (s.atanh() - e * (e * s).atanh()).sinh();
        let (sin_l, cos_l) = lam.sin_cos();
        let xi_p = t.atan2(cos_l);
        let eta_p = (sin_l / (1.0 + t * t).sqrt()).atanh();
        let (d_xi, d_eta) = clenshaw_sin(&ALPHA, xi_p, eta_p);
        let (xi, eta) = (xi_p + d_xi, eta_p + d_eta);
        (
            FALSE_EASTING + K0_A * eta,
            self.false_northing() + K0_A * xi,
        )
    }

    /// WGS84 (lon, lat) in degrees of (easting, northing) in metres.
    pub fn inverse(&self, easting: f64, northing: f64) -> (f64, f64) {
        let xi = (northing - self.false_northing()) / K0_A;
        let eta = (easting - FALSE_EASTING) / K0_A;
        let (mut xi_p, mut eta_p) = (xi, eta);
        for (j, b) in BETA.iter().enumerate() {
            let k = 2.0 * (j + 1) as f64;
            let (s2, c2) = (k * xi).sin_cos();
            xi_p -= b * s2 * (k * eta).cosh();
            eta_p -= b * c2 * (k * eta).sinh();
        }
        // Tangent of the conformal latitude, then of the geodetic one (Newton, as GeographicLib).
        let tau_p = xi_p.sin() / (eta_p.sinh().hypot(xi_p.cos()));
        let tau = tau_from_conformal(tau_p);
        let lat = tau.atan().to_degrees();
        let lon = self.central_meridian() + eta_p.sinh().atan2(xi_p.cos()).to_degrees();
        (lon, lat)
    }
}

/// Σⱼ cⱼ sin(2j ζ) for complex ζ = ξ + iη, as (real, imaginary) = (Σ cⱼ sin 2jξ cosh 2jη,
/// Σ cⱼ cos 2jξ sinh 2jη), by Clenshaw's recurrence: one sin/cos and one sinh/cosh instead of
/// six of each (the DSM gridding projects millions of points).
#[inline]
fn clenshaw_sin(c: &[f64; 6], xi: f64, eta: f64) -> (f64, f64) {
    let (s2, c2) = (2.0 * xi).sin_cos();
    let (sh2, ch2) = ((2.0 * eta).sinh(), (2.0 * eta).cosh());
    // y = 2 cos 2ζ and sin 2ζ, complex.
    let (yr, yi) = (2.0 * c2 * ch2, -2.0 * s2 * sh2);
    let (mut b1r, mut b1i, mut b2r, mut b2i) = (0.0, 0.0, 0.0, 0.0);
    for &ck in c.iter().rev() {
        let br = ck + (yr * b1r - yi * b1i) - b2r;
        let bi = (yr * b1i + yi * b1r) - b2i;
        (b2r, b2i, b1r, b1i) = (b1r, b1i, br, bi);
    }
    let (sr, si) = (s2 * ch2, c2 * sh2);
    (b1r * sr - b1i * si, b1r * si + b1i * sr)
}

/// Solves τ' = τ√(1+σ²) − σ√(1+τ²), σ = sinh(e·atanh(e τ/√(1+τ²))), for τ = tan φ.
fn tau_from_conformal(tau_p: f64) -> f64 {
    let e = E2.sqrt();
    let one_minus_e2 = 1.0 - E2;
    let mut tau = tau_p / one_minus_e2;
    for _ in 0..8 {
        let s1 = (1.0 + tau * tau).sqrt();
        let sigma = (e * (e * tau / s1).atanh()).sinh();
        let taupa = tau * (1.0 + sigma * sigma).sqrt() - sigma * s1;
        let dtau = (tau_p - taupa) * (1.0 + one_minus_e2 * tau * tau)
            / (one_minus_e2 * s1 * (1.0 + taupa * taupa).sqrt());
        tau += dtau;
        if dtau.abs() < 1e-15 * tau.abs().max(1.0) {
            break;
        }
    }
    tau
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zones() {
        assert_eq!(UtmZone::from_lonlat(-81.66, 30.35).epsg(), 32617);
        assert_eq!(UtmZone::from_lonlat(55.71, -21.23).epsg(), 32740);
        assert_eq!(
            UtmZone::from_epsg(32740).unwrap(),
            UtmZone::new(40, false).unwrap()
        );
        assert!(UtmZone::from_epsg(4326).is_err());
    }

    #[test]
    fn round_trip_far_from_the_central_meridian() {
        let z = UtmZone::new(17, true).unwrap();
        for &(lon, lat) in &[(-81.66, 30.35), (-84.9, 0.5), (-77.1, 70.0), (-90.0, 45.0)] {
            let (e, n) = z.forward(lon, lat);
            let (lo, la) = z.inverse(e, n);
            assert!(
                (lo - lon).abs() < 1e-11 && (la - lat).abs() < 1e-11,
                "{lo} {la}"
            );
        }
    }
}

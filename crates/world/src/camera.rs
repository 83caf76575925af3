//! The world's cameras: two pushbroom-like affine views, a local geographic frame, and their export as
//! degree-1 RPC models in the SatNeRF/rpcm JSON layout, so the satellite geometry code reads them like
//! any real camera.

use raster::Homography;
use serde_json::json;

/// Mean Earth radius used by the local frame, metres.
const EARTH_RADIUS_M: f64 = 6_378_137.0;

/// One view of the scene in rectified coordinates: a ground point (x, y, z) with x, y in ground
/// pixels and z in metres appears at column `x + slope·z + offset`, row `y`. Different slopes are
/// different incidence angles; epipolar lines are rows by construction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewCamera {
    /// Pixels of horizontal parallax per metre of altitude (tan of the incidence angle / GSD).
    pub slope: f64,
    /// Constant column shift, pixels.
    pub offset: f64,
}

impl ViewCamera {
    #[inline]
    pub fn column(&self, x: f64, z: f64) -> f64 {
        x + self.slope * z + self.offset
    }
}

/// Ground pixels ↔ longitude/latitude: a local north-up frame, linear around its origin.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GeoFrame {
    /// Longitude and latitude of ground pixel (0, 0), degrees.
    pub lon0: f64,
    pub lat0: f64,
    /// Metres per ground pixel.
    pub gsd: f64,
}

impl GeoFrame {
    fn degrees_per_pixel(&self) -> (f64, f64) {
        let lat_deg = (self.gsd / EARTH_RADIUS_M).to_degrees();
        (lat_deg / self.lat0.to_radians().cos(), lat_deg)
    }

    /// Longitude and latitude of ground pixel (x, y).
    pub fn lonlat(&self, x: f64, y: f64) -> (f64, f64) {
        let (dlon, dlat) = self.degrees_per_pixel();
        (self.lon0 + x * dlon, self.lat0 - y * dlat)
    }

    /// Ground pixel of (lon, lat).
    pub fn ground(&self, lon: f64, lat: f64) -> (f64, f64) {
        let (dlon, dlat) = self.degrees_per_pixel();
        ((lon - self.lon0) / dlon, (self.lat0 - lat) / dlat)
    }
}

/// An affine camera: raw image (col, row) = M · (lon, lat, alt, 1).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AffineCamera {
    pub col: [f64; 4],
    pub row: [f64; 4],
}

impl AffineCamera {
    /// The raw camera of a view whose rectified image is `rectify` (raw → rectified) of the raw one.
    pub fn from_view(view: &ViewCamera, geo: &GeoFrame, rectify: &Homography) -> Self {
        let unrectify = rectify
            .inverse()
            .expect("rectifying homographies are invertible");
        let m = &unrectify.0;
        assert!(
            m[2][0] == 0.0 && m[2][1] == 0.0,
            "the world's homographies are affine so that its cameras stay affine"
        );
        let (dlon, dlat) = geo.degrees_per_pixel();
        // Rectified (u, v) in terms of (lon, lat, alt, 1).
        let u = [1.0 / dlon, 0.0, view.slope, -geo.lon0 / dlon + view.offset];
        let v = [0.0, -1.0 / dlat, 0.0, geo.lat0 / dlat];
        let combine = |r: &[f64; 3]| {
            let mut out = [0.0; 4];
            for i in 0..4 {
                out[i] = (r[0] * u[i] + r[1] * v[i]) / m[2][2];
            }
            out[3] += r[2] / m[2][2];
            out
        };
        AffineCamera {
            col: combine(&m[0]),
            row: combine(&m[1]),
        }
    }

    /// Raw image (col, row) of a ground point.
    pub fn project(&self, lon: f64, lat: f64, alt: f64) -> (f64, f64) {
        let p = [lon, lat, alt, 1.0];
        let dot = |c: &[f64; 4]| c.iter().zip(&p).map(|(a, b)| a * b).sum::<f64>();
        (dot(&self.col), dot(&self.row))
    }

    /// The camera as a degree-1 RPC in the SatNeRF image JSON layout (`rpc` dict in rpcm's
    /// format: 20-term polynomials in the RPC00B order 1, lon, lat, alt, …; denominators 1).
    pub fn to_satnerf_json(
        &self,
        image_name: &str,
        width: usize,
        height: usize,
        centre_lonlat: (f64, f64),
        half_extent_deg: (f64, f64),
        alt_range: (f64, f64),
    ) -> serde_json::Value {
        let (lon_off, lat_off) = centre_lonlat;
        let (lon_scale, lat_scale) = half_extent_deg;
        let alt_off = (alt_range.0 + alt_range.1) / 2.0;
        let alt_scale = ((alt_range.1 - alt_range.0) / 2.0).max(1.0);
        let (col_off, row_off) = (width as f64 / 2.0, height as f64 / 2.0);
        let (col_scale, row_scale) = (width as f64 / 2.0, height as f64 / 2.0);
        let normalised = |a: &[f64; 4], off: f64, scale: f64| {
            let mut num = vec![0.0; 20];
            num[0] = (a[0] * lon_off + a[1] * lat_off + a[2] * alt_off + a[3] - off) / scale;
            num[1] = a[0] * lon_scale / scale;
            num[2] = a[1] * lat_scale / scale;
            num[3] = a[2] * alt_scale / scale;
            num
        };
        let mut den = vec![0.0; 20];
        den[0] = 1.0;
        json!({
            "img": image_name,
            "width": width,
            "height": height,
            "min_alt": alt_range.0,
            "max_alt": alt_range.1,
            "rpc": {
                "row_offset": row_off, "col_offset": col_off,
                "lat_offset": lat_off, "lon_offset": lon_off, "alt_offset": alt_off,
                "row_scale": row_scale, "col_scale": col_scale,
                "lat_scale": lat_scale, "lon_scale": lon_scale, "alt_scale": alt_scale,
                "row_num": normalised(&self.row, row_off, row_scale), "row_den": den.clone(),
                "col_num": normalised(&self.col, col_off, col_scale), "col_den": den,
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn affine_camera_composes_view_frame_and_homography() {
        let geo = GeoFrame {
            lon0: -81.66,
            lat0: 30.35,
            gsd: 0.5,
        };
        let view = ViewCamera {
            slope: 0.4,
            offset: -3.0,
        };
        let h = Homography([[0.998, -0.05, 12.0], [0.05, 0.998, -7.0], [0.0, 0.0, 1.0]]);
        let cam = AffineCamera::from_view(&view, &geo, &h);
        for &(x, y, z) in &[(10.0, 20.0, 0.0), (200.0, 35.5, 17.0), (-5.0, 300.0, 42.0)] {
            let (lon, lat) = geo.lonlat(x, y);
            let (col, row) = cam.project(lon, lat, z);
            let (u, v) = h.apply(col, row);
            assert!((u - view.column(x, z)).abs() < 1e-6, "u {u}");
            assert!((v - y).abs() < 1e-6, "v {v}");
        }
        let (gx, gy) = geo.ground(geo.lonlat(123.0, 45.0).0, geo.lonlat(123.0, 45.0).1);
        assert!((gx - 123.0).abs() < 1e-9 && (gy - 45.0).abs() < 1e-9);
    }

    #[test]
    fn rpc_json_reproduces_the_camera() {
        let geo = GeoFrame {
            lon0: 2.35,
            lat0: 48.85,
            gsd: 0.5,
        };
        let cam = AffineCamera::from_view(
            &ViewCamera {
                slope: -0.3,
                offset: 0.0,
            },
            &geo,
            &Homography::IDENTITY,
        );
        let centre = geo.lonlat(128.0, 128.0);
        let j = cam.to_satnerf_json("a", 256, 256, centre, (0.002, 0.002), (-5.0, 60.0));
        let rpc = &j["rpc"];
        let f = |k: &str| rpc[k].as_f64().unwrap();
        let poly = |k: &str| -> Vec<f64> {
            rpc[k]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_f64().unwrap())
                .collect()
        };
        let (lon, lat, alt) = (centre.0 + 0.0007, centre.1 - 0.0011, 23.0);
        let (l, p, h) = (
            (lon - f("lon_offset")) / f("lon_scale"),
            (lat - f("lat_offset")) / f("lat_scale"),
            (alt - f("alt_offset")) / f("alt_scale"),
        );
        let eval = |c: &[f64]| c[0] + c[1] * l + c[2] * p + c[3] * h;
        let col = eval(&poly("col_num")) * f("col_scale") + f("col_offset");
        let row = eval(&poly("row_num")) * f("row_scale") + f("row_offset");
        let (ec, er) = cam.project(lon, lat, alt);
        assert!((col - ec).abs() < 1e-6 && (row - er).abs() < 1e-6);
    }
}

//! GDAL's and GeoEye's `_RPC.TXT`: RPC00B as `KEY: value` lines, values possibly followed by a
//! unit (`+030.3003 degrees`, `pixels`, `meters`), the coefficients as `LINE_NUM_COEFF_1` … `_20`
//! in RPC00B term order.

use std::fmt::Write;
use std::path::Path;

use super::fields::{number, rpc_error, Rpc00b};
use crate::{Result, RpcModel};

const OFFSETS: [&str; 5] = ["LINE_OFF", "SAMP_OFF", "LAT_OFF", "LONG_OFF", "HEIGHT_OFF"];
const SCALES: [&str; 5] = [
    "LINE_SCALE",
    "SAMP_SCALE",
    "LAT_SCALE",
    "LONG_SCALE",
    "HEIGHT_SCALE",
];
const UNITS: [&str; 5] = ["pixels", "pixels", "degrees", "degrees", "meters"];
const POLYS: [&str; 4] = [
    "LINE_NUM_COEFF",
    "LINE_DEN_COEFF",
    "SAMP_NUM_COEFF",
    "SAMP_DEN_COEFF",
];

/// Reads a GDAL/GeoEye `_RPC.TXT` camera.
pub fn read_rpc_txt(path: &Path) -> Result<RpcModel> {
    let text = std::fs::read(path).map_err(|e| raster::RasterError::io(path, e))?;
    rpc_txt_from_text(&String::from_utf8_lossy(&text), &path.display().to_string())
}

pub(super) fn rpc_txt_from_text(text: &str, origin: &str) -> Result<RpcModel> {
    let pairs: Vec<(String, &str)> = text
        .lines()
        .filter_map(|l| l.split_once(':'))
        .map(|(k, v)| (k.trim().to_ascii_uppercase(), v.trim()))
        .collect();
    let get = |key: &str| {
        pairs
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| *v)
            .ok_or_else(|| rpc_error(origin, key, "missing"))
    };
    let scalar =
        |key: &str| -> Result<f64> { number(get(key)?).map_err(|m| rpc_error(origin, key, m)) };
    let scale = |key: &str| -> Result<f64> {
        let x = scalar(key)?;
        if x == 0.0 {
            return Err(rpc_error(origin, key, "a scale cannot be zero"));
        }
        Ok(x)
    };
    let poly = |name: &str| -> Result<[f64; 20]> {
        let extra = format!("{name}_21");
        if pairs.iter().any(|(k, _)| *k == extra) {
            return Err(rpc_error(origin, &extra, "more than 20 coefficients"));
        }
        let mut out = [0.0; 20];
        for (i, o) in out.iter_mut().enumerate() {
            *o = scalar(&format!("{name}_{}", i + 1))?;
        }
        Ok(out)
    };
    let mut offsets = [0.0; 5];
    let mut scales = [0.0; 5];
    for i in 0..5 {
        offsets[i] = scalar(OFFSETS[i])?;
        scales[i] = scale(SCALES[i])?;
    }
    Rpc00b {
        offsets,
        scales,
        polys: [
            poly(POLYS[0])?,
            poly(POLYS[1])?,
            poly(POLYS[2])?,
            poly(POLYS[3])?,
        ],
    }
    .into_model(origin)
}

/// The `_RPC.TXT` text of `m`; `{}` formatting gives the shortest digits that read back exactly.
pub(super) fn write(m: &RpcModel) -> String {
    let offsets = [
        m.row_offset,
        m.col_offset,
        m.lat_offset,
        m.lon_offset,
        m.alt_offset,
    ];
    let scales = [
        m.row_scale,
        m.col_scale,
        m.lat_scale,
        m.lon_scale,
        m.alt_scale,
    ];
    let mut s = String::new();
    for i in 0..5 {
        let _ = writeln!(s, "{}: {} {}", OFFSETS[i], offsets[i], UNITS[i]);
    }
    for i in 0..5 {
        let _ = writeln!(s, "{}: {} {}", SCALES[i], scales[i], UNITS[i]);
    }
    for (name, poly) in POLYS
        .iter()
        .zip([&m.row_num, &m.row_den, &m.col_num, &m.col_den])
    {
        for (j, c) in poly.iter().enumerate() {
            let _ = writeln!(s, "{name}_{}: {c}", j + 1);
        }
    }
    s
}

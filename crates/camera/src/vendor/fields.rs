//! What the vendor files share: the acquisition they describe, the RPC00B coefficients they
//! carry, how their numbers and dates read, and the errors naming a file and its key.

use std::path::PathBuf;

use crate::{CameraError, Result, RpcModel};

/// When and under which sun and view an image was taken, as its metadata says.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Acquisition {
    /// UTC date and time of acquisition as `YYYYMMDDhhmmss` (seconds truncated), the form the
    /// rest of the product takes; `None` when the metadata gives none.
    pub datetime: Option<String>,
    /// Sun elevation above the horizon, degrees.
    pub sun_elevation: Option<f64>,
    /// Sun azimuth, degrees clockwise from north.
    pub sun_azimuth: Option<f64>,
    /// Satellite elevation seen from the scene, degrees.
    pub satellite_elevation: Option<f64>,
    /// Satellite azimuth seen from the scene, degrees clockwise from north.
    pub satellite_azimuth: Option<f64>,
    /// The file the values were read from.
    pub source: PathBuf,
}

pub(crate) fn rpc_error(origin: &str, key: &str, message: impl Into<String>) -> CameraError {
    CameraError::Rpc {
        origin: origin.to_string(),
        key: key.to_string(),
        message: message.into(),
    }
}

pub(crate) fn metadata_error(origin: &str, key: &str, message: impl Into<String>) -> CameraError {
    CameraError::Metadata {
        origin: origin.to_string(),
        key: key.to_string(),
        message: message.into(),
    }
}

/// The first whitespace-separated token of `text` as a finite number (vendor values may carry a
/// unit after it, `+030.3003 degrees`); the error message otherwise.
pub(crate) fn number(text: &str) -> std::result::Result<f64, String> {
    let token = text
        .split_whitespace()
        .next()
        .ok_or_else(|| "no value".to_string())?;
    let x: f64 = token
        .parse()
        .map_err(|_| format!("not a number: {token:?}"))?;
    if !x.is_finite() {
        return Err(format!("not finite: {token:?}"));
    }
    Ok(x)
}

/// The named offsets, scales and 20-term polynomials of an RPC00B model, checked and assembled.
pub(crate) struct Rpc00b {
    /// `[line, samp, lat, long, height]` offsets.
    pub offsets: [f64; 5],
    /// `[line, samp, lat, long, height]` scales.
    pub scales: [f64; 5],
    /// Line numerator and denominator, sample numerator and denominator.
    pub polys: [[f64; 20]; 4],
}

impl Rpc00b {
    pub fn into_model(self, origin: &str) -> Result<RpcModel> {
        let [row_offset, col_offset, lat_offset, lon_offset, alt_offset] = self.offsets;
        let [row_scale, col_scale, lat_scale, lon_scale, alt_scale] = self.scales;
        let [row_num, row_den, col_num, col_den] = self.polys;
        let model = RpcModel {
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
            row_den,
            col_num,
            col_den,
            min_alt: None,
            max_alt: None,
        };
        model.check(origin)?;
        Ok(model)
    }
}

/// `YYYYMMDDhhmmss` from a date `YYYY-MM-DD` and a time `hh:mm:ss[.fff][Z]` (midnight when
/// absent); `None` when either is malformed.
pub(crate) fn compact_datetime(date: &str, time: Option<&str>) -> Option<String> {
    let mut d = date.trim().split('-');
    let (y, mo, da) = (d.next()?, d.next()?, d.next()?);
    if d.next().is_some() || y.len() != 4 || mo.len() != 2 || da.len() != 2 {
        return None;
    }
    let (h, mi, s) = match time.map(str::trim) {
        None | Some("") => ("00", "00", "00"),
        Some(t) => {
            let t = t.strip_suffix('Z').unwrap_or(t);
            let mut p = t.split(':');
            let (h, mi, s) = (p.next()?, p.next()?, p.next()?);
            if p.next().is_some() {
                return None;
            }
            let s = s.split('.').next()?;
            if h.len() != 2 || mi.len() != 2 || s.len() != 2 {
                return None;
            }
            (h, mi, s)
        }
    };
    nitf_datetime(&format!("{y}{mo}{da}{h}{mi}{s}"))
}

/// `YYYYMMDDhhmmss` from an ISO 8601 date-time `YYYY-MM-DDThh:mm:ss[.fff]Z`.
pub(crate) fn iso_datetime(text: &str) -> Option<String> {
    let text = text.trim();
    match text.split_once(['T', ' ']) {
        Some((date, time)) => compact_datetime(date, Some(time)),
        None => compact_datetime(text, None),
    }
}

/// A 14-digit `YYYYMMDDhhmmss` with plausible fields (NITF's `IDATIM`), as is.
pub(crate) fn nitf_datetime(text: &str) -> Option<String> {
    let t = text.trim();
    if t.len() != 14 || !t.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    let field = |a: usize, b: usize| t[a..b].parse::<u32>().ok();
    let (mo, d, h, mi, s) = (
        field(4, 6)?,
        field(6, 8)?,
        field(8, 10)?,
        field(10, 12)?,
        field(12, 14)?,
    );
    let ok = (1..=12).contains(&mo) && (1..=31).contains(&d) && h < 24 && mi < 60 && s < 61;
    ok.then(|| t.to_string())
}

//! Pléiades/SPOT DIMAP: the `RPC_*.XML` camera and the `DIM_*.XML` product metadata.
//!
//! The camera is the `Inverse_Model` (ground → image, DIMAP v3 `GroundtoImage_Values`) of
//! `<Global_RFM>` (v3 `<Rational_Function_Model>`), its offsets and scales in `<RFM_Validity>`.
//! Its coefficients `SAMP_NUM_COEFF_1` … `_20` etc. are in the RPC00B term order, which GDAL
//! hands on to the same RPC code as an RPB's. DIMAP image coordinates are 1-based (the centre
//! of the first pixel is (1, 1)) while [`RpcModel`]'s are 0-based, so, as GDAL does, the index
//! of the first pixel is subtracted from `LINE_OFF` and `SAMP_OFF`: 1, or DIMAP v3's
//! `ImagetoGround_Validity_Domain/FIRST_COL` when given. The offset GDAL adds for the tiles of a tiled product other than `R1C1` is not applied.

use std::path::Path;

use super::fields::{
    compact_datetime, iso_datetime, metadata_error, number, rpc_error, Acquisition, Rpc00b,
};
use super::xml::{leaves, Leaf};
use crate::{Result, RpcModel};

const VALIDITY: [&str; 10] = [
    "LINE_OFF",
    "SAMP_OFF",
    "LAT_OFF",
    "LONG_OFF",
    "HEIGHT_OFF",
    "LINE_SCALE",
    "SAMP_SCALE",
    "LAT_SCALE",
    "LONG_SCALE",
    "HEIGHT_SCALE",
];
const POLYS: [&str; 4] = [
    "LINE_NUM_COEFF",
    "LINE_DEN_COEFF",
    "SAMP_NUM_COEFF",
    "SAMP_DEN_COEFF",
];

fn read_leaves(
    path: &Path,
    error: fn(&str, &str, String) -> crate::CameraError,
) -> Result<Vec<Leaf>> {
    let bytes = std::fs::read(path).map_err(|e| raster::RasterError::io(path, e))?;
    leaves(&String::from_utf8_lossy(&bytes)).map_err(|m| {
        error(
            &path.display().to_string(),
            "",
            format!("malformed XML: {m}"),
        )
    })
}

/// Reads a DIMAP `RPC_*.XML` camera, its image offsets made 0-based.
pub fn read_dimap_rpc(path: &Path) -> Result<RpcModel> {
    let leaves = read_leaves(path, rpc_error)?;
    dimap_rpc_from_leaves(&leaves, &path.display().to_string())
}

pub(super) fn dimap_rpc_from_leaves(leaves: &[Leaf], origin: &str) -> Result<RpcModel> {
    let in_model = |l: &Leaf| {
        l.within("Global_RFM").is_some() || l.within("Rational_Function_Model").is_some()
    };
    if !leaves.iter().any(in_model) {
        return Err(rpc_error(
            origin,
            "Global_RFM",
            "no <Global_RFM> or <Rational_Function_Model>: not a DIMAP RPC file",
        ));
    }
    let value = |parents: &[&str], key: &str| -> Result<f64> {
        let leaf = leaves
            .iter()
            .find(|l| {
                l.name == key && in_model(l) && l.parent().is_some_and(|p| parents.contains(&p))
            })
            .ok_or_else(|| rpc_error(origin, &format!("{}.{key}", parents[0]), "missing"))?;
        number(&leaf.text).map_err(|m| rpc_error(origin, &format!("{}.{key}", parents[0]), m))
    };
    let mut v = [0.0; 10];
    for (x, key) in v.iter_mut().zip(VALIDITY) {
        *x = value(&["RFM_Validity"], key)?;
    }
    for (i, key) in VALIDITY[5..].iter().enumerate() {
        if v[5 + i] == 0.0 {
            return Err(rpc_error(
                origin,
                &format!("RFM_Validity.{key}"),
                "a scale cannot be zero",
            ));
        }
    }
    let first = match leaves
        .iter()
        .find(|l| l.name == "FIRST_COL" && l.parent() == Some("ImagetoGround_Validity_Domain"))
    {
        Some(l) => number(&l.text)
            .map_err(|m| rpc_error(origin, "ImagetoGround_Validity_Domain.FIRST_COL", m))?,
        None => 1.0,
    };
    let models = ["Inverse_Model", "GroundtoImage_Values"];
    let mut polys = [[0.0; 20]; 4];
    for (poly, name) in polys.iter_mut().zip(POLYS) {
        let extra = format!("{name}_21");
        if leaves.iter().any(|l| l.name == extra && in_model(l)) {
            return Err(rpc_error(
                origin,
                &format!("Inverse_Model.{extra}"),
                "more than 20 coefficients",
            ));
        }
        for (j, c) in poly.iter_mut().enumerate() {
            *c = value(&models, &format!("{name}_{}", j + 1))?;
        }
    }
    Rpc00b {
        offsets: [v[0] - first, v[1] - first, v[2], v[3], v[4]],
        scales: [v[5], v[6], v[7], v[8], v[9]],
        polys,
    }
    .into_model(origin)
}

/// Reads a DIMAP `DIM_*.XML`: the acquisition date and time (`IMAGING_DATE` and `IMAGING_TIME`
/// of the first `Strip_Source`, as GDAL reads them, else the `TIME` of the centre's
/// `Located_Geometric_Values`) and the sun angles there (`SUN_ELEVATION`, `SUN_AZIMUTH`). The
/// satellite angles are left out: DIMAP gives viewing incidence and azimuth in conventions this
/// reader does not convert.
pub fn read_dimap_metadata(path: &Path) -> Result<Acquisition> {
    let leaves = read_leaves(path, metadata_error)?;
    dimap_metadata_from_leaves(&leaves, path)
}

pub(super) fn dimap_metadata_from_leaves(leaves: &[Leaf], path: &Path) -> Result<Acquisition> {
    let origin = path.display().to_string();
    let strip = |key: &str| {
        leaves
            .iter()
            .find(|l| l.name == key && l.within("Strip_Source").is_some())
            .map(|l| l.text.as_str())
    };
    // The centre's located values, else the first ones.
    let located = leaves
        .iter()
        .find(|l| l.name == "LOCATION_TYPE" && l.text.eq_ignore_ascii_case("center"))
        .and_then(|l| l.within("Located_Geometric_Values"))
        .or_else(|| {
            leaves
                .iter()
                .find_map(|l| l.within("Located_Geometric_Values"))
        });
    let at_centre = |key: &str| {
        located.and_then(|id| {
            leaves
                .iter()
                .find(|l| l.name == key && l.within("Located_Geometric_Values") == Some(id))
                .map(|l| l.text.as_str())
        })
    };
    let datetime = if let Some(date) = strip("IMAGING_DATE") {
        let time = strip("IMAGING_TIME");
        Some(compact_datetime(date, time).ok_or_else(|| {
            metadata_error(
                &origin,
                "Strip_Source.IMAGING_DATE",
                format!("not a date and time: {date:?} {:?}", time.unwrap_or("")),
            )
        })?)
    } else if let Some(time) = at_centre("TIME") {
        Some(iso_datetime(time).ok_or_else(|| {
            metadata_error(
                &origin,
                "Located_Geometric_Values.TIME",
                format!("not a date-time: {time:?}"),
            )
        })?)
    } else {
        None
    };
    let angle = |key: &str| -> Result<Option<f64>> {
        match at_centre(key) {
            None => Ok(None),
            Some(v) => number(v)
                .map(Some)
                .map_err(|m| metadata_error(&origin, &format!("Solar_Incidences.{key}"), m)),
        }
    };
    Ok(Acquisition {
        datetime,
        sun_elevation: angle("SUN_ELEVATION")?,
        sun_azimuth: angle("SUN_AZIMUTH")?,
        satellite_elevation: None,
        satellite_azimuth: None,
        source: path.to_path_buf(),
    })
}

//! LAS 1.2 and LAZ through the `las` crate: point format 2 (RGB) or 0, coordinates scaled to a
//! millimetre (1e-7 degree on a geographic grid) from the grid's south-west corner, and the CRS
//! as GeoTIFF keys in a `LASF_Projection` VLR, the way LAS 1.2 readers (laspy, PDAL, LAStools)
//! look for it.

use std::fs::File;
use std::io::BufWriter;
use std::path::Path;

use camera::DsmGrid;
use las::point::Format;
use las::{Builder, Color, Header, Point, Transform, Vector, Vlr, Writer};

use super::cells::Cells;
use crate::atomic::write_owned_atomically;
use crate::{ProductsError, Result};

/// Record id of the GeoKeyDirectoryTag VLR (the GeoTIFF tag's number).
const GEOKEY_DIRECTORY_RECORD: u16 = 34735;
/// User id of the LAS specification's projection VLRs.
const PROJECTION_USER_ID: &str = "LASF_Projection";

/// GeoTIFF keys written (GeoTIFF 1.0 names and numbers).
const GT_MODEL_TYPE: u16 = 1024;
const GT_RASTER_TYPE: u16 = 1025;
const GEOGRAPHIC_TYPE: u16 = 2048;
const PROJECTED_CS_TYPE: u16 = 3072;
const VERTICAL_UNITS: u16 = 4099;
/// EPSG unit code of the metre.
const METRE: u16 = 9001;

/// Writes the points of `cells` as LAS (or LAZ when `compressed`) at `path`; returns their
/// number.
pub(super) fn write(path: &Path, grid: &DsmGrid, cells: &Cells, compressed: bool) -> Result<usize> {
    let header = header(path, grid, cells.colours.is_some(), compressed)?;
    let las_err = |e: las::Error| ProductsError::point_cloud(path, e);
    let mut n = 0;
    write_owned_atomically(path, |file| {
        let mut writer = Writer::new(BufWriter::new(file), header).map_err(las_err)?;
        if let Err(e) = write_points(&mut writer, cells, &mut n) {
            // Dropping an unclosed writer closes it and panics on failure: after an I/O error,
            // leak it instead (the temporary file is removed all the same).
            std::mem::forget(writer);
            return Err(las_err(e));
        }
        let buffered = writer.into_inner().map_err(las_err)?;
        buffered
            .into_inner()
            .map_err(|e| ProductsError::point_cloud(path, e.error()))
    })?;
    Ok(n)
}

/// Writes every point of `cells`, counting them in `n`.
fn write_points(
    writer: &mut Writer<BufWriter<File>>,
    cells: &Cells,
    n: &mut usize,
) -> las::Result<()> {
    for p in cells.iter() {
        writer.write_point(Point {
            x: p.x,
            y: p.y,
            z: p.z,
            return_number: 1,
            number_of_returns: 1,
            color: p.rgb.map(|[r, g, b]| Color {
                red: u16::from(r) * 257,
                green: u16::from(g) * 257,
                blue: u16::from(b) * 257,
            }),
            ..Point::default()
        })?;
        *n += 1;
    }
    Ok(())
}

/// The header: LAS 1.2, the point format, the scales and offsets, the CRS's VLR.
fn header(path: &Path, grid: &DsmGrid, coloured: bool, compressed: bool) -> Result<Header> {
    let crs = grid.crs();
    let mut builder = Builder::from((1, 2));
    builder.point_format = Format::new(if coloured { 2 } else { 0 })
        .map_err(|e| ProductsError::point_cloud(path, e))?;
    builder.point_format.is_compressed = compressed;
    builder.system_identifier = "seasonstereo".into();
    builder.generating_software = "seasonstereo products".into();
    let xy_scale = if crs.is_geographic() { 1e-7 } else { 1e-3 };
    let y_min = grid.y0 - grid.height as f64 * grid.resolution;
    let transform = |scale, offset| Transform { scale, offset };
    builder.transforms = Vector {
        x: transform(xy_scale, grid.x0),
        y: transform(xy_scale, y_min),
        z: transform(1e-3, 0.0),
    };
    builder
        .vlrs
        .push(geokey_vlr(path, grid.epsg, crs.is_geographic())?);
    builder
        .into_header()
        .map_err(|e| ProductsError::point_cloud(path, e))
}

/// The GeoKeyDirectoryTag of an EPSG code, as a GeoTIFF stores it: a header (version 1, revision
/// 1.0, key count) then (key, location 0 = inline, count 1, value) per key, in key order.
fn geokey_vlr(path: &Path, epsg: u32, geographic: bool) -> Result<Vlr> {
    let code = u16::try_from(epsg).map_err(|_| {
        ProductsError::point_cloud(path, format!("EPSG:{epsg} does not fit a GeoTIFF key"))
    })?;
    let keys: [(u16, u16); 4] = if geographic {
        [
            (GT_MODEL_TYPE, 2),
            (GT_RASTER_TYPE, 1),
            (GEOGRAPHIC_TYPE, code),
            (VERTICAL_UNITS, METRE),
        ]
    } else {
        [
            (GT_MODEL_TYPE, 1),
            (GT_RASTER_TYPE, 1),
            (PROJECTED_CS_TYPE, code),
            (VERTICAL_UNITS, METRE),
        ]
    };
    let mut words = vec![1, 1, 0, keys.len() as u16];
    for (key, value) in keys {
        words.extend_from_slice(&[key, 0, 1, value]);
    }
    Ok(Vlr {
        user_id: PROJECTION_USER_ID.into(),
        record_id: GEOKEY_DIRECTORY_RECORD,
        description: "GeoTIFF GeoKeyDirectoryTag".into(),
        data: words.iter().flat_map(|w| w.to_le_bytes()).collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn geokeys_are_sorted_and_inline() {
        let vlr = geokey_vlr(Path::new("x.las"), 32617, false).unwrap();
        let words: Vec<u16> = vlr
            .data
            .chunks_exact(2)
            .map(|b| u16::from_le_bytes([b[0], b[1]]))
            .collect();
        assert_eq!(&words[..4], &[1, 1, 0, 4]);
        let keys: Vec<u16> = words[4..].chunks_exact(4).map(|e| e[0]).collect();
        assert_eq!(keys, [1024, 1025, 3072, 4099]);
        assert!(words[4..].chunks_exact(4).all(|e| e[1] == 0 && e[2] == 1));
        assert_eq!(words[4 + 2 * 4 + 3], 32617);
    }
}

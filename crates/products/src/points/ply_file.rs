//! Binary PLY, as s2p writes its clouds: a text header, then per vertex x y z as little-endian
//! doubles and, when coloured, red green blue as bytes. Doubles because UTM coordinates need more
//! digits than a float has.

use std::io::Write;
use std::path::Path;

use camera::DsmGrid;
use raster::formats::write_atomically;

use super::cells::Cells;
use crate::Result;

/// Writes the points of `cells` as a binary little-endian PLY at `path`; returns their number.
pub(super) fn write(path: &Path, grid: &DsmGrid, cells: &Cells) -> Result<usize> {
    let n = cells.count();
    let header = header(grid, n, cells.colours.is_some());
    write_atomically(path, |w| {
        w.write_all(header.as_bytes())?;
        for p in cells.iter() {
            w.write_all(&p.x.to_le_bytes())?;
            w.write_all(&p.y.to_le_bytes())?;
            w.write_all(&p.z.to_le_bytes())?;
            if let Some(rgb) = p.rgb {
                w.write_all(&rgb)?;
            }
        }
        Ok(())
    })?;
    Ok(n)
}

/// The PLY header of `n` vertices; the CRS goes in a comment, as PLY has no field for it.
fn header(grid: &DsmGrid, n: usize, coloured: bool) -> String {
    let mut h = format!(
        "ply\nformat binary_little_endian 1.0\ncomment created by seasonstereo\n\
         comment crs EPSG:{}\nelement vertex {n}\n\
         property double x\nproperty double y\nproperty double z\n",
        grid.epsg
    );
    if coloured {
        h.push_str("property uchar red\nproperty uchar green\nproperty uchar blue\n");
    }
    h.push_str("end_header\n");
    h
}

//! The quicklook of a DSM: heights in colour (turbo) over a hillshade lit from the north-west, the
//! picture the demo's report draws, as a PNG small enough to open anywhere.

use std::path::Path;

use camera::DsmGrid;
use raster::formats::{write_png, PngDepth};
use raster::resize::block_mean_finite;
use raster::{colormap, Image};

use crate::Result;

/// Longest side of a quicklook, pixels: larger DSMs are shrunk by a whole factor (the mean of
/// the finite heights of each block), so a city-wide DSM still gives a picture of a few MB.
pub const PREVIEW_MAX_SIDE: usize = 2048;

/// Lambertian hillshade of a DSM (north-up, square cells of `cell` metres) lit from azimuth
/// `azimuth_deg` (clockwise from north) at `elevation_deg`: 0 (dark) … 1 (facing the sun); NaN
/// where the DSM is NaN. A missing neighbour counts as flat ground at the cell's own height.
pub fn hillshade(dsm: &Image, cell: f64, azimuth_deg: f64, elevation_deg: f64) -> Image {
    let (w, h) = dsm.size();
    let (az, el) = (azimuth_deg.to_radians(), elevation_deg.to_radians());
    let sun = [az.sin() * el.cos(), az.cos() * el.cos(), el.sin()];
    let z = |x: usize, y: usize| dsm.get(x, y, 0) as f64;
    let mut out = Image::filled(w, h, 1, f32::NAN);
    for y in 0..h {
        for x in 0..w {
            let c = z(x, y);
            if !c.is_finite() {
                continue;
            }
            let at = |x: Option<usize>, y: Option<usize>| match (x, y) {
                (Some(x), Some(y)) if x < w && y < h && z(x, y).is_finite() => z(x, y),
                _ => c,
            };
            let east = (at(Some(x + 1), Some(y)) - at(x.checked_sub(1), Some(y))) / (2.0 * cell);
            let north = (at(Some(x), y.checked_sub(1)) - at(Some(x), Some(y + 1))) / (2.0 * cell);
            let n = [-east, -north, 1.0];
            let norm = (n[0] * n[0] + n[1] * n[1] + 1.0).sqrt();
            let shade = (n[0] * sun[0] + n[1] * sun[1] + n[2] * sun[2]) / norm;
            out.set(x, y, 0, shade.max(0.0) as f32);
        }
    }
    out
}

/// A DSM as an RGB picture: heights through the turbo map over `range` (default: the 2nd–98th
/// percentile), darkened by the hillshade (so roofs, walls and relief read as shapes); cells
/// without height are black.
pub fn dsm_picture(dsm: &Image, cell: f64, range: Option<(f32, f32)>) -> Image {
    let mut colour = colormap::colorize(dsm, range);
    let shade = hillshade(dsm, cell, 315.0, 45.0);
    let (w, h) = dsm.size();
    for y in 0..h {
        for x in 0..w {
            let s = shade.get(x, y, 0);
            let k = if s.is_finite() { 0.35 + 0.65 * s } else { 0.0 };
            for c in 0..3 {
                colour.set(x, y, c, colour.get(x, y, c) * k);
            }
        }
    }
    colour
}

/// Writes the quicklook of `dsm` (lying on `grid`) as an 8-bit RGBA PNG, atomically: the
/// [`dsm_picture`] of the heights, cells without height transparent. A DSM longer than
/// [`PREVIEW_MAX_SIDE`] is shrunk first.
pub fn write_preview(path: &Path, dsm: &Image, grid: &DsmGrid) -> Result<()> {
    grid.check_heights(dsm, &path.display().to_string())?;
    let factor = dsm.width().max(dsm.height()).div_ceil(PREVIEW_MAX_SIDE);
    let small = block_mean_finite(dsm, factor);
    let picture = dsm_picture(&small, cell_metres(grid) * factor as f64, None);
    let (w, h) = small.size();
    let mut rgba = Vec::with_capacity(w * h * 4);
    for (rgb, z) in picture.data().chunks_exact(3).zip(small.data()) {
        rgba.extend_from_slice(rgb);
        rgba.push(if z.is_finite() { 255.0 } else { 0.0 });
    }
    let rgba = Image::new(w, h, 4, rgba).expect("four samples per cell");
    Ok(write_png(path, &rgba, PngDepth::Eight)?)
}

/// The ground size of a cell of `grid`, metres (a geographic grid's cells are degrees).
fn cell_metres(grid: &DsmGrid) -> f64 {
    let (lon, lat) = grid.centre_lonlat();
    let per_metre = grid.crs().units_per_metre(lon, lat);
    if per_metre.is_finite() && per_metre > 0.0 {
        grid.resolution / per_metre
    } else {
        grid.resolution
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hillshade_lights_slopes_facing_the_sun() {
        // A ramp rising towards the east: it faces west, away from a sun in the east.
        let ramp = Image::new(3, 3, 1, (0..9).map(|i| (i % 3) as f32).collect()).unwrap();
        let flat = Image::filled(3, 3, 1, 5.0);
        let east_sun = hillshade(&ramp, 1.0, 90.0, 45.0).get(1, 1, 0);
        let west_sun = hillshade(&ramp, 1.0, 270.0, 45.0).get(1, 1, 0);
        let level = hillshade(&flat, 1.0, 90.0, 45.0).get(1, 1, 0);
        assert!(
            west_sun > level && level > east_sun,
            "{west_sun} {level} {east_sun}"
        );
        assert!((level - 45f32.to_radians().sin()).abs() < 1e-6);
        let mut hole = flat.clone();
        hole.set(0, 0, 0, f32::NAN);
        let h = hillshade(&hole, 1.0, 90.0, 45.0);
        assert!(h.get(0, 0, 0).is_nan() && h.get(1, 0, 0).is_finite());
    }

    #[test]
    fn shrinking_averages_the_finite_heights() {
        let dsm = Image::new(3, 2, 1, vec![1.0, 3.0, f32::NAN, 5.0, f32::NAN, f32::NAN]).unwrap();
        let small = block_mean_finite(&dsm, 2);
        assert_eq!(small.size(), (2, 1));
        assert_eq!(small.get(0, 0, 0), 3.0);
        assert!(small.get(1, 0, 0).is_nan());
    }
}

//! Heights above the EGM96 geoid (≈ mean sea level) from the ellipsoidal heights the RPC cameras
//! give: h_geoid = h_ellipsoid − N(lon, lat), N the geoid's undulation, computed from EGM96's
//! spherical-harmonic coefficients to degree 360 (the `egm96` crate ships them; no grid file).
//! N varies by centimetres over kilometres, so it is computed on a lattice of the grid and
//! interpolated between.

use raster::Image;
use rayon::prelude::*;

use crate::DsmGrid;

/// The EGM96 geoid undulation N (metres above the WGS84 ellipsoid) at (lon, lat) in degrees.
pub fn egm96_undulation(lon: f64, lat: f64) -> f64 {
    egm96::egm96_compute_altitude_offset(lat, lon)
}

/// Cells between two exact evaluations of N: 256 cells of 0.5 m are 128 m, over which EGM96
/// bends by well under a millimetre.
const LATTICE: usize = 256;

/// `dsm` (ellipsoidal heights on `grid`) turned into heights above the EGM96 geoid, in place.
pub fn to_egm96(dsm: &mut Image, grid: &DsmGrid) {
    let crs = grid.crs();
    let nodes = |n: usize| n.div_ceil(LATTICE) + 1;
    let (nx, ny) = (nodes(grid.width), nodes(grid.height));
    let node = |k: usize, len: usize| (k * LATTICE).min(len) as f64;
    let lattice: Vec<f64> = (0..nx * ny)
        .into_par_iter()
        .map(|i| {
            let (c, r) = (node(i % nx, grid.width), node(i / nx, grid.height));
            let x = grid.x0 + c * grid.resolution;
            let y = grid.y0 - r * grid.resolution;
            let (lon, lat) = crs.inverse(x, y);
            egm96_undulation(lon, lat)
        })
        .collect();
    let width = grid.width;
    dsm.data_mut()
        .par_chunks_mut(width)
        .enumerate()
        .for_each(|(row, heights)| {
            let fy = (row as f64 + 0.5) / LATTICE as f64;
            let (r0, ty) = ((fy.floor() as usize).min(ny - 2), fy.fract());
            for (col, h) in heights.iter_mut().enumerate() {
                let fx = (col as f64 + 0.5) / LATTICE as f64;
                let (c0, tx) = ((fx.floor() as usize).min(nx - 2), fx.fract());
                let at = |r: usize, c: usize| lattice[r * nx + c];
                let top = at(r0, c0) * (1.0 - tx) + at(r0, c0 + 1) * tx;
                let bottom = at(r0 + 1, c0) * (1.0 - tx) + at(r0 + 1, c0 + 1) * tx;
                *h -= (top * (1.0 - ty) + bottom * ty) as f32;
            }
        });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn undulations_are_egm96s() {
        // Published EGM96 values (NGA's 15' grid, interpolated): Everest's summit −28.74 m.
        assert!((egm96_undulation(86.925278, 27.988056) + 28.74).abs() < 0.1);
        // Jacksonville, the dev area: about −29 m, its ground at −27 m ellipsoidal is ~2 m.
        let n = egm96_undulation(-81.66, 30.31);
        assert!((-31.0..-27.0).contains(&n), "{n}");
    }

    #[test]
    fn a_dsm_is_lifted_by_the_interpolated_undulation() {
        let grid = DsmGrid::new(436_000.0, 3_358_000.0, 0.5, 600, 300, 32617).unwrap();
        let mut dsm = Image::filled(600, 300, 1, -27.0);
        dsm.set(5, 5, 0, f32::NAN);
        to_egm96(&mut dsm, &grid);
        for (col, row) in [(0, 0), (599, 299), (300, 150), (257, 31)] {
            let (x, y) = grid.cell_centre(col, row);
            let (lon, lat) = grid.crs().inverse(x, y);
            let exact = -27.0 - egm96_undulation(lon, lat);
            let got = dsm.get(col, row, 0) as f64;
            assert!((got - exact).abs() < 2e-3, "{col},{row}: {got} {exact}");
        }
        assert!(dsm.get(5, 5, 0).is_nan());
    }
}

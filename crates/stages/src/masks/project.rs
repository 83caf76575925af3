//! A raster on a UTM DSM grid seen from a camera: every cell is projected into the image through
//! the RPC at its own altitude, and each pixel keeps the value of the highest cell that lands on
//! it (a z-buffer: a pushbroom satellite looks down, so the highest point along a line of sight is
//! the one it sees). Used both ways round by the masks: heights above ground from the stereo DSM
//! into the image the masks are computed on, and the truth's classes into the image to score them.

use camera::{DsmGrid, RpcModel};
use raster::Image;
use rayon::prelude::*;

/// Samples per cell side: 2 × 2 points per 0.5 m cell leave no gaps on flat ground at
/// WorldView-3's 0.3 m pixels; pixels left without a sample (facades, outside the grid) are NaN.
const SAMPLES: usize = 2;

/// Renders the `values` planes (same grid and size as `altitude`, one channel each) into a
/// `width`×`height` image of the camera `rpc`: NaN where no cell with a finite altitude falls.
/// The output has one channel per plane.
pub fn render_into_image(
    altitude: &Image,
    values: &[&Image],
    grid: &DsmGrid,
    rpc: &RpcModel,
    (width, height): (usize, usize),
) -> Image {
    let (gw, gh) = altitude.size();
    let crs = grid.crs();
    let step = grid.resolution / SAMPLES as f64;
    // One exact projection per cell (its centre); the samples inside the cell are placed by the
    // camera's ground-to-image Jacobian at the grid's centre (the RPC is affine to far below a
    // pixel across 0.5 m), four times fewer projections and UTM inversions.
    let centre = |col: f64, row: f64| {
        (
            grid.x0 + (col + 0.5) * grid.resolution,
            grid.y0 - (row + 0.5) * grid.resolution,
        )
    };
    let mid_alt = {
        let mut v: Vec<f32> = altitude
            .data()
            .iter()
            .copied()
            .filter(|a| a.is_finite())
            .collect();
        v.sort_unstable_by(f32::total_cmp);
        v.get(v.len() / 2).copied().unwrap_or(0.0) as f64
    };
    let jacobian = {
        let (e, n) = centre(gw as f64 / 2.0, gh as f64 / 2.0);
        let at = |e: f64, n: f64| {
            let (lon, lat) = crs.inverse(e, n);
            rpc.projection(lon, lat, mid_alt)
        };
        let d = 1.0;
        let (xe1, ye1) = at(e + d, n);
        let (xe0, ye0) = at(e - d, n);
        let (xn1, yn1) = at(e, n + d);
        let (xn0, yn0) = at(e, n - d);
        [
            (xe1 - xe0) / (2.0 * d),
            (xn1 - xn0) / (2.0 * d),
            (ye1 - ye0) / (2.0 * d),
            (yn1 - yn0) / (2.0 * d),
        ]
    };
    let offsets: Vec<(f64, f64)> = (0..SAMPLES * SAMPLES)
        .map(|s| {
            let oe = ((s % SAMPLES) as f64 + 0.5) * step - grid.resolution / 2.0;
            let on = grid.resolution / 2.0 - ((s / SAMPLES) as f64 + 0.5) * step;
            (
                jacobian[0] * oe + jacobian[1] * on,
                jacobian[2] * oe + jacobian[3] * on,
            )
        })
        .collect();
    // (pixel index, altitude, cell index) of every sample that lands in the image.
    let hits: Vec<(usize, f32, usize)> = (0..gh)
        .into_par_iter()
        .flat_map_iter(|row| {
            let mut out = Vec::new();
            for col in 0..gw {
                let alt = altitude.get(col, row, 0);
                if !alt.is_finite() {
                    continue;
                }
                let (e, n) = centre(col as f64, row as f64);
                let (lon, lat) = crs.inverse(e, n);
                let (xc, yc) = rpc.projection(lon, lat, alt as f64);
                for &(ox, oy) in &offsets {
                    let (x, y) = ((xc + ox).round(), (yc + oy).round());
                    if x >= 0.0 && y >= 0.0 && (x as usize) < width && (y as usize) < height {
                        out.push((y as usize * width + x as usize, alt, row * gw + col));
                    }
                }
            }
            out
        })
        .collect();
    // A z-buffer: per pixel the highest sample, ties broken by the larger cell index (the
    // result does not depend on the order of the hits).
    let mut best: Vec<Option<(f32, usize)>> = vec![None; width * height];
    for (pixel, alt, cell) in hits {
        let b = &mut best[pixel];
        if b.is_none_or(|(a, k)| alt.total_cmp(&a).then(cell.cmp(&k)).is_gt()) {
            *b = Some((alt, cell));
        }
    }
    let c = values.len();
    let mut data = vec![f32::NAN; width * height * c];
    for (pixel, b) in best.iter().enumerate() {
        if let Some((_, cell)) = b {
            for (k, plane) in values.iter().enumerate() {
                data[pixel * c + k] = plane.data()[*cell];
            }
        }
    }
    Image::new(width, height, c, data).expect("sizes match")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A nadir camera over the grid, 3 px per metre: col ∝ lon, row ∝ −lat.
    fn nadir_camera(grid: &DsmGrid) -> RpcModel {
        let crs = grid.crs();
        let (lon0, lat0) = crs.inverse(grid.x0, grid.y0);
        let (lon1, lat1) = crs.inverse(grid.x0 + 4.0, grid.y0 - 4.0);
        RpcModel::nadir(
            [0.0, 0.0, lat0, lon0, 0.0],
            [12.0, 12.0, lat0 - lat1, lon1 - lon0, 1.0],
        )
    }

    /// Pixel (6, 6) sees samples of cell (3, 3), 10 m high, and of its lower neighbours: the
    /// z-buffer keeps the high one; cells without altitude and pixels off the grid stay NaN.
    #[test]
    fn the_highest_cell_wins_and_empty_pixels_stay_nan() {
        let grid = DsmGrid::new(436_000.0, 3_357_000.0, 0.5, 8, 8, 32617).unwrap();
        let rpc = nadir_camera(&grid);
        let mut alt = Image::filled(8, 8, 1, 0.0);
        alt.set(3, 3, 0, 10.0);
        alt.set(7, 7, 0, f32::NAN);
        let value = Image::from_fn(8, 8, |x, y| (y * 8 + x) as f32);
        let out = render_into_image(&alt, &[&value], &grid, &rpc, (20, 20));
        assert_eq!(out.get(5, 5, 0), 27.0);
        assert_eq!(out.get(6, 6, 0), 27.0, "the 10 m cell hides its neighbours");
        assert_eq!(out.get(7, 7, 0), 36.0);
        assert_eq!(out.get(0, 0, 0), 0.0);
        assert!(out.get(11, 11, 0).is_nan(), "cell (7, 7) has no altitude");
        assert!(out.get(19, 0, 0).is_nan(), "beyond the grid");
    }
}

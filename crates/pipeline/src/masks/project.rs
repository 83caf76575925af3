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
    let zone = grid.zone();
    let step = grid.resolution / SAMPLES as f64;
    // (pixel index, altitude, cell index) of every sample that lands in the image.
    let mut hits: Vec<(usize, f32, usize)> = (0..gh)
        .into_par_iter()
        .flat_map_iter(|row| {
            let mut out = Vec::new();
            for col in 0..gw {
                let alt = altitude.get(col, row, 0);
                if !alt.is_finite() {
                    continue;
                }
                for s in 0..SAMPLES * SAMPLES {
                    let e = grid.x0
                        + col as f64 * grid.resolution
                        + ((s % SAMPLES) as f64 + 0.5) * step;
                    let n = grid.y0
                        - row as f64 * grid.resolution
                        - ((s / SAMPLES) as f64 + 0.5) * step;
                    let (lon, lat) = zone.inverse(e, n);
                    let (x, y) = rpc.projection(lon, lat, alt as f64);
                    let (x, y) = (x.round(), y.round());
                    if x >= 0.0 && y >= 0.0 && (x as usize) < width && (y as usize) < height {
                        out.push((y as usize * width + x as usize, alt, row * gw + col));
                    }
                }
            }
            out
        })
        .collect();
    // Highest last, so the last write per pixel wins; ties broken by cell for determinism.
    hits.par_sort_unstable_by(|a, b| a.1.total_cmp(&b.1).then(a.2.cmp(&b.2)));
    let c = values.len();
    let mut data = vec![f32::NAN; width * height * c];
    for (pixel, _, cell) in hits {
        for (k, plane) in values.iter().enumerate() {
            data[pixel * c + k] = plane.data()[cell];
        }
    }
    Image::new(width, height, c, data).expect("sizes match")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A nadir camera over the grid, 3 px per metre: col ∝ lon, row ∝ −lat.
    fn nadir_camera(grid: &DsmGrid) -> RpcModel {
        let zone = grid.zone();
        let (lon0, lat0) = zone.inverse(grid.x0, grid.y0);
        let (lon1, lat1) = zone.inverse(grid.x0 + 4.0, grid.y0 - 4.0);
        let mut col_num = [0.0; 20];
        let mut row_num = [0.0; 20];
        let mut den = [0.0; 20];
        col_num[1] = 1.0;
        row_num[2] = -1.0;
        den[0] = 1.0;
        RpcModel {
            row_offset: 0.0,
            col_offset: 0.0,
            lat_offset: lat0,
            lon_offset: lon0,
            alt_offset: 0.0,
            row_scale: 12.0,
            col_scale: 12.0,
            lat_scale: lat0 - lat1,
            lon_scale: lon1 - lon0,
            alt_scale: 1.0,
            row_num,
            row_den: den,
            col_num,
            col_den: den,
            min_alt: None,
            max_alt: None,
        }
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

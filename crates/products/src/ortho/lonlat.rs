//! Longitude and latitude of a row's cell centres. The inverse projection (UTM's series, or
//! PROJ's) costs as much as all the rest of a cell's work for a view; it is smooth at the scale
//! of a few cells, so it is computed exactly every [`KNOT`] cells and linearly in between (the
//! error over 16 cells of 0.5 m is far below a millimetre).

use camera::DsmGrid;

/// Cells between exact inverse projections.
const KNOT: usize = 16;

/// Fills `out` with the (lon, lat) of the centres of row `row`'s cells.
pub(super) fn row_lonlat(grid: &DsmGrid, row: usize, out: &mut Vec<(f64, f64)>) {
    let crs = grid.crs();
    let exact = |col: usize| {
        let (x, y) = grid.cell_centre(col, row);
        crs.inverse(x, y)
    };
    out.clear();
    let last = grid.width - 1;
    let mut a = exact(0);
    let mut k0 = 0;
    while k0 < last {
        let k1 = (k0 + KNOT).min(last);
        let b = exact(k1);
        let span = (k1 - k0) as f64;
        out.extend((k0..k1).map(|c| {
            let t = (c - k0) as f64 / span;
            (a.0 + (b.0 - a.0) * t, a.1 + (b.1 - a.1) * t)
        }));
        (a, k0) = (b, k1);
    }
    out.push(a);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolation_matches_the_exact_projection() {
        // A 1 km row of 0.5 m cells in UTM 17N, far from the zone's central meridian.
        let grid = DsmGrid::new(435_000.0, 3_355_000.0, 0.5, 2001, 3, 32617).unwrap();
        let mut out = Vec::new();
        row_lonlat(&grid, 2, &mut out);
        assert_eq!(out.len(), 2001);
        let crs = grid.crs();
        let worst = (0..2001)
            .map(|c| {
                let (x, y) = grid.cell_centre(c, 2);
                let (lon, lat) = crs.inverse(x, y);
                (out[c].0 - lon).abs().max((out[c].1 - lat).abs())
            })
            .fold(0.0, f64::max);
        // 1e-10 degree is 0.01 mm.
        assert!(worst < 1e-10, "{worst}");
        let one = DsmGrid::new(435_000.0, 3_355_000.0, 0.5, 1, 1, 32617).unwrap();
        row_lonlat(&one, 0, &mut out);
        assert_eq!(out.len(), 1);
    }
}

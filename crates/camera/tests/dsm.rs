//! DSM grids, max-per-cell rasterisation and GeoTIFF output.

mod support;

use camera::{rasterize_max, write_dsm, CameraError, DsmGrid, Points, UtmZone};
use raster::formats::{read_tiff, GeoRaster, GeoReference};
use raster::Image;
use support::{s2p, S2P};

#[test]
fn grid_of_the_s2p_dsm() {
    testdata::require!(S2P);
    let grid = DsmGrid::read_geotiff(s2p("tests/data/expected_output/pair/dsm.tif")).unwrap();
    assert_eq!((grid.width, grid.height, grid.epsg), (721, 739, 32740));
    assert_eq!(grid.resolution, 0.5);
    assert_eq!(grid.zone(), Some(UtmZone::from_epsg(32740).unwrap()));
}

#[test]
fn max_per_cell_floor_indexing() {
    let zone = UtmZone::from_epsg(32617).unwrap();
    let grid = DsmGrid::new(436000.0, 3358000.0, 0.5, 4, 3, 32617).unwrap();
    // Points at chosen UTM positions, converted to lon/lat.
    let at = |e: f64, n: f64, alt: f64| {
        let (lon, lat) = zone.inverse(e, n);
        [lon, lat, alt]
    };
    let pts = vec![
        at(436000.1, 3357999.9, 5.0),   // cell (0, 0)
        at(436000.4, 3357999.6, 7.0),   // cell (0, 0), higher
        at(436000.2, 3357999.8, 6.0),   // cell (0, 0), lower
        at(436001.7, 3357998.6, 2.0),   // cell (3, 2)
        at(436002.1, 3357999.9, 9.0),   // east of the grid
        at(435999.9, 3357999.9, 9.0),   // west of the grid
        [f64::NAN, f64::NAN, f64::NAN], // no point
    ];
    let points = Points {
        width: pts.len(),
        height: 1,
        lonlatalt: pts,
    };
    let dsm = rasterize_max(&points, &grid);
    assert_eq!(dsm.size(), (4, 3));
    assert_eq!(dsm.get(0, 0, 0), 7.0);
    assert_eq!(dsm.get(3, 2, 0), 2.0);
    let finite = dsm.data().iter().filter(|v| v.is_finite()).count();
    assert_eq!(finite, 2);
}

#[test]
fn from_bounds_covers_the_extent() {
    let g = DsmGrid::from_bounds(100.0, 200.0, 110.2, 205.0, 0.5, 32740).unwrap();
    assert_eq!((g.x0, g.y0, g.width, g.height), (100.0, 205.0, 21, 10));
    assert!(DsmGrid::from_bounds(100.0, 200.0, 90.0, 205.0, 0.5, 32740).is_err());
    assert!(DsmGrid::new(0.0, 0.0, 0.0, 1, 1, 32740).is_err());
    // Any known EPSG code; unknown codes are refused.
    assert!(DsmGrid::new(-81.7, 30.3, 1e-5, 1, 1, 4326).is_ok());
    assert!(DsmGrid::new(0.0, 0.0, 1.0, 1, 1, 3857).is_ok());
    assert!(DsmGrid::new(0.0, 0.0, 1.0, 1, 1, 1).is_err());
}

#[test]
fn write_dsm_round_trips_georeference() {
    let grid = DsmGrid::new(366000.0, 7652000.0, 0.5, 5, 4, 32740).unwrap();
    let mut img = Image::filled(5, 4, 1, f32::NAN);
    img.set(1, 2, 0, 12.5);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("out/dsm.tif");
    write_dsm(&path, &img, &grid).unwrap();
    let back = read_tiff(&path).unwrap();
    assert_eq!(back.image.get(1, 2, 0), 12.5);
    assert!(back.image.get(0, 0, 0).is_nan());
    assert!(back.nodata.unwrap().is_nan());
    assert_eq!(DsmGrid::of_raster(&back, "dsm.tif").unwrap(), grid);
    // A mismatched image is refused.
    assert!(write_dsm(&path, &Image::filled(4, 4, 1, 0.0), &grid).is_err());
}

#[test]
fn a_dsm_says_what_its_heights_are_in_any_crs() {
    let dir = tempfile::tempdir().unwrap();
    for grid in [
        DsmGrid::new(366000.0, 7652000.0, 0.5, 5, 4, 32740).unwrap(),
        DsmGrid::new(-81.70, 30.32, 4.5e-6, 5, 4, 4326).unwrap(),
        DsmGrid::new(-9_094_000.0, 3_543_000.0, 0.58, 5, 4, 3857).unwrap(),
    ] {
        let path = dir.path().join(format!("{}.tif", grid.epsg));
        write_dsm(&path, &Image::filled(5, 4, 1, 3.0), &grid).unwrap();
        let meta = raster::formats::TiffReader::open(&path)
            .unwrap()
            .gdal_metadata
            .unwrap();
        for item in [
            r#"role="description">height above the WGS84 ellipsoid<"#,
            r#"role="unittype">metre<"#,
            "VERTICAL_REFERENCE\">ellipsoidal heights, WGS84 (EPSG:4979)<",
        ] {
            assert!(meta.contains(item), "{item} not in {meta}");
        }
        assert_eq!(DsmGrid::read_geotiff(&path).unwrap(), grid);
    }
}

#[test]
fn unusable_georeferences_are_errors() {
    let raster = GeoRaster {
        image: Image::filled(3, 3, 1, 0.0),
        georef: None,
        nodata: None,
        rpc: None,
    };
    let err = DsmGrid::of_raster(&raster, "gt.tif").unwrap_err();
    assert!(matches!(err, CameraError::Georeference(_)));
    assert!(err.to_string().contains("gt.tif") && err.to_string().contains("no georeference"));

    let mut rotated = GeoReference::from_origin_utm(0.0, 0.0, 0.5, 32740);
    rotated.geotransform[2] = 0.1;
    let msg = DsmGrid::from_georeference(&rotated, 3, 3)
        .unwrap_err()
        .to_string();
    assert!(msg.contains("rotated"), "{msg}");

    let mut no_epsg = GeoReference::from_origin_utm(0.0, 0.0, 0.5, 32740);
    no_epsg.epsg = None;
    assert!(DsmGrid::from_georeference(&no_epsg, 3, 3).is_err());
    let unknown = GeoReference::from_origin_utm(0.0, 0.0, 0.5, 1);
    assert!(DsmGrid::from_georeference(&unknown, 3, 3).is_err());

    // A real TIFF without georeference: a satellite image.
    testdata::require!(S2P);
    let msg = DsmGrid::read_geotiff(s2p(support::S2P_IMG1))
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("img_01.tif") && msg.contains("no georeference"),
        "{msg}"
    );
}

#[test]
fn dfc2019_truth_as_distributed_reads_with_its_txt_georeference() {
    testdata::require!(support::JAX_DEV);
    let path = support::jax_dev("truth/JAX_068_DSM.tif");
    // The plain TIFF carries no georeference: the zone must come from somewhere.
    let msg = camera::read_dsm(&path, None).unwrap_err().to_string();
    assert!(
        msg.contains("UTM zone") && msg.contains("JAX_068_DSM.txt"),
        "{msg}"
    );
    let zone = UtmZone::new(17, true).unwrap();
    let dsm = camera::read_dsm(&path, Some(zone)).unwrap();
    let g = &dsm.grid;
    assert_eq!(
        (g.width, g.height, g.epsg, g.resolution),
        (512, 512, 32617, 0.5)
    );
    // "E N size res" is the lower-left corner: the north edge is N + size·res.
    assert!((g.x0 - 436078.995946).abs() < 1e-6);
    assert!((g.y0 - (3357495.999923 + 256.0)).abs() < 1e-6);
    // LiDAR heights above the ellipsoid in Jacksonville: about −30 to +40 m, no NaN fill.
    let finite: Vec<f32> = dsm
        .image
        .data()
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .collect();
    assert!(finite.len() > 500 * 500);
    let (lo, hi) = finite
        .iter()
        .fold((f32::MAX, f32::MIN), |(a, b), &v| (a.min(v), b.max(v)));
    assert!(lo > -40.0 && hi < 80.0 && hi - lo > 15.0, "{lo} {hi}");
    assert_eq!(DsmGrid::read(&path, Some(zone)).unwrap(), dsm.grid);
}

#[test]
fn dfc2019_txt_errors_name_the_file() {
    let zone = UtmZone::new(17, true).unwrap();
    let bad = DsmGrid::from_dfc_txt("1 2 3", "x.txt", 3, 3, zone).unwrap_err();
    assert!(bad.to_string().contains("x.txt"), "{bad}");
    let wrong = DsmGrid::from_dfc_txt("1 2 4 0.5", "x.txt", 3, 3, zone).unwrap_err();
    assert!(wrong.to_string().contains("4 cells"), "{wrong}");
    assert!(DsmGrid::from_dfc_txt("1 2 3 0.5", "x.txt", 3, 3, zone).is_ok());
}

#[test]
fn median_gridding_ignores_an_isolated_high_point() {
    let grid = DsmGrid::new(436000.0, 3358000.0, 0.5, 4, 3, 32617).unwrap();
    let zone = grid.zone().unwrap();
    // Three points in cell (1, 1): 10, 11 and a wrong 40 m; one point in cell (3, 0).
    let at = |c: f64, r: f64, alt: f64| {
        let (lon, lat) = zone.inverse(436000.0 + (c + 0.5) * 0.5, 3358000.0 - (r + 0.5) * 0.5);
        [lon, lat, alt]
    };
    let points = Points {
        width: 5,
        height: 1,
        lonlatalt: vec![
            at(1.0, 1.0, 10.0),
            at(1.0, 1.0, 40.0),
            at(1.0, 1.0, 11.0),
            at(3.0, 0.0, 5.0),
            [f64::NAN, 0.0, 1.0],
        ],
    };
    let max = camera::rasterize(&points, &grid, camera::Gridding::Max);
    let med = camera::rasterize(&points, &grid, camera::Gridding::Median);
    assert_eq!(max.get(1, 1, 0), 40.0);
    assert_eq!(med.get(1, 1, 0), 11.0);
    assert_eq!((max.get(3, 0, 0), med.get(3, 0, 0)), (5.0, 5.0));
    assert_eq!(med.data().iter().filter(|v| v.is_finite()).count(), 2);
    let bits = |i: &Image| i.data().iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&max), bits(&rasterize_max(&points, &grid)));

    // A per-point attribute (the matcher's confidence) lands in the heights' cells: the window
    // is the heights' (cells (1, 0) to (3, 1)), the values' median per cell, NaN values ignored.
    let plain = camera::rasterize_window(&points, &grid, camera::Gridding::Median).unwrap();
    let conf = [0.9, 0.1, 0.5, f32::NAN, 0.7];
    let with =
        camera::rasterize_window_with(&points, &conf, &grid, camera::Gridding::Median).unwrap();
    assert_eq!(plain.confidence, None);
    assert_eq!(
        (with.col, with.row, with.width, with.height),
        (plain.col, plain.row, plain.width, plain.height)
    );
    assert_eq!((with.col, with.row, with.width, with.height), (1, 0, 3, 2));
    assert_eq!(
        bits(&Image::new(3, 2, 1, with.heights.clone()).unwrap()),
        bits(&Image::new(3, 2, 1, plain.heights).unwrap())
    );
    let c = with.confidence.unwrap();
    assert_eq!(c[3], 0.5, "cell (1, 1): the median of 0.9, 0.1, 0.5");
    assert!(
        c[2].is_nan(),
        "cell (3, 0): its only point has a NaN confidence"
    );
    assert_eq!(c.iter().filter(|v| v.is_finite()).count(), 1);
}

#[test]
fn hole_filling_takes_the_ground_side_and_never_extrapolates() {
    // 12 × 7 cells: ground at 1 m, a roof at 9 m on columns 6..9, an occluded strip (NaN) on
    // columns 3..6 between ground and roof, a one-cell hole inside the roof, and nothing on the
    // last column (outside the footprint).
    let (w, h) = (12, 7);
    let mut dsm = Image::filled(w, h, 1, 1.0);
    for y in 0..h {
        for x in 6..10 {
            dsm.set(x, y, 0, 9.0);
        }
        for x in 3..6 {
            dsm.set(x, y, 0, f32::NAN);
        }
        dsm.set(11, y, 0, f32::NAN);
    }
    dsm.set(7, 3, 0, f32::NAN);
    let (filled, n) = camera::fill_holes(&dsm, camera::HoleFill::spanning(20));
    assert_eq!(n, 3 * h + 1);
    for y in 0..h {
        for x in 3..6 {
            assert_eq!(filled.get(x, y, 0), 1.0, "occluded strip at ({x}, {y})");
        }
        assert!(filled.get(11, y, 0).is_nan(), "outside the footprint");
    }
    assert_eq!(filled.get(7, 3, 0), 9.0, "hole inside the roof");
    // Too far to reach data: nothing is invented.
    let (short, m) = camera::fill_holes(&dsm, camera::HoleFill::spanning(1));
    assert_eq!(m, 1, "only the roof hole is enclosed within one cell");
    assert!(short.get(4, 3, 0).is_nan());
}

/// A courtyard 21 cells wide inside a roof: within `reach` of the roof its cells are filled,
/// its middle, farther from every measurement, stays empty; a narrow strip is filled whole.
#[test]
fn fill_holes_leaves_the_interior_of_a_wide_hole_empty_beyond_its_reach() {
    let (w, h) = (41, 41);
    let mut dsm = Image::from_fn(w, h, |_, _| 12.0);
    for y in 10..31 {
        for x in 10..31 {
            dsm.set(x, y, 0, f32::NAN);
        }
    }
    for y in 0..h {
        dsm.set(36, y, 0, f32::NAN);
    }
    let unlimited = camera::fill_holes(&dsm, camera::HoleFill::spanning(40)).0;
    assert!(unlimited.data().iter().all(|v| v.is_finite()));
    let fill = camera::HoleFill { span: 40, reach: 4 };
    let (filled, n) = camera::fill_holes(&dsm, fill);
    // The nearest roof cell along the 8 rays of (x, y) in the courtyard (columns and rows
    // 10..31) is min(x − 9, 31 − x, y − 9, 31 − y) cells away.
    let mut want = h;
    for y in 10..31 {
        for x in 10..31 {
            let nearest = (x - 9).min(31 - x).min(y - 9).min(31 - y);
            let v = filled.get(x, y, 0);
            if nearest <= 4 {
                assert_eq!(v, 12.0, "({x}, {y}) is {nearest} cells from the roof");
                want += 1;
            } else {
                assert!(v.is_nan(), "({x}, {y}) is {nearest} cells from the roof");
            }
        }
    }
    assert_eq!(n, want, "the strip's {h} cells and the courtyard's rim");
    assert!((0..h).all(|y| filled.get(36, y, 0) == 12.0));
}

#[test]
fn median_filter_removes_a_spike_keeps_an_edge_and_the_holes() {
    // Ground at 1 m on the left, a roof at 9 m from column 4, one wrong 30 m cell on the roof,
    // one empty cell on the ground.
    let (w, h) = (8, 6);
    let mut dsm = Image::from_fn(w, h, |x, _| if x >= 4 { 9.0 } else { 1.0 });
    dsm.set(6, 2, 0, 30.0);
    dsm.set(1, 3, 0, f32::NAN);
    let f = camera::median_filter(&dsm, 3);
    assert_eq!(f.get(6, 2, 0), 9.0, "spike removed");
    assert!(f.get(1, 3, 0).is_nan(), "holes stay holes");
    for y in 0..h {
        assert_eq!(f.get(3, y, 0), 1.0, "ground side of the edge at row {y}");
        assert_eq!(f.get(4, y, 0), 9.0, "roof side of the edge at row {y}");
    }
    // A window of 1 changes nothing.
    let same = camera::median_filter(&dsm, 1);
    assert_eq!(same.get(6, 2, 0), 30.0);
}

/// A DSM whose cell (col, row) holds `100·col + row`, to read back where each value came from.
fn labelled(grid: &DsmGrid) -> Image {
    Image::from_fn(grid.width, grid.height, |c, r| (100 * c + r) as f32)
}

#[test]
fn a_dsm_on_another_window_is_cut_onto_the_grid_cell_for_cell() {
    let from = DsmGrid::new(436080.5, 3357759.0, 0.5, 10, 8, 32617).unwrap();
    // The truth-like window starts 2.02 cells east and 1 cell south of the DSM's corner, as
    // s2p's grid and the DFC2019 truth's do (up to the fraction of a cell).
    let onto = DsmGrid::new(436080.5 + 1.01, 3357759.0 - 0.5, 0.5, 9, 8, 32617).unwrap();
    let out = camera::resample_nearest(&labelled(&from), &from, &onto);
    assert_eq!(out.size(), (9, 8));
    for r in 0..8 {
        for c in 0..9 {
            let v = out.get(c, r, 0);
            if c + 2 < 10 && r + 1 < 8 {
                assert_eq!(v, (100 * (c + 2) + r + 1) as f32, "cell {c},{r}");
            } else {
                assert!(v.is_nan(), "cell {c},{r} is outside the DSM: {v}");
            }
        }
    }
    // The same grid gives the DSM back, cell for cell.
    let same = camera::resample_nearest(&labelled(&from), &from, &from);
    assert_eq!(same.data(), labelled(&from).data());
}

#[test]
fn resampling_to_coarser_cells_takes_the_cell_under_each_centre() {
    let from = DsmGrid::new(436000.0, 3358000.0, 0.5, 8, 8, 32617).unwrap();
    let onto = DsmGrid::new(436000.0, 3358000.0, 1.0, 4, 4, 32617).unwrap();
    let out = camera::resample_nearest(&labelled(&from), &from, &onto);
    for r in 0..4 {
        for c in 0..4 {
            assert_eq!(out.get(c, r, 0), (100 * (2 * c + 1) + 2 * r + 1) as f32);
        }
    }
    // A window that misses the DSM is all empty.
    let away = DsmGrid::new(437000.0, 3358000.0, 0.5, 4, 4, 32617).unwrap();
    let none = camera::resample_nearest(&labelled(&from), &from, &away);
    assert!(none.data().iter().all(|v| v.is_nan()));
}

#[test]
fn a_dsm_in_the_neighbouring_utm_zone_is_resampled_through_longitude_and_latitude() {
    // Near −78°, the edge between zones 17N and 18N: the same place in both.
    let (z17, z18) = (
        UtmZone::new(17, true).unwrap(),
        UtmZone::new(18, true).unwrap(),
    );
    let (e18, n18) = z18.forward(-78.0005, 30.3);
    let from = DsmGrid::new(e18 - 20.0, n18 + 20.0, 1.0, 40, 40, 32618).unwrap();
    let (e17, n17) = z17.forward(-78.0005, 30.3);
    let onto = DsmGrid::new(e17 - 10.0, n17 + 10.0, 0.5, 40, 40, 32617).unwrap();
    let out = camera::resample_nearest(&labelled(&from), &from, &onto);
    for r in 0..40 {
        for c in 0..40 {
            let v = out.get(c, r, 0);
            assert!(v.is_finite(), "cell {c},{r} lies inside the DSM");
            let (col, row) = ((v as usize) / 100, (v as usize) % 100);
            // The onto cell's centre, in zone 18, lies in the cell its value came from.
            let centre = (
                onto.x0 + (c as f64 + 0.5) * 0.5,
                onto.y0 - (r as f64 + 0.5) * 0.5,
            );
            let (lon, lat) = z17.inverse(centre.0, centre.1);
            let (e, n) = z18.forward(lon, lat);
            assert_eq!(from.cell_of(e, n), Some((col, row)), "cell {c},{r}");
        }
    }
}

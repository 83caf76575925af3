//! DSM grids, max-per-cell rasterisation and GeoTIFF output.

mod support;

use camera::{rasterize_max, write_dsm, CameraError, DsmGrid, Points, UtmZone};
use raster::formats::{read_tiff, GeoRaster, GeoReference};
use raster::Image;
use support::anchor;

#[test]
fn grid_of_the_s2p_dsm() {
    let grid =
        DsmGrid::read_geotiff(anchor("s2p/tests/data/expected_output/pair/dsm.tif")).unwrap();
    assert_eq!((grid.width, grid.height, grid.epsg), (721, 739, 32740));
    assert_eq!(grid.resolution, 0.5);
    assert_eq!(grid.zone(), UtmZone::from_epsg(32740).unwrap());
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
    assert!(DsmGrid::new(0.0, 0.0, 1.0, 1, 1, 4326).is_err());
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
    let geographic = GeoReference::from_origin_utm(0.0, 0.0, 0.5, 4326);
    assert!(DsmGrid::from_georeference(&geographic, 3, 3).is_err());

    // A real TIFF without georeference: a satellite image.
    let msg = DsmGrid::read_geotiff(anchor(support::S2P_IMG1))
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("img_01.tif") && msg.contains("no georeference"),
        "{msg}"
    );
}

//! The products beside a DSM on the real dev images, as delivered (DFC2019 JAX_068 `vendor/`:
//! TIFF + `.RPB` + `.IMD`, read in place): the orthoimage lies on exactly the DSM's grid and its
//! edges on the DSM's building edges, the point cloud holds the measured cells in the DSM's CRS
//! with colours, a DSM in another CRS scores as the UTM one does, and heights above the geoid
//! are the ellipsoidal ones lifted by EGM96.

use std::path::{Path, PathBuf};

use camera::{read_dsm, DsmGrid, Heights, UtmZone};
use matching::SgmParams;
use products::Products;
use raster::formats::read_tiff;
use raster::Image;
use reconstruct::dsm::GridChoice;
use reconstruct::many::{reconstruct_many, ReconstructManyOptions};
use reconstruct::{reconstruct, ReconstructOptions};
use workflow::matcher::Matcher;
use workflow::Silent;

use testdata::{jax, JAX_DEV};

fn delivered(id: &str) -> PathBuf {
    jax(&format!("vendor/JAX_068_{id}_RGB.TIF"))
}

fn resolution_grid(epsg: Option<u32>) -> GridChoice {
    GridChoice::Resolution {
        resolution: 0.5,
        bounds: None,
        epsg,
    }
}

/// Central-difference gradient magnitude, NaN on the border and next to NaN.
fn gradient(image: &Image) -> Vec<f32> {
    let (w, h) = image.size();
    let v = |x: usize, y: usize| image.get(x, y, 0);
    let mut g = vec![f32::NAN; w * h];
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            let gx = (v(x + 1, y) - v(x - 1, y)) / 2.0;
            let gy = (v(x, y + 1) - v(x, y - 1)) / 2.0;
            g[y * w + x] = gx.hypot(gy);
        }
    }
    g
}

/// The mean colour gradient of the orthoimage at the DSM's height edges (over 2 m per cell),
/// with the orthoimage moved by (dx, dy) cells.
fn colour_gradient_at_height_edges(dsm: &Image, ortho: &Image, dx: i64, dy: i64) -> f64 {
    let (w, h) = dsm.size();
    let luminance: Vec<f32> = (0..w * h)
        .map(|i| {
            let (x, y) = (i % w, i / w);
            let rgb = [0, 1, 2].map(|c| ortho.get(x, y, c));
            if rgb == [0.0; 3] {
                f32::NAN
            } else {
                rgb.iter().sum::<f32>() / 3.0
            }
        })
        .collect();
    let colour = gradient(&Image::new(w, h, 1, luminance).unwrap());
    let height = gradient(dsm);
    let (mut sum, mut n) = (0.0, 0usize);
    for y in 0..h as i64 {
        for x in 0..w as i64 {
            let (sx, sy) = (x - dx, y - dy);
            if sx < 0 || sy < 0 || sx >= w as i64 || sy >= h as i64 {
                continue;
            }
            let g = colour[(sy * w as i64 + sx) as usize];
            if height[(y * w as i64 + x) as usize] > 2.0 && g.is_finite() {
                sum += g as f64;
                n += 1;
            }
        }
    }
    sum / n as f64
}

#[test]
fn the_orthoimage_sits_on_the_dsm_and_the_point_cloud_holds_its_measured_cells() {
    testdata::require!(JAX_DEV);
    let dir = tempfile::tempdir().unwrap();
    let out = |name: &str| dir.path().join(name);
    let opts = ReconstructManyOptions {
        pairs: 3,
        products: Products {
            ortho: Some(out("ortho.tif")),
            points: Some(out("points.las")),
            preview: Some(out("preview.png")),
            ..Default::default()
        },
        ..ReconstructManyOptions::new(
            ["003", "004", "013", "014"].map(delivered).to_vec(),
            None,
            Matcher::Classical(SgmParams::default()),
            resolution_grid(None),
            out("dsm.tif"),
        )
    };
    let s = reconstruct_many(&opts, &Silent).unwrap();
    let written = s.products.expect("products written");

    // The orthoimage: RGB on exactly the DSM's grid.
    let dsm = read_dsm(out("dsm.tif"), None).unwrap();
    let ortho = read_tiff(out("ortho.tif")).unwrap();
    assert_eq!(DsmGrid::of_raster(&ortho, "ortho").unwrap(), dsm.grid);
    assert_eq!(ortho.image.channels(), 3);
    assert_eq!(ortho.nodata, Some(0.0));
    // Its edges are the DSM's building edges: the colour changes most where the heights do,
    // with the orthoimage where it is (within a cell, the walls' own width), not moved by three
    // cells.
    let at = |dx, dy| colour_gradient_at_height_edges(&dsm.image, &ortho.image, dx, dy);
    let best = (-1..=1)
        .flat_map(|dy| (-1..=1).map(move |dx| (dx, dy)))
        .map(|(dx, dy)| at(dx, dy))
        .fold(0.0, f64::max);
    let moved = [(3, 0), (-3, 0), (0, 3), (0, -3)].map(|(dx, dy)| at(dx, dy));
    eprintln!("colour gradient at height edges: {best:.1} in place, {moved:.1?} moved 3 cells");
    for m in moved {
        assert!(best > 1.15 * m, "{best} against {moved:?}");
    }

    // The point cloud: one point per measured cell (the fused DSM's count > 0), in its CRS,
    // coloured.
    let count = read_dsm(out("dsm_count.tif"), None).unwrap().image;
    let measured = (dsm.image.data().iter().zip(count.data()))
        .filter(|(h, c)| h.is_finite() && **c > 0.0)
        .count();
    assert_eq!(written.points, Some(measured));
    let mut reader = las::Reader::from_path(out("points.las")).unwrap();
    let header = reader.header().clone();
    assert_eq!(header.number_of_points() as usize, measured);
    let keys = header
        .all_vlrs()
        .find(|v| v.record_id == 34735)
        .expect("the GeoKeyDirectory VLR")
        .data
        .clone();
    let keys: Vec<u16> = keys
        .chunks_exact(2)
        .map(|b| u16::from_le_bytes([b[0], b[1]]))
        .collect();
    assert!(
        keys.chunks_exact(4)
            .any(|k| k[0] == 3072 && k[3] as u32 == dsm.grid.epsg),
        "{keys:?}"
    );
    let g = &dsm.grid;
    let (x1, y0) = (
        g.x0 + g.width as f64 * g.resolution,
        g.y0 - g.height as f64 * g.resolution,
    );
    let data = reader.read_all().unwrap();
    let points: Vec<las::Point> = data.points().map(Result::unwrap).collect();
    assert!(points
        .iter()
        .all(|p| p.x > g.x0 && p.x < x1 && p.y > y0 && p.y < g.y0));
    let coloured = points
        .iter()
        .filter(|p| p.color.is_some_and(|c| c.red.max(c.green).max(c.blue) > 0))
        .count();
    assert!(
        coloured as f64 > 0.99 * measured as f64,
        "{coloured} of {measured}"
    );
    // Each file says what its band holds: heights for the DSM, counts for the count.
    let said = |name: &str| {
        raster::formats::TiffReader::open(out(name))
            .unwrap()
            .gdal_metadata
            .unwrap()
    };
    assert!(said("dsm.tif").contains("height above the WGS84 ellipsoid"));
    let count_says = said("dsm_count.tif");
    assert!(
        count_says.contains("pairs that measured the cell") && !count_says.contains("height"),
        "{count_says}"
    );
    let png = std::fs::read(out("preview.png")).unwrap();
    assert_eq!(&png[1..4], b"PNG");
}

/// The DSM of one pair (006-020 as delivered) on `grid`, with `heights`.
fn pair_dsm(grid: GridChoice, heights: Heights, output: &Path) {
    let opts = ReconstructOptions {
        products: Products {
            heights,
            ..Default::default()
        },
        ..ReconstructOptions::new(
            delivered("006"),
            delivered("020"),
            Matcher::Classical(SgmParams::default()),
            grid,
            output.to_path_buf(),
        )
    };
    reconstruct(&opts, &Silent).unwrap();
}

/// The DSM of one pair scored against the truth, on the grid of `epsg`.
fn pair_mae(epsg: Option<u32>, dir: &Path) -> (f64, f64, u32) {
    let output = dir.join(format!("{}.tif", epsg.unwrap_or(0)));
    pair_dsm(resolution_grid(epsg), Heights::Ellipsoid, &output);
    let truth = eval::score::read_truth(
        &jax("truth/JAX_068_DSM.tif"),
        UtmZone::new(17, true).unwrap(),
    )
    .unwrap();
    let s = eval::score::score_dsm_file(&output, &truth).unwrap();
    let grid = read_dsm(&output, None).unwrap().grid;
    (s.mae_filtered.unwrap(), s.coverage.unwrap(), grid.epsg)
}

#[test]
fn a_dsm_in_geographic_or_web_mercator_coordinates_scores_as_the_utm_one() {
    testdata::require!(JAX_DEV);
    let dir = tempfile::tempdir().unwrap();
    let utm = pair_mae(None, dir.path());
    assert_eq!(utm.2, 32617);
    for epsg in [4326, 3857] {
        let other = pair_mae(Some(epsg), dir.path());
        eprintln!("UTM {utm:?}, EPSG:{epsg} {other:?}");
        assert_eq!(other.2, epsg);
        assert!((other.0 - utm.0).abs() < 0.02, "{other:?} against {utm:?}");
        assert!((other.1 - utm.1).abs() < 0.01, "{other:?} against {utm:?}");
    }
    // `--like` a DSM in longitude/latitude: exactly its grid.
    let like = dir.path().join("4326.tif");
    let again = dir.path().join("like-4326.tif");
    pair_dsm(GridChoice::Like(like.clone()), Heights::Ellipsoid, &again);
    assert_eq!(
        read_dsm(&again, None).unwrap().grid,
        read_dsm(&like, None).unwrap().grid
    );

    // Heights above the EGM96 geoid: the same DSM lifted by the geoid's undulation (about 29 m
    // here), and the file says so.
    let geoid = dir.path().join("egm96.tif");
    pair_dsm(resolution_grid(None), Heights::Egm96, &geoid);
    let (a, b) = (
        read_dsm(dir.path().join("0.tif"), None).unwrap(),
        read_dsm(&geoid, None).unwrap(),
    );
    assert_eq!(a.grid, b.grid);
    let (lon, lat) = a.grid.centre_lonlat();
    let n = camera::egm96_undulation(lon, lat);
    assert!((-31.0..-27.0).contains(&n), "{n}");
    for (e, g) in a.image.data().iter().zip(b.image.data()) {
        assert_eq!(e.is_finite(), g.is_finite());
        if e.is_finite() {
            assert!(((e - g) as f64 - n).abs() < 0.05, "{e} {g} {n}");
        }
    }
    let metadata = raster::formats::TiffReader::open(&geoid)
        .unwrap()
        .gdal_metadata
        .unwrap();
    assert!(
        metadata.contains("EGM96 geoid heights (EPSG:5773)"),
        "{metadata}"
    );
}

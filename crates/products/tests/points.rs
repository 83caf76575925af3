//! Point clouds written and read back: LAS and LAZ through the `las` crate's reader (count,
//! coordinates, colours, header bounds, the CRS's GeoTIFF keys), PLY by parsing its header and
//! body.

use std::path::Path;

use camera::DsmGrid;
use las::crs::GeoTiffData;
use las::Reader;
use products::write_point_cloud;
use raster::Image;

const W: usize = 7;
const H: usize = 5;

/// A 7 × 5 grid of 0.5 m UTM cells, heights `10 + col + row/10` with two holes; its colours; and
/// a keep mask dropping cell (3, 2).
fn cloud() -> (Image, DsmGrid, Image, Vec<bool>) {
    let grid = DsmGrid::new(435_000.0, 3_355_000.0, 0.5, W, H, 32617).unwrap();
    let mut dsm = Image::from_fn(W, H, |x, y| 10.0 + x as f32 + y as f32 / 10.0);
    dsm.set(0, 0, 0, f32::NAN);
    dsm.set(6, 4, 0, f32::NAN);
    let colours = Image::new(
        W,
        H,
        3,
        (0..W * H)
            .flat_map(|i| [i as f32, 255.0 - i as f32, 7.0])
            .collect(),
    )
    .unwrap();
    let mut keep = vec![true; W * H];
    keep[2 * W + 3] = false;
    (dsm, grid, colours, keep)
}

/// Reads a LAS/LAZ file and checks it against [`cloud`].
fn check_las(path: &Path, grid: &DsmGrid, coloured: bool) {
    let mut reader = Reader::from_path(path).unwrap();
    let header = reader.header().clone();
    assert_eq!(header.number_of_points(), (W * H - 3) as u64);
    assert_eq!((header.version().major, header.version().minor), (1, 2));
    assert_eq!(header.point_format().has_color, coloured);
    let t = header.transforms();
    assert_eq!((t.x.scale, t.z.scale), (0.001, 0.001));
    assert_eq!(t.x.offset, grid.x0);
    assert_eq!(t.y.offset, grid.y0 - H as f64 * 0.5);

    let b = header.bounds();
    let (x_lo, y_hi) = grid.cell_centre(0, 0);
    let (x_hi, y_lo) = grid.cell_centre(W - 1, H - 1);
    assert!(
        (b.min.x - x_lo).abs() < 1e-6 && (b.max.x - x_hi).abs() < 1e-6,
        "{b:?}"
    );
    assert!(
        (b.min.y - y_lo).abs() < 1e-6 && (b.max.y - y_hi).abs() < 1e-6,
        "{b:?}"
    );
    assert!(
        (b.min.z - 10.1).abs() < 1e-4 && (b.max.z - 16.3).abs() < 1e-4,
        "{b:?}"
    );

    let crs = header
        .get_geotiff_crs()
        .unwrap()
        .expect("a GeoKeyDirectoryTag VLR");
    let key = |id: u16| {
        crs.entries
            .iter()
            .find(|e| e.id == id)
            .map(|e| match e.data {
                GeoTiffData::U16(v) => v,
                _ => panic!("key {id} is not a short"),
            })
    };
    assert_eq!(key(1024), Some(1), "projected model");
    assert_eq!(key(1025), Some(1), "pixel is area");
    assert_eq!(key(3072), Some(32617));
    assert_eq!(key(4099), Some(9001));
    let vlr = header.vlrs().iter().find(|v| v.record_id == 34735).unwrap();
    assert_eq!(vlr.user_id, "LASF_Projection");

    let data = reader.read_all().unwrap();
    let points: Vec<las::Point> = data.points().map(|p| p.unwrap()).collect();
    // Row order: the first point is cell (1, 0), the ninth cell (2, 1), after the hole at (0, 0).
    let first = &points[0];
    let (x, y) = grid.cell_centre(1, 0);
    assert!(
        (first.x - x).abs() < 1e-3 && (first.y - y).abs() < 1e-3 && (first.z - 11.0).abs() < 1e-3
    );
    let p = &points[8];
    let (x, y) = grid.cell_centre(2, 1);
    assert!((p.x - x).abs() < 1e-3 && (p.y - y).abs() < 1e-3 && (p.z - 12.1).abs() < 1e-3);
    if coloured {
        let c = p.color.unwrap();
        let i = (W + 2) as u16;
        assert_eq!(
            (c.red, c.green, c.blue),
            (i * 257, (255 - i) * 257, 7 * 257)
        );
    } else {
        assert!(p.color.is_none());
    }
}

#[test]
fn las_and_laz_read_back_with_their_crs() {
    let dir = tempfile::tempdir().unwrap();
    let (dsm, grid, colours, keep) = cloud();
    for (name, coloured) in [("c.las", true), ("c.laz", true), ("grey.las", false)] {
        let path = dir.path().join(name);
        let n = write_point_cloud(
            &path,
            &dsm,
            &grid,
            coloured.then_some(&colours),
            Some(&keep),
        )
        .unwrap();
        assert_eq!(n, W * H - 3);
        check_las(&path, &grid, coloured);
    }
    // The LAZ is compressed.
    let size = |n: &str| std::fs::metadata(dir.path().join(n)).unwrap().len();
    assert!(size("c.laz") < size("c.las"));
    // No temporary file left behind.
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 3);
}

#[test]
fn geographic_grids_get_fine_scales_and_geographic_keys() {
    let dir = tempfile::tempdir().unwrap();
    let grid = DsmGrid::new(-81.7, 30.4, 5e-6, W, H, 4326).unwrap();
    let dsm = Image::filled(W, H, 1, 3.0);
    let path = dir.path().join("geo.las");
    write_point_cloud(&path, &dsm, &grid, None, None).unwrap();
    let mut reader = Reader::from_path(&path).unwrap();
    let header = reader.header().clone();
    assert_eq!(header.transforms().x.scale, 1e-7);
    let crs = header.get_geotiff_crs().unwrap().unwrap();
    let ids: Vec<u16> = crs.entries.iter().map(|e| e.id).collect();
    assert_eq!(ids, [1024, 1025, 2048, 4099]);
    assert_eq!(crs.get_gt_model_type_geo_key_value(), Some(2));
    let data = reader.read_all().unwrap();
    let last = data.points().last().unwrap().unwrap();
    let (x, y) = grid.cell_centre(W - 1, H - 1);
    assert!((last.x - x).abs() < 2e-7 && (last.y - y).abs() < 2e-7);
}

#[test]
fn ply_is_binary_with_double_coordinates() {
    let dir = tempfile::tempdir().unwrap();
    let (dsm, grid, colours, _) = cloud();
    let path = dir.path().join("c.ply");
    let n = write_point_cloud(&path, &dsm, &grid, Some(&colours), None).unwrap();
    assert_eq!(n, W * H - 2);
    let bytes = std::fs::read(&path).unwrap();
    let end = b"end_header\n";
    let at = bytes.windows(end.len()).position(|w| w == end).unwrap() + end.len();
    let header = std::str::from_utf8(&bytes[..at]).unwrap();
    assert!(
        header.starts_with("ply\nformat binary_little_endian 1.0\n"),
        "{header}"
    );
    assert!(header.contains(&format!("element vertex {n}\n")));
    for p in [
        "double x",
        "double y",
        "double z",
        "uchar red",
        "uchar green",
        "uchar blue",
    ] {
        assert!(header.contains(&format!("property {p}\n")), "{p}");
    }
    let body = &bytes[at..];
    assert!(!header.contains("uchar") || header.contains("property uchar blue\nend_header"));
    assert_eq!(body.len(), n * (3 * 8 + 3));
    let f64_at = |o: usize| f64::from_le_bytes(body[o..o + 8].try_into().unwrap());
    let (x, y) = grid.cell_centre(1, 0);
    assert_eq!((f64_at(0), f64_at(8), f64_at(16)), (x, y, 11.0));
    assert_eq!(&body[24..27], &[1, 254, 7]);

    let grey = dir.path().join("grey.ply");
    write_point_cloud(&grey, &dsm, &grid, None, None).unwrap();
    let bytes = std::fs::read(&grey).unwrap();
    let at = bytes.windows(end.len()).position(|w| w == end).unwrap() + end.len();
    assert!(!std::str::from_utf8(&bytes[..at]).unwrap().contains("uchar"));
    assert_eq!(bytes.len() - at, n * 24);
}

#[test]
fn bad_inputs_are_refused_with_the_path() {
    let dir = tempfile::tempdir().unwrap();
    let (dsm, grid, colours, keep) = cloud();
    let xyz = dir.path().join("c.xyz");
    let msg = write_point_cloud(&xyz, &dsm, &grid, None, None)
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("c.xyz") && msg.contains("las, laz, ply"),
        "{msg}"
    );
    let las = dir.path().join("c.las");
    let grey = Image::filled(W, H, 1, 0.0);
    assert!(write_point_cloud(&las, &dsm, &grid, Some(&grey), None).is_err());
    assert!(write_point_cloud(&las, &dsm, &grid, Some(&colours), Some(&keep[1..])).is_err());
    assert!(!las.exists());
}

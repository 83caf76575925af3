//! The quicklook PNG of a DSM.

use camera::DsmGrid;
use products::write_preview;
use raster::formats::{decode_png, PngDepth};
use raster::Image;

#[test]
fn a_preview_decodes_at_the_dsm_size_with_holes_transparent() {
    let dir = tempfile::tempdir().unwrap();
    let grid = DsmGrid::new(435_000.0, 3_355_000.0, 0.5, 40, 30, 32617).unwrap();
    let mut dsm = Image::from_fn(40, 30, |x, y| {
        if (10..20).contains(&x) && (5..15).contains(&y) {
            25.0
        } else {
            x as f32 * 0.1
        }
    });
    dsm.set(3, 3, 0, f32::NAN);
    let path = dir.path().join("preview.png");
    write_preview(&path, &dsm, &grid).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let (png, depth) = decode_png(&bytes, &path).unwrap();
    assert_eq!(depth, PngDepth::Eight);
    assert_eq!((png.width(), png.height(), png.channels()), (40, 30, 4));
    assert_eq!(png.get(3, 3, 3), 0.0, "a hole is transparent");
    assert_eq!(png.get(4, 3, 3), 255.0);
    // The tower is red-ish (top of the turbo map), the low ground blue-ish.
    let (tower, ground) = (png.pixel(15, 10), png.pixel(2, 25));
    assert!(
        tower[0] > tower[2] && ground[2] > ground[0],
        "{tower:?} {ground:?}"
    );

    let wrong = Image::filled(10, 10, 1, 0.0);
    assert!(write_preview(&path, &wrong, &grid).is_err());
}

#[test]
fn a_large_dsm_is_shrunk() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (5000, 40);
    let grid = DsmGrid::new(435_000.0, 3_355_000.0, 0.5, w, h, 32617).unwrap();
    let dsm = Image::from_fn(w, h, |x, _| (x % 100) as f32);
    let path = dir.path().join("big.png");
    write_preview(&path, &dsm, &grid).unwrap();
    let (png, _) = decode_png(&std::fs::read(&path).unwrap(), &path).unwrap();
    // 5000 cells → a factor of 3 → 1667 × 14.
    assert_eq!(png.size(), (1667, 14));
}

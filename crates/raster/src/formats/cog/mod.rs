//! Cloud-Optimized GeoTIFF writer for float32 rasters (DSMs; and tiled uint8 imagery): internal 256 × 256 tiles, Deflate,
//! overviews by 2× down to one tile, every directory (IFD) at the start of the file and the tile
//! data after them, smallest overview first: the layout GDAL's COG driver writes, so GDAL, QGIS
//! and HTTP range readers open a whole-scene DSM at any zoom without reading all of it.
//!
//! The tiff crate writes strips only, hence this small writer. Classic TIFF is used up to 4 GiB,
//! BigTIFF beyond. It takes the rows in blocks ([`CogWriter`]) and parks the compressed tiles on
//! disk until the directories can be written, so a DSM larger than memory can be written while it
//! is computed; [`write_cog`] gives it a whole image at once.

mod layout;
mod sample;
mod spool;
mod writer;

use std::path::Path;

use super::GeoTiffMeta;
use crate::{Image, Result};

pub use sample::COG_TILE;
pub use writer::CogWriter;

use sample::Sample;

/// Writes `image` (float32, 1–16 bands) as a tiled, Deflate-compressed GeoTIFF with overviews
/// and the georeferencing, GDAL_NODATA and RPC tags of `meta` (on the full-resolution image;
/// the nodata tag on every level). Overviews average the finite samples of each 2 × 2 block.
/// An image computed by parts can be written without holding it whole: [`CogWriter`].
pub fn write_cog(path: impl AsRef<Path>, image: &Image, meta: &GeoTiffMeta) -> Result<()> {
    write_whole(path.as_ref(), image, meta, Sample::F32, true)
}

/// Writes `image` as a tiled, Deflate-compressed uint8 (Geo)TIFF without overviews, the way
/// satellite imagery ships (values rounded and clamped to 0–255, NaN stored as 0: give
/// `meta.nodata = Some(0.0)` to mark it).
pub fn write_tiled_u8(path: impl AsRef<Path>, image: &Image, meta: &GeoTiffMeta) -> Result<()> {
    write_whole(path.as_ref(), image, meta, Sample::U8, false)
}

/// An image held whole, given to the row writer in one call (its tiles compress in parallel).
fn write_whole(
    path: &Path,
    image: &Image,
    meta: &GeoTiffMeta,
    sample: Sample,
    overviews: bool,
) -> Result<()> {
    let size = (image.width(), image.height(), image.channels());
    let mut writer = CogWriter::open(path, size, meta, sample, overviews)?;
    writer.write_rows(image.data())?;
    writer.finish()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formats::{read_tiff, GeoReference};

    /// A 0.5 m UTM grid (zone 17N) with NaN as nodata.
    fn utm_meta() -> GeoTiffMeta {
        GeoTiffMeta {
            georef: Some(GeoReference::from_origin_utm(
                435000.0, 3355000.0, 0.5, 32617,
            )),
            nodata: Some(f64::NAN),
            rpc: None,
            gdal_metadata: None,
        }
    }

    #[test]
    fn a_cog_reads_back_exactly_with_its_georeference() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("dsm.tif");
        let (w, h) = (600, 300);
        let mut img = Image::from_fn(w, h, |x, y| (x as f32) * 0.5 - (y as f32) * 0.25);
        img.set(7, 3, 0, f32::NAN);
        let meta = utm_meta();
        write_cog(&path, &img, &meta).unwrap();
        let back = read_tiff(&path).unwrap();
        assert_eq!(back.image.size(), (w, h));
        for (a, b) in back.image.data().iter().zip(img.data()) {
            assert!(a == b || (a.is_nan() && b.is_nan()), "{a} {b}");
        }
        let g = back.georef.unwrap();
        assert_eq!(g.epsg, Some(32617));
        assert_eq!(g.geotransform, [435000.0, 0.5, 0.0, 3355000.0, 0.0, -0.5]);
        assert!(back.nodata.unwrap().is_nan());
    }

    #[test]
    fn tiled_uint8_imagery_rounds_and_keeps_its_nodata() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("raw.tif");
        let mut img = Image::from_fn(300, 260, |x, y| ((x * 7 + y) % 300) as f32 - 20.4);
        img.set(0, 0, 0, f32::NAN);
        let rgb = img.to_rgb();
        let meta = GeoTiffMeta {
            nodata: Some(0.0),
            ..GeoTiffMeta::default()
        };
        write_tiled_u8(&path, &rgb, &meta).unwrap();
        let back = read_tiff(&path).unwrap();
        assert_eq!(back.image.channels(), 3);
        assert_eq!(back.nodata, Some(0.0));
        for (a, b) in back.image.data().iter().zip(rgb.data()) {
            let want = if b.is_nan() {
                0.0
            } else {
                b.round().clamp(0.0, 255.0)
            };
            assert_eq!(*a, want);
        }
    }

    #[test]
    fn overviews_halve_down_to_one_tile_and_average_finite_samples() {
        let img = Image::new(3, 2, 1, vec![1.0, 3.0, 5.0, f32::NAN, 7.0, f32::NAN]).unwrap();
        let half = writer::halve_rows(img.data(), 3, 1);
        assert_eq!(half, &[(1.0 + 3.0 + 7.0) / 3.0, 5.0]);
        let big = Image::filled(1000, 300, 1, 1.0);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("big.tif");
        write_cog(&path, &big, &GeoTiffMeta::default()).unwrap();
        // 1000 → 500 → 250 wide: three directories, the last one tile.
        let bytes = std::fs::read(&path).unwrap();
        let mut at = u32::from_le_bytes(bytes[4..8].try_into().unwrap()) as usize;
        let mut widths = Vec::new();
        while at != 0 {
            let n = u16::from_le_bytes(bytes[at..at + 2].try_into().unwrap()) as usize;
            for i in 0..n {
                let e = at + 2 + 12 * i;
                if u16::from_le_bytes(bytes[e..e + 2].try_into().unwrap()) == 256 {
                    widths.push(u32::from_le_bytes(bytes[e + 8..e + 12].try_into().unwrap()));
                }
            }
            let next = at + 2 + 12 * n;
            at = u32::from_le_bytes(bytes[next..next + 4].try_into().unwrap()) as usize;
        }
        assert_eq!(widths, vec![1000, 500, 250]);
    }

    /// An image with NaN holes and values that do not compress to nothing.
    fn patterned(w: usize, h: usize, bands: usize) -> Image {
        let data = (0..w * h * bands)
            .map(|i| {
                let (x, y) = ((i / bands) % w, i / bands / w);
                if (x * 7 + y * 3) % 29 == 0 {
                    f32::NAN
                } else {
                    ((x * 31 + y * 17 + i % bands) % 97) as f32 * 0.37
                }
            })
            .collect();
        Image::new(w, h, bands, data).unwrap()
    }

    /// Rows given in blocks of any height make the same bytes as the image given whole, on sizes
    /// that are and are not multiples of the tile, with up to four levels.
    #[test]
    fn rows_written_in_blocks_make_the_same_file_as_the_whole_image() {
        let dir = tempfile::tempdir().unwrap();
        let meta = utm_meta();
        for (w, h, bands) in [
            (1, 1, 1),
            (300, 7, 1),
            (256, 512, 1),
            (1100, 1300, 1),
            (600, 531, 2),
        ] {
            let img = patterned(w, h, bands);
            let whole = dir.path().join("whole.tif");
            write_cog(&whole, &img, &meta).unwrap();
            let want = std::fs::read(&whole).unwrap();
            for block in [1, 7, 32, 256, 300, 1024] {
                let path = dir.path().join(format!("rows{block}.tif"));
                let mut writer = CogWriter::new(&path, (w, h, bands), &meta).unwrap();
                for rows in img.data().chunks(block * w * bands) {
                    writer.write_rows(rows).unwrap();
                }
                writer.finish().unwrap();
                let got = std::fs::read(&path).unwrap();
                assert!(
                    got == want,
                    "{w}x{h}x{bands} in blocks of {block} rows differs"
                );
            }
        }
        let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(names.len(), 7, "no spool left behind: {names:?}");
    }

    #[test]
    fn an_unfinished_writer_leaves_nothing_and_a_short_image_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("dsm.tif");
        let meta = GeoTiffMeta::default();
        let mut writer = CogWriter::new(&path, (300, 300, 1), &meta).unwrap();
        writer.write_rows(&[1.0; 300 * 10]).unwrap();
        let msg = writer.finish().unwrap_err().to_string();
        assert!(msg.contains("10 rows written of 300"), "{msg}");
        let mut writer = CogWriter::new(&path, (300, 300, 1), &meta).unwrap();
        assert!(writer.write_rows(&[1.0; 301]).is_err());
        drop(writer);
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    }
}

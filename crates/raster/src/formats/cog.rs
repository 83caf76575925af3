//! Cloud-Optimized GeoTIFF writer for float32 rasters (DSMs; and tiled uint8 imagery): internal 256 × 256 tiles, Deflate,
//! overviews by 2× down to one tile, every directory (IFD) at the start of the file and the tile
//! data after them, smallest overview first: the layout GDAL's COG driver writes, so GDAL, QGIS
//! and HTTP range readers open a whole-scene DSM at any zoom without reading all of it.
//!
//! The tiff crate writes strips only, hence this small writer. Classic TIFF is used up to 4 GiB,
//! BigTIFF beyond.

use std::borrow::Cow;
use std::io::{self, Write};
use std::path::Path;

use flate2::write::ZlibEncoder;
use rayon::prelude::*;

use super::support::write_atomically;
use super::tiff::{geo_tags, GeoTags, TAG_RPC};
use super::GeoTiffMeta;
use crate::{Image, RasterError, Result};

/// Side of the internal tiles, pixels.
pub const COG_TILE: usize = 256;

/// TIFF field types.
const SHORT: u16 = 3;
const LONG: u16 = 4;
const DOUBLE: u16 = 12;
const ASCII: u16 = 2;
const LONG8: u16 = 16;

/// How samples are stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Sample {
    F32,
    /// Rounded and clamped to 0–255; NaN becomes 0.
    U8,
}

/// Writes `image` (float32, 1–16 bands) as a tiled, Deflate-compressed GeoTIFF with overviews
/// and the georeferencing, GDAL_NODATA and RPC tags of `meta` (on the full-resolution image;
/// the nodata tag on every level). Overviews average the finite samples of each 2 × 2 block.
pub fn write_cog(path: impl AsRef<Path>, image: &Image, meta: &GeoTiffMeta) -> Result<()> {
    write_tiled(path.as_ref(), image, meta, Sample::F32, true)
}

/// Writes `image` as a tiled, Deflate-compressed uint8 (Geo)TIFF without overviews, the way
/// satellite imagery ships (values rounded and clamped to 0–255, NaN stored as 0: give
/// `meta.nodata = Some(0.0)` to mark it).
pub fn write_tiled_u8(path: impl AsRef<Path>, image: &Image, meta: &GeoTiffMeta) -> Result<()> {
    write_tiled(path.as_ref(), image, meta, Sample::U8, false)
}

fn write_tiled(
    path: &Path,
    image: &Image,
    meta: &GeoTiffMeta,
    sample: Sample,
    overviews: bool,
) -> Result<()> {
    let shape = |m: String| RasterError::Shape(format!("{}: {m}", path.display()));
    let (w, h, bands) = (image.width(), image.height(), image.channels());
    if w == 0 || h == 0 {
        return Err(shape("cannot write an empty image".into()));
    }
    if !(1..=16).contains(&bands) || w > u32::MAX as usize || h > u32::MAX as usize {
        return Err(shape(format!("cannot write a {w}x{h}x{bands} COG")));
    }
    let tags = geo_tags(meta).map_err(shape)?;
    // The full resolution is borrowed, not copied: a scene's DSM can be gigabytes.
    let mut levels = vec![Cow::Borrowed(image)];
    while overviews
        && levels
            .last()
            .is_some_and(|l| l.width() > COG_TILE || l.height() > COG_TILE)
    {
        let next = halve(levels.last().expect("a level"));
        levels.push(Cow::Owned(next));
    }
    let tiles: Vec<Vec<Vec<u8>>> = levels
        .iter()
        .map(|l| compress_tiles(l, sample))
        .collect::<io::Result<_>>()
        .map_err(|e| RasterError::io(path, e))?;
    let data_len: u64 = tiles.iter().flatten().map(|t| t.len() as u64).sum();
    let big = data_len > (u32::MAX as u64) - (64 << 20);
    let bytes = layout(&levels, &tiles, &tags, sample, big);
    write_atomically(path, |file| {
        file.write_all(&bytes)?;
        // Tile data after every directory, smallest overview first (GDAL's COG order).
        for level in tiles.iter().rev() {
            for t in level {
                file.write_all(t)?;
            }
        }
        Ok(())
    })
}

/// The next overview: each cell the mean of the finite samples of its 2 × 2 block (NaN if none).
fn halve(image: &Image) -> Image {
    let (w, h, c) = (image.width(), image.height(), image.channels());
    let (hw, hh) = (w.div_ceil(2), h.div_ceil(2));
    let mut out = vec![f32::NAN; hw * hh * c];
    out.par_chunks_mut(hw * c).enumerate().for_each(|(y, row)| {
        for x in 0..hw {
            for b in 0..c {
                let (mut sum, mut n) = (0.0f64, 0u32);
                for (sx, sy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let (xx, yy) = (2 * x + sx, 2 * y + sy);
                    if xx < w && yy < h {
                        let v = image.get(xx, yy, b);
                        if v.is_finite() {
                            sum += v as f64;
                            n += 1;
                        }
                    }
                }
                if n > 0 {
                    row[x * c + b] = (sum / n as f64) as f32;
                }
            }
        }
    });
    Image::new(hw, hh, c, out).expect("sizes match")
}

/// The Deflate (zlib) stream of every tile, row-major; edge tiles are padded with NaN.
fn compress_tiles(image: &Image, sample: Sample) -> io::Result<Vec<Vec<u8>>> {
    let (w, h, c) = (image.width(), image.height(), image.channels());
    let (across, down) = (w.div_ceil(COG_TILE), h.div_ceil(COG_TILE));
    (0..across * down)
        .into_par_iter()
        .map(|i| {
            let (x0, y0) = ((i % across) * COG_TILE, (i / across) * COG_TILE);
            let mut raw = Vec::with_capacity(COG_TILE * COG_TILE * c * 4);
            let mut push = |v: f32| match sample {
                Sample::F32 => raw.extend_from_slice(&v.to_le_bytes()),
                Sample::U8 => raw.push(if v.is_nan() {
                    0
                } else {
                    v.round().clamp(0.0, 255.0) as u8
                }),
            };
            for y in y0..y0 + COG_TILE {
                for x in x0..x0 + COG_TILE {
                    for b in 0..c {
                        let v = if x < w && y < h {
                            image.get(x, y, b)
                        } else {
                            f32::NAN
                        };
                        push(v);
                    }
                }
            }
            let mut z = ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
            z.write_all(&raw)?;
            z.finish()
        })
        .collect()
}

/// One directory entry: tag, type, and its values as little-endian bytes.
struct Entry {
    tag: u16,
    kind: u16,
    count: u64,
    bytes: Vec<u8>,
}

impl Entry {
    fn shorts(tag: u16, v: &[u16]) -> Self {
        let bytes = v.iter().flat_map(|x| x.to_le_bytes()).collect();
        Entry {
            tag,
            kind: SHORT,
            count: v.len() as u64,
            bytes,
        }
    }
    fn long(tag: u16, v: u32) -> Self {
        Entry {
            tag,
            kind: LONG,
            count: 1,
            bytes: v.to_le_bytes().to_vec(),
        }
    }
    fn doubles(tag: u16, v: &[f64]) -> Self {
        let bytes = v.iter().flat_map(|x| x.to_le_bytes()).collect();
        Entry {
            tag,
            kind: DOUBLE,
            count: v.len() as u64,
            bytes,
        }
    }
    fn ascii(tag: u16, s: &str) -> Self {
        let mut bytes = s.as_bytes().to_vec();
        bytes.push(0);
        Entry {
            tag,
            kind: ASCII,
            count: bytes.len() as u64,
            bytes,
        }
    }
    /// File offsets: LONG in classic TIFF, LONG8 in BigTIFF.
    fn offsets(tag: u16, v: &[u64], big: bool) -> Self {
        let bytes = if big {
            v.iter().flat_map(|x| x.to_le_bytes()).collect()
        } else {
            v.iter().flat_map(|&x| (x as u32).to_le_bytes()).collect()
        };
        let kind = if big { LONG8 } else { LONG };
        Entry {
            tag,
            kind,
            count: v.len() as u64,
            bytes,
        }
    }
}

/// The header and every directory with its out-of-line values; the tile data follows, in the
/// order [`write_cog`] writes it.
fn layout(
    levels: &[Cow<Image>],
    tiles: &[Vec<Vec<u8>>],
    tags: &GeoTags,
    sample: Sample,
    big: bool,
) -> Vec<u8> {
    // Directory sizes do not depend on the offsets' values: lay them out with zero offsets
    // first, then again with the real ones.
    let dirs = |tile_offsets: &[Vec<u64>]| -> Vec<Vec<Entry>> {
        levels
            .iter()
            .enumerate()
            .map(|(k, level)| directory(k, level, &tiles[k], &tile_offsets[k], tags, sample, big))
            .collect()
    };
    let zeros: Vec<Vec<u64>> = tiles.iter().map(|t| vec![0; t.len()]).collect();
    let header_len = if big { 16 } else { 8 };
    let dir_len = |entries: &[Entry]| -> u64 {
        let (count, entry, next, inline) = if big { (8, 20, 8, 8) } else { (2, 12, 4, 4) };
        let out_of_line: u64 = entries
            .iter()
            .filter(|e| e.bytes.len() > inline)
            .map(|e| e.bytes.len().next_multiple_of(2) as u64)
            .sum();
        count + entry * entries.len() as u64 + next + out_of_line
    };
    let total_dirs: u64 = dirs(&zeros).iter().map(|d| dir_len(d)).sum();
    // Tile data: smallest overview first.
    let mut offsets = zeros.clone();
    let mut at = header_len + total_dirs;
    for k in (0..levels.len()).rev() {
        for (i, t) in tiles[k].iter().enumerate() {
            offsets[k][i] = at;
            at += t.len() as u64;
        }
    }
    let dirs = dirs(&offsets);
    let mut out = Vec::new();
    if big {
        out.extend_from_slice(b"II");
        out.extend_from_slice(&43u16.to_le_bytes());
        out.extend_from_slice(&8u16.to_le_bytes());
        out.extend_from_slice(&0u16.to_le_bytes());
        out.extend_from_slice(&16u64.to_le_bytes());
    } else {
        out.extend_from_slice(b"II");
        out.extend_from_slice(&42u16.to_le_bytes());
        out.extend_from_slice(&8u32.to_le_bytes());
    }
    let n = dirs.len();
    for (k, entries) in dirs.iter().enumerate() {
        let start = out.len() as u64;
        let len = dir_len(entries);
        let next = if k + 1 < n { start + len } else { 0 };
        write_directory(&mut out, entries, start, next, big);
        debug_assert_eq!(out.len() as u64, start + len);
    }
    debug_assert_eq!(out.len() as u64, header_len + total_dirs);
    out
}

/// The entries of level `k` (0 = full resolution), sorted by tag as TIFF requires.
fn directory(
    k: usize,
    level: &Image,
    tiles: &[Vec<u8>],
    offsets: &[u64],
    tags: &GeoTags,
    sample: Sample,
    big: bool,
) -> Vec<Entry> {
    let bands = level.channels();
    let (bits, format) = match sample {
        Sample::F32 => (32, 3),
        Sample::U8 => (8, 1),
    };
    let photometric = if sample == Sample::U8 && bands == 3 {
        2
    } else {
        1
    };
    let counts: Vec<u64> = tiles.iter().map(|t| t.len() as u64).collect();
    let mut e = vec![
        Entry::long(254, (k > 0) as u32),
        Entry::long(256, level.width() as u32),
        Entry::long(257, level.height() as u32),
        Entry::shorts(258, &vec![bits; bands]),
        Entry::shorts(259, &[8]),
        Entry::shorts(262, &[photometric]),
        Entry::shorts(277, &[bands as u16]),
        Entry::shorts(284, &[1]),
        Entry::shorts(322, &[COG_TILE as u16]),
        Entry::shorts(323, &[COG_TILE as u16]),
        Entry::offsets(324, offsets, big),
        Entry::offsets(325, &counts, big),
        Entry::shorts(339, &vec![format; bands]),
    ];
    let extra = if photometric == 2 {
        bands - 3
    } else {
        bands - 1
    };
    if extra > 0 {
        e.push(Entry::shorts(338, &vec![0; extra]));
    }
    if let Some(n) = &tags.nodata {
        e.push(Entry::ascii(42113, n));
    }
    if k == 0 {
        if let Some(s) = &tags.scale {
            e.push(Entry::doubles(33550, s));
        }
        if let Some(t) = &tags.tiepoint {
            e.push(Entry::doubles(33922, t));
        }
        if let Some(m) = &tags.transform {
            e.push(Entry::doubles(34264, m));
        }
        if let Some(keys) = &tags.keys {
            e.push(Entry::shorts(34735, keys));
        }
        if let Some(d) = &tags.doubles {
            e.push(Entry::doubles(34736, d));
        }
        if let Some(a) = &tags.ascii {
            e.push(Entry::ascii(34737, a));
        }
        if let Some(r) = &tags.rpc {
            e.push(Entry::doubles(TAG_RPC, r));
        }
    }
    e.sort_by_key(|x| x.tag);
    e
}

/// Appends a directory that starts at file offset `start`: entries, the next directory's offset,
/// then the values that do not fit in an entry (word-aligned).
fn write_directory(out: &mut Vec<u8>, entries: &[Entry], start: u64, next: u64, big: bool) {
    let (count_len, entry_len, next_len, inline) = if big { (8, 20, 8, 8) } else { (2, 12, 4, 4) };
    let mut extra_at = start + count_len + entry_len * entries.len() as u64 + next_len;
    let mut extra = Vec::new();
    if big {
        out.extend_from_slice(&(entries.len() as u64).to_le_bytes());
    } else {
        out.extend_from_slice(&(entries.len() as u16).to_le_bytes());
    }
    for e in entries {
        out.extend_from_slice(&e.tag.to_le_bytes());
        out.extend_from_slice(&e.kind.to_le_bytes());
        if big {
            out.extend_from_slice(&e.count.to_le_bytes());
        } else {
            out.extend_from_slice(&(e.count as u32).to_le_bytes());
        }
        if e.bytes.len() <= inline {
            let mut v = e.bytes.clone();
            v.resize(inline, 0);
            out.extend_from_slice(&v);
        } else {
            if big {
                out.extend_from_slice(&extra_at.to_le_bytes());
            } else {
                out.extend_from_slice(&(extra_at as u32).to_le_bytes());
            }
            let padded = e.bytes.len().next_multiple_of(2);
            extra.extend_from_slice(&e.bytes);
            extra.resize(extra.len() + padded - e.bytes.len(), 0);
            extra_at += padded as u64;
        }
    }
    if big {
        out.extend_from_slice(&next.to_le_bytes());
    } else {
        out.extend_from_slice(&(next as u32).to_le_bytes());
    }
    out.extend_from_slice(&extra);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formats::{read_tiff, GeoReference};

    #[test]
    fn a_cog_reads_back_exactly_with_its_georeference() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("dsm.tif");
        let (w, h) = (600, 300);
        let mut img = Image::from_fn(w, h, |x, y| (x as f32) * 0.5 - (y as f32) * 0.25);
        img.set(7, 3, 0, f32::NAN);
        let meta = GeoTiffMeta {
            georef: Some(GeoReference::from_origin_utm(
                435000.0, 3355000.0, 0.5, 32617,
            )),
            nodata: Some(f64::NAN),
            rpc: None,
        };
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
        let half = halve(&img);
        assert_eq!(half.size(), (2, 1));
        assert_eq!(half.data(), &[(1.0 + 3.0 + 7.0) / 3.0, 5.0]);
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
}

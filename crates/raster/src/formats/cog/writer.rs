//! The COG writer proper, fed by rows: each level of the pyramid compresses its tiles as soon as
//! a row of tiles is complete, hands every pair of rows down to the next level as one halved row,
//! and parks its compressed tiles in a [`Spool`]. Memory stays at a row of tiles per level
//! whatever the image's height, so a DSM can be written while it is still being computed.

use std::io::{self, Write};
use std::path::{Path, PathBuf};

use flate2::write::ZlibEncoder;
use rayon::prelude::*;

use super::layout::{layout, LevelTiles};
use super::sample::{Sample, COG_TILE};
use super::spool::Spool;
use crate::formats::support::write_atomically;
use crate::formats::tiff::{geo_tags, GeoTags};
use crate::formats::GeoTiffMeta;
use crate::{RasterError, Result};

/// Writes a tiled, Deflate-compressed (Geo)TIFF from rows given top to bottom, in as many calls
/// of [`CogWriter::write_rows`] as the caller likes; [`CogWriter::finish`] assembles the file
/// (atomically). Dropping it unfinished leaves no file behind.
pub struct CogWriter {
    path: PathBuf,
    tags: GeoTags,
    sample: Sample,
    bands: usize,
    /// Full resolution first, then each overview.
    levels: Vec<Level>,
}

/// One level of the pyramid while rows arrive.
struct Level {
    width: usize,
    height: usize,
    /// Rows received so far.
    received: usize,
    /// Rows received that do not yet make a complete row of tiles.
    pending: Vec<f32>,
    /// A row waiting for the next one to make a row of the next level.
    unpaired: Option<Vec<f32>>,
    lengths: Vec<u64>,
    spool: Spool,
}

impl CogWriter {
    /// A writer of a `width × height × bands` float32 image with overviews by 2× down to one
    /// tile (each the mean of the finite samples of a 2 × 2 block), the georeferencing, nodata and
    /// RPC tags of `meta` on the full resolution and the nodata tag on every level.
    pub fn new(
        path: impl AsRef<Path>,
        (width, height, bands): (usize, usize, usize),
        meta: &GeoTiffMeta,
    ) -> Result<Self> {
        Self::open(
            path.as_ref(),
            (width, height, bands),
            meta,
            Sample::F32,
            true,
        )
    }

    pub(super) fn open(
        path: &Path,
        (w, h, bands): (usize, usize, usize),
        meta: &GeoTiffMeta,
        sample: Sample,
        overviews: bool,
    ) -> Result<Self> {
        let shape = |m: String| RasterError::Shape(format!("{}: {m}", path.display()));
        if w == 0 || h == 0 {
            return Err(shape("cannot write an empty image".into()));
        }
        if !(1..=16).contains(&bands) || w > u32::MAX as usize || h > u32::MAX as usize {
            return Err(shape(format!("cannot write a {w}x{h}x{bands} COG")));
        }
        let tags = geo_tags(meta).map_err(shape)?;
        let err = |e| RasterError::io(path, e);
        let name = path.file_name().ok_or_else(|| {
            err(io::Error::new(
                io::ErrorKind::InvalidInput,
                "not a file path",
            ))
        })?;
        let dir = match path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        std::fs::create_dir_all(dir).map_err(err)?;
        let mut sizes = vec![(w, h)];
        while let Some(&(lw, lh)) = sizes.last().filter(|_| overviews) {
            if lw <= COG_TILE && lh <= COG_TILE {
                break;
            }
            sizes.push((lw.div_ceil(2), lh.div_ceil(2)));
        }
        let levels = sizes
            .into_iter()
            .map(|(width, height)| {
                Ok(Level {
                    width,
                    height,
                    received: 0,
                    pending: Vec::new(),
                    unpaired: None,
                    lengths: Vec::new(),
                    spool: Spool::create(dir, name)?,
                })
            })
            .collect::<io::Result<_>>()
            .map_err(err)?;
        Ok(CogWriter {
            path: path.to_path_buf(),
            tags,
            sample,
            bands,
            levels,
        })
    }

    /// The next full-resolution rows, bands interleaved (`width × bands` values a row).
    pub fn write_rows(&mut self, rows: &[f32]) -> Result<()> {
        let (w, h) = (self.levels[0].width, self.levels[0].height);
        let row_len = w * self.bands;
        let n = rows.len() / row_len;
        if !rows.len().is_multiple_of(row_len) || self.levels[0].received + n > h {
            return Err(RasterError::Shape(format!(
                "{}: {} values do not make whole rows of {w}x{}, or go past its {h} rows",
                self.path.display(),
                rows.len(),
                self.bands
            )));
        }
        self.push(0, rows)
            .map_err(|e| RasterError::io(&self.path, e))
    }

    /// Writes the file, once every row has been given.
    pub fn finish(mut self) -> Result<()> {
        let (received, h) = (self.levels[0].received, self.levels[0].height);
        if received != h {
            return Err(RasterError::Shape(format!(
                "{}: {received} rows written of {h}",
                self.path.display()
            )));
        }
        let tiles: Vec<LevelTiles> = self
            .levels
            .iter_mut()
            .map(|l| LevelTiles {
                width: l.width,
                height: l.height,
                bands: self.bands,
                lengths: std::mem::take(&mut l.lengths),
            })
            .collect();
        let data_len: u64 = tiles.iter().flat_map(|l| &l.lengths).sum();
        let big = data_len > (u32::MAX as u64) - (64 << 20);
        let head = layout(&tiles, &self.tags, self.sample, big);
        let levels = &mut self.levels;
        write_atomically(&self.path, |file| {
            file.write_all(&head)?;
            // Tile data after every directory, smallest overview first (GDAL's COG order).
            for level in levels.iter_mut().rev() {
                level.spool.copy_into(file)?;
            }
            Ok(())
        })
    }

    /// Gives level `k` its next rows: complete rows of tiles are compressed and spooled, pairs of
    /// rows go down to level `k + 1` halved.
    fn push(&mut self, k: usize, rows: &[f32]) -> io::Result<()> {
        let (bands, sample) = (self.bands, self.sample);
        let has_next = k + 1 < self.levels.len();
        let level = &mut self.levels[k];
        let row_len = level.width * bands;
        level.received += rows.len() / row_len;
        let down = if has_next {
            level.halve(rows, bands)
        } else {
            Vec::new()
        };
        level.compress(rows, bands, sample)?;
        if !down.is_empty() {
            self.push(k + 1, &down)?;
        }
        Ok(())
    }
}

impl Level {
    /// The next level's rows from `rows` and the row left unpaired before them; the last row of
    /// an odd height is halved alone once it arrives.
    fn halve(&mut self, mut rows: &[f32], bands: usize) -> Vec<f32> {
        let row_len = self.width * bands;
        let mut out = Vec::new();
        if let Some(first) = self.unpaired.take() {
            match rows.split_at_checked(row_len) {
                Some((second, rest)) => {
                    let pair: Vec<f32> = first.iter().chain(second).copied().collect();
                    out.extend(halve_rows(&pair, self.width, bands));
                    rows = rest;
                }
                None => self.unpaired = Some(first),
            }
        }
        let even = rows.len() / (2 * row_len) * (2 * row_len);
        out.extend(halve_rows(&rows[..even], self.width, bands));
        if even < rows.len() {
            self.unpaired = Some(rows[even..].to_vec());
        }
        if self.received == self.height {
            if let Some(last) = self.unpaired.take() {
                out.extend(halve_rows(&last, self.width, bands));
            }
        }
        out
    }

    /// Compresses and spools every row of tiles `rows` completes (a row of tiles is 256 rows,
    /// or what is left at the bottom), keeping the rest for the next call.
    fn compress(&mut self, rows: &[f32], bands: usize, sample: Sample) -> io::Result<()> {
        let tile_len = COG_TILE * self.width * bands;
        let last = self.received == self.height;
        let mut rows = rows;
        if !self.pending.is_empty() {
            let take = (tile_len - self.pending.len()).min(rows.len());
            self.pending.extend_from_slice(&rows[..take]);
            rows = &rows[take..];
            if self.pending.len() < tile_len && !last {
                return Ok(());
            }
            let pending = std::mem::take(&mut self.pending);
            self.spool_tiles(&pending, bands, sample)?;
        }
        let whole = if last {
            rows.len()
        } else {
            rows.len() / tile_len * tile_len
        };
        self.spool_tiles(&rows[..whole], bands, sample)?;
        self.pending.extend_from_slice(&rows[whole..]);
        Ok(())
    }

    /// Compresses the tiles of complete rows of tiles (in parallel) and spools them in order.
    fn spool_tiles(&mut self, rows: &[f32], bands: usize, sample: Sample) -> io::Result<()> {
        let row_len = self.width * bands;
        let across = self.width.div_ceil(COG_TILE);
        let tile_rows: Vec<&[f32]> = rows.chunks(COG_TILE * row_len).collect();
        let tiles: Vec<Vec<u8>> = (0..tile_rows.len() * across)
            .into_par_iter()
            .map(|i| {
                let strip = tile_rows[i / across];
                compress_tile(strip, self.width, bands, (i % across) * COG_TILE, sample)
            })
            .collect::<io::Result<_>>()?;
        for t in &tiles {
            self.spool.append(t)?;
            self.lengths.push(t.len() as u64);
        }
        Ok(())
    }
}

/// The next overview of whole rows: each cell the mean of the finite samples of its 2 × 2 block
/// (NaN if none); an odd last row is halved alone.
pub(super) fn halve_rows(rows: &[f32], w: usize, c: usize) -> Vec<f32> {
    let h = rows.len() / (w * c);
    let (hw, hh) = (w.div_ceil(2), h.div_ceil(2));
    let mut out = vec![f32::NAN; hw * hh * c];
    out.par_chunks_mut(hw * c).enumerate().for_each(|(y, row)| {
        for x in 0..hw {
            for b in 0..c {
                let (mut sum, mut n) = (0.0f64, 0u32);
                for (sx, sy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let (xx, yy) = (2 * x + sx, 2 * y + sy);
                    if xx < w && yy < h {
                        let v = rows[(yy * w + xx) * c + b];
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
    out
}

/// The Deflate (zlib) stream of the tile at column `x0` of a row of tiles (`strip`: up to 256
/// whole rows of width `w`); what lies outside the image is padded with NaN.
fn compress_tile(
    strip: &[f32],
    w: usize,
    c: usize,
    x0: usize,
    sample: Sample,
) -> io::Result<Vec<u8>> {
    let h = strip.len() / (w * c);
    let mut raw = Vec::with_capacity(COG_TILE * COG_TILE * c * 4);
    let mut push = |v: f32| match sample {
        Sample::F32 => raw.extend_from_slice(&v.to_le_bytes()),
        Sample::U8 => raw.push(if v.is_nan() {
            0
        } else {
            v.round().clamp(0.0, 255.0) as u8
        }),
    };
    for y in 0..COG_TILE {
        for x in x0..x0 + COG_TILE {
            for b in 0..c {
                let v = if x < w && y < h {
                    strip[(y * w + x) * c + b]
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
}

//! The header and directories (IFDs) of a COG, laid out once every level's tile sizes are known:
//! they come first in the file, the tile data after them.

use super::sample::{Sample, COG_TILE};
use crate::formats::tiff::{GeoTags, TAG_GDAL_METADATA, TAG_RPC};

/// TIFF field types.
const SHORT: u16 = 3;
const LONG: u16 = 4;
const DOUBLE: u16 = 12;
const ASCII: u16 = 2;
const LONG8: u16 = 16;

/// One level of the pyramid as its directory describes it: size, bands and the compressed length
/// of each tile, row-major.
pub(super) struct LevelTiles {
    pub width: usize,
    pub height: usize,
    pub bands: usize,
    pub lengths: Vec<u64>,
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
/// order [`super::CogWriter`] writes it.
pub(super) fn layout(levels: &[LevelTiles], tags: &GeoTags, sample: Sample, big: bool) -> Vec<u8> {
    // Directory sizes do not depend on the offsets' values: lay them out with zero offsets
    // first, then again with the real ones.
    let dirs = |tile_offsets: &[Vec<u64>]| -> Vec<Vec<Entry>> {
        levels
            .iter()
            .enumerate()
            .map(|(k, level)| directory(k, level, &tile_offsets[k], tags, sample, big))
            .collect()
    };
    let zeros: Vec<Vec<u64>> = levels.iter().map(|l| vec![0; l.lengths.len()]).collect();
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
        for (i, len) in levels[k].lengths.iter().enumerate() {
            offsets[k][i] = at;
            at += len;
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
    level: &LevelTiles,
    offsets: &[u64],
    tags: &GeoTags,
    sample: Sample,
    big: bool,
) -> Vec<Entry> {
    let bands = level.bands;
    let (bits, format) = match sample {
        Sample::F32 => (32, 3),
        Sample::U8 => (8, 1),
    };
    let photometric = if sample == Sample::U8 && bands == 3 {
        2
    } else {
        1
    };
    let mut e = vec![
        Entry::long(254, (k > 0) as u32),
        Entry::long(256, level.width as u32),
        Entry::long(257, level.height as u32),
        Entry::shorts(258, &vec![bits; bands]),
        Entry::shorts(259, &[8]),
        Entry::shorts(262, &[photometric]),
        Entry::shorts(277, &[bands as u16]),
        Entry::shorts(284, &[1]),
        Entry::shorts(322, &[COG_TILE as u16]),
        Entry::shorts(323, &[COG_TILE as u16]),
        Entry::offsets(324, offsets, big),
        Entry::offsets(325, &level.lengths, big),
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
        if let Some(m) = &tags.gdal_metadata {
            e.push(Entry::ascii(TAG_GDAL_METADATA, m));
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

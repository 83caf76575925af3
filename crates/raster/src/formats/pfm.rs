//! PFM (portable float map), the disparity format of the Middlebury and SceneFlow benchmarks:
//! `Pf` (1 channel) or `PF` (3 channels), a negative scale for little endian, rows bottom to top.

use std::io::Write;
use std::path::Path;

use super::support::{alloc_samples, checked_samples, read_bytes, write_atomically};
use crate::{Image, RasterError, Result};

/// Reads a PFM file.
pub fn read_pfm(path: impl AsRef<Path>) -> Result<Image> {
    let path = path.as_ref();
    let bytes = read_bytes(path)?;
    let err = |m: String| RasterError::format(path, m);
    // Header: three whitespace-separated tokens lines: magic, "W H", scale; one whitespace byte
    // then the data.
    let mut tokens = Vec::with_capacity(4);
    let mut i = 0;
    while tokens.len() < 4 {
        while i < bytes.len() && bytes[i].is_ascii_whitespace() {
            i += 1;
        }
        let start = i;
        while i < bytes.len() && !bytes[i].is_ascii_whitespace() && i - start < 64 {
            i += 1;
        }
        if start == i {
            return Err(err("truncated PFM header".into()));
        }
        tokens.push(String::from_utf8_lossy(&bytes[start..i]).into_owned());
        if tokens.len() == 1 && tokens[0] != "PF" && tokens[0] != "Pf" {
            return Err(err("not a PFM file (bad magic, expected PF or Pf)".into()));
        }
    }
    if i >= bytes.len() || !bytes[i].is_ascii_whitespace() {
        return Err(err("truncated PFM header".into()));
    }
    let data = &bytes[i + 1..];
    let channels = if tokens[0] == "PF" { 3 } else { 1 };
    let dim = |s: &str| {
        s.parse::<u64>()
            .ok()
            .filter(|&d| d > 0)
            .ok_or_else(|| err(format!("bad PFM dimension '{s}'")))
    };
    let (w, h) = (dim(&tokens[1])?, dim(&tokens[2])?);
    let scale: f64 = tokens[3]
        .parse()
        .ok()
        .filter(|s: &f64| s.is_finite() && *s != 0.0)
        .ok_or_else(|| err(format!("bad PFM scale '{}'", tokens[3])))?;
    let n = checked_samples(path, w, h, channels, data.len() as u64 / 4).map_err(|_| {
        err(format!(
            "header/data size mismatch: {w}x{h}x{channels} floats need {} bytes, the file has {}",
            w as u128 * h as u128 * channels as u128 * 4,
            data.len()
        ))
    })?;
    let (w, h, c) = (w as usize, h as usize, channels as usize);
    let little = scale < 0.0;
    let mut out = alloc_samples(path, n, 0.0)?;
    let row = w * c;
    for y in 0..h {
        // Stored bottom row first.
        let src = &data[(h - 1 - y) * row * 4..(h - y) * row * 4];
        for (dst, b) in out[y * row..(y + 1) * row]
            .iter_mut()
            .zip(src.chunks_exact(4))
        {
            let b = [b[0], b[1], b[2], b[3]];
            *dst = if little {
                f32::from_le_bytes(b)
            } else {
                f32::from_be_bytes(b)
            };
        }
    }
    Image::new(w, h, c, out).map_err(|e| err(e.to_string()))
}

/// Writes a 1- or 3-channel image as a little-endian PFM.
pub fn write_pfm(path: impl AsRef<Path>, image: &Image) -> Result<()> {
    let path = path.as_ref();
    let magic = match image.channels() {
        1 => "Pf",
        3 => "PF",
        c => {
            return Err(RasterError::Shape(format!(
                "{}: PFM stores 1 or 3 channels, the image has {c}",
                path.display()
            )))
        }
    };
    write_atomically(path, |w| {
        write!(w, "{magic}\n{} {}\n-1.0\n", image.width(), image.height())?;
        for y in (0..image.height()).rev() {
            let bytes: Vec<u8> = image.row(y).iter().flat_map(|v| v.to_le_bytes()).collect();
            w.write_all(&bytes)?;
        }
        Ok(())
    })
}

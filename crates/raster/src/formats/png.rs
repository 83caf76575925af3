//! PNG images: 8- or 16-bit grey, grey+alpha, RGB or RGBA (palettes and low bit depths expanded),
//! values kept in their native units (0–255 or 0–65535).

use std::io::{Cursor, Write};
use std::path::Path;

use png::{BitDepth, ColorType, Decoder, Encoder, Transformations};

use super::support::{alloc_samples, checked_samples, no_panic, write_atomically};
use crate::{Image, RasterError, Result};

/// Bit depth of a written PNG.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PngDepth {
    /// Values rounded and clamped to 0–255.
    Eight,
    /// Values rounded and clamped to 0–65535.
    Sixteen,
}

/// Reads a PNG (first frame of an APNG).
pub fn read_png(path: impl AsRef<Path>) -> Result<Image> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).map_err(|e| RasterError::io(path, e))?;
    decode_png(&bytes, path).map(|(image, _)| image)
}

/// Decodes a PNG held in memory (an HTTP answer, an archive member), first frame of an APNG;
/// `source` names it in errors. Returns the image in its native units and the bit depth.
pub fn decode_png(bytes: &[u8], source: &Path) -> Result<(Image, PngDepth)> {
    let err = |m: String| RasterError::format(source, m);
    no_panic(source, "PNG", || {
        let mut decoder = Decoder::new_with_limits(
            Cursor::new(bytes),
            png::Limits {
                bytes: usize::MAX / 2,
            },
        );
        decoder.set_transformations(Transformations::EXPAND);
        let mut reader = decoder
            .read_info()
            .map_err(|e| err(format!("not a readable PNG: {e}")))?;
        let (color, depth) = reader.output_color_type();
        let (w, h) = reader.info().size();
        let c = color.samples() as u64;
        // Deflate expands at most ~1032:1: a header promising more pixels than that is corrupt.
        let max = (bytes.len() as u64)
            .saturating_mul(1100)
            .saturating_add(1 << 20);
        checked_samples(source, w as u64, h as u64, c, max)?;
        let mut buf = vec![0u8; reader.output_buffer_size()];
        let info = reader
            .next_frame(&mut buf)
            .map_err(|e| err(format!("corrupt PNG data: {e}")))?;
        let bytes = &buf[..info.buffer_size()];
        let n = (w as usize) * (h as usize) * c as usize;
        let mut data = alloc_samples(source, n, 0.0)?;
        let line = info.line_size;
        let row = w as usize * c as usize;
        for y in 0..h as usize {
            let src = &bytes[y * line..];
            let dst = &mut data[y * row..(y + 1) * row];
            match depth {
                BitDepth::Sixteen => {
                    for (d, b) in dst.iter_mut().zip(src.chunks_exact(2)) {
                        *d = u16::from_be_bytes([b[0], b[1]]) as f32;
                    }
                }
                BitDepth::Eight => {
                    for (d, &b) in dst.iter_mut().zip(src) {
                        *d = b as f32;
                    }
                }
                other => return Err(err(format!("unexpected PNG bit depth {other:?}"))),
            }
        }
        let depth = match depth {
            BitDepth::Sixteen => PngDepth::Sixteen,
            _ => PngDepth::Eight,
        };
        let image =
            Image::new(w as usize, h as usize, c as usize, data).map_err(|e| err(e.to_string()))?;
        Ok((image, depth))
    })
}

/// Writes a 1- (grey), 2- (grey+alpha), 3- (RGB) or 4-channel (RGBA) image; values are rounded
/// and clamped to the depth's range, NaN written as 0.
pub fn write_png(path: impl AsRef<Path>, image: &Image, depth: PngDepth) -> Result<()> {
    let path = path.as_ref();
    let bytes = encode_png(image, depth).map_err(|e| match e {
        RasterError::Shape(m) => RasterError::Shape(format!("{}: {m}", path.display())),
        other => other,
    })?;
    write_atomically(path, |file| file.write_all(&bytes))
}

/// The PNG file of [`write_png`], in memory.
pub fn encode_png(image: &Image, depth: PngDepth) -> Result<Vec<u8>> {
    let color = match image.channels() {
        1 => ColorType::Grayscale,
        2 => ColorType::GrayscaleAlpha,
        3 => ColorType::Rgb,
        4 => ColorType::Rgba,
        c => {
            return Err(RasterError::Shape(format!(
                "PNG stores 1 to 4 channels, the image has {c}"
            )))
        }
    };
    let (w, h) = (u32::try_from(image.width()), u32::try_from(image.height()));
    let (Ok(w), Ok(h)) = (w, h) else {
        return Err(RasterError::Shape("image too large for PNG".into()));
    };
    let samples: Vec<u8> = match depth {
        // `as` saturates and maps NaN to 0.
        PngDepth::Eight => image.data().iter().map(|v| v.round() as u8).collect(),
        PngDepth::Sixteen => image
            .data()
            .iter()
            .flat_map(|v| (v.round() as u16).to_be_bytes())
            .collect(),
    };
    let mut out = Vec::new();
    let mut enc = Encoder::new(&mut out, w, h);
    enc.set_color(color);
    enc.set_depth(match depth {
        PngDepth::Eight => BitDepth::Eight,
        PngDepth::Sixteen => BitDepth::Sixteen,
    });
    let encoded = (|| {
        let mut writer = enc.write_header()?;
        writer.write_image_data(&samples)?;
        writer.finish()
    })();
    encoded.map_err(|e| RasterError::Shape(format!("PNG encoding failed: {e}")))?;
    Ok(out)
}

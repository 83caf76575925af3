//! In-memory image codecs for the API (the request carries a PNG, the answer a PNG or JPEG),
//! on top of `raster`'s PNG codec; the answer is brought to RGB 0–255.

use std::path::Path;

use raster::formats::{decode_png, encode_png, PngDepth};
use raster::Image;

/// Largest decoded image accepted (pixels): far above the API's 4K output, far below memory
/// exhaustion by a corrupt header.
const MAX_PIXELS: u64 = 64 * 1024 * 1024;

/// 8-bit RGB PNG of an RGB image with values 0–255 (rounded and clamped, NaN written as 0).
pub(crate) fn encode_rgb_png(image: &Image) -> Result<Vec<u8>, String> {
    if image.channels() != 3 {
        return Err(format!("expected RGB, got {} channel(s)", image.channels()));
    }
    encode_png(image, PngDepth::Eight).map_err(|e| e.to_string())
}

/// Decodes a PNG or JPEG (recognised by its signature, whatever the declared MIME type) into
/// RGB 0–255; grey is replicated, alpha dropped, 16-bit samples keep their high byte.
pub(crate) fn decode_image(bytes: &[u8]) -> Result<Image, String> {
    if bytes.starts_with(b"\x89PNG\r\n\x1a\n") {
        let (mut image, depth) =
            decode_png(bytes, Path::new("the returned PNG")).map_err(|e| e.to_string())?;
        check_size(image.width() as u64, image.height() as u64)?;
        if depth == PngDepth::Sixteen {
            image
                .data_mut()
                .iter_mut()
                .for_each(|v| *v = (*v / 256.0).floor());
        }
        Ok(image.to_rgb())
    } else if bytes.starts_with(&[0xff, 0xd8, 0xff]) {
        decode_jpeg(bytes)
    } else {
        let head: String = bytes.iter().take(8).map(|b| format!("{b:02x}")).collect();
        Err(format!(
            "the returned image is neither PNG nor JPEG (first bytes {head}); only these are supported"
        ))
    }
}

fn decode_jpeg(bytes: &[u8]) -> Result<Image, String> {
    use zune_jpeg::zune_core::colorspace::ColorSpace;
    use zune_jpeg::zune_core::options::DecoderOptions;
    let options = DecoderOptions::default()
        .jpeg_set_out_colorspace(ColorSpace::RGB)
        .set_max_width(1 << 15)
        .set_max_height(1 << 15);
    let mut decoder = zune_jpeg::JpegDecoder::new_with_options(bytes, options);
    let pixels = decoder
        .decode()
        .map_err(|e| format!("corrupt JPEG data: {e:?}"))?;
    let info = decoder.info().ok_or("JPEG without a header")?;
    let (w, h) = (usize::from(info.width), usize::from(info.height));
    check_size(w as u64, h as u64)?;
    if pixels.len() != w * h * 3 {
        return Err(format!(
            "JPEG decoded to {} bytes, expected {w}x{h} RGB",
            pixels.len()
        ));
    }
    let data = pixels.iter().map(|&b| f32::from(b)).collect();
    Image::new(w, h, 3, data).map_err(|e| e.to_string())
}

fn check_size(w: u64, h: u64) -> Result<(), String> {
    if w == 0 || h == 0 || w * h > MAX_PIXELS {
        return Err(format!("implausible image size {w}x{h}"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn png_round_trip_is_exact_on_integers() {
        let img = Image::from_fn(5, 4, |x, y| (x * 40 + y * 3) as f32);
        let rgb = Image::new(
            5,
            4,
            3,
            img.data()
                .iter()
                .flat_map(|&v| [v, 255.0 - v, 7.0])
                .collect(),
        )
        .unwrap();
        let back = decode_image(&encode_rgb_png(&rgb).unwrap()).unwrap();
        assert_eq!(back.data(), rgb.data());
    }

    #[test]
    fn garbage_is_refused_clearly() {
        let err = decode_image(b"<html>oops</html>").unwrap_err();
        assert!(err.contains("neither PNG nor JPEG"), "{err}");
        let err = decode_image(b"\x89PNG\r\n\x1a\nbroken").unwrap_err();
        assert!(err.contains("PNG"), "{err}");
    }
}

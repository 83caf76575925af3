//! In-memory image codecs for the API (the request carries a PNG, the answer a PNG or JPEG) and
//! the resize back to the source size when the model answers at another size.

use raster::Image;

/// Largest decoded image accepted (pixels): far above the API's 4K output, far below memory
/// exhaustion by a corrupt header.
const MAX_PIXELS: u64 = 64 * 1024 * 1024;

/// 8-bit RGB PNG of an RGB image with values 0–255 (rounded and clamped, NaN written as 0).
pub(crate) fn encode_png(image: &Image) -> Result<Vec<u8>, String> {
    if image.channels() != 3 {
        return Err(format!("expected RGB, got {} channel(s)", image.channels()));
    }
    let (w, h) = (
        u32::try_from(image.width()).map_err(|_| "image too wide")?,
        u32::try_from(image.height()).map_err(|_| "image too tall")?,
    );
    // `as` saturates and maps NaN to 0.
    let bytes: Vec<u8> = image.data().iter().map(|v| v.round() as u8).collect();
    let mut out = Vec::new();
    let mut enc = png::Encoder::new(&mut out, w, h);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    let mut writer = enc.write_header().map_err(|e| e.to_string())?;
    writer.write_image_data(&bytes).map_err(|e| e.to_string())?;
    writer.finish().map_err(|e| e.to_string())?;
    Ok(out)
}

/// Decodes a PNG or JPEG (recognised by its signature, whatever the declared MIME type) into
/// RGB 0–255; grey is replicated, alpha dropped.
pub(crate) fn decode_image(bytes: &[u8]) -> Result<Image, String> {
    if bytes.starts_with(b"\x89PNG\r\n\x1a\n") {
        decode_png(bytes)
    } else if bytes.starts_with(&[0xff, 0xd8, 0xff]) {
        decode_jpeg(bytes)
    } else {
        let head: String = bytes.iter().take(8).map(|b| format!("{b:02x}")).collect();
        Err(format!(
            "the returned image is neither PNG nor JPEG (first bytes {head}); only these are supported"
        ))
    }
}

fn decode_png(bytes: &[u8]) -> Result<Image, String> {
    let mut decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    decoder.set_transformations(png::Transformations::EXPAND | png::Transformations::STRIP_16);
    let mut reader = decoder
        .read_info()
        .map_err(|e| format!("not a readable PNG: {e}"))?;
    let (w, h) = reader.info().size();
    check_size(w as u64, h as u64)?;
    let mut buf = vec![0u8; reader.output_buffer_size()];
    let info = reader
        .next_frame(&mut buf)
        .map_err(|e| format!("corrupt PNG data: {e}"))?;
    let channels = info.color_type.samples();
    let (w, h) = (w as usize, h as usize);
    let mut data = Vec::with_capacity(w * h * 3);
    for y in 0..h {
        let row = &buf[y * info.line_size..y * info.line_size + w * channels];
        for px in row.chunks_exact(channels) {
            push_rgb(&mut data, px);
        }
    }
    Image::new(w, h, 3, data).map_err(|e| e.to_string())
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

fn push_rgb(data: &mut Vec<f32>, px: &[u8]) {
    match px.len() {
        1 | 2 => data.extend([f32::from(px[0]); 3]),
        _ => data.extend(px[..3].iter().map(|&b| f32::from(b))),
    }
}

/// Separable Lanczos-3 resampling (the filter the release uses to bring the model's output back to
/// the input size), antialiased when shrinking: the kernel is widened by the scale factor.
pub(crate) fn resize_lanczos3(image: &Image, width: usize, height: usize) -> Image {
    let c = image.channels();
    let (w0, h0) = image.size();
    let horizontal = resize_axis(image.data(), w0, h0, c, width, true);
    let data = resize_axis(&horizontal, width, h0, c, height, false);
    Image::new(width, height, c, data).expect("buffer sized for the output")
}

/// Resizes along x (`along_x`) or y, from `(w, h)` to `n` samples on that axis.
fn resize_axis(src: &[f32], w: usize, h: usize, c: usize, n: usize, along_x: bool) -> Vec<f32> {
    let len = if along_x { w } else { h };
    let weights = lanczos_weights(len, n);
    let (ow, oh) = if along_x { (n, h) } else { (w, n) };
    let mut out = vec![0f32; ow * oh * c];
    for y in 0..oh {
        for x in 0..ow {
            let (first, taps) = &weights[if along_x { x } else { y }];
            for k in 0..c {
                let mut acc = 0f32;
                for (t, &wt) in taps.iter().enumerate() {
                    let j = *first + t;
                    let s = if along_x {
                        src[(y * w + j) * c + k]
                    } else {
                        src[(j * w + x) * c + k]
                    };
                    acc += wt * s;
                }
                out[(y * ow + x) * c + k] = acc;
            }
        }
    }
    out
}

/// For each output sample: first input index and normalised Lanczos-3 weights.
fn lanczos_weights(len: usize, n: usize) -> Vec<(usize, Vec<f32>)> {
    let scale = len as f64 / n as f64;
    let support = 3.0 * scale.max(1.0);
    let stretch = scale.max(1.0);
    (0..n)
        .map(|i| {
            let centre = (i as f64 + 0.5) * scale;
            let lo = ((centre - support).floor().max(0.0)) as usize;
            let hi = ((centre + support).ceil() as usize).min(len);
            let mut taps: Vec<f64> = (lo..hi)
                .map(|j| lanczos3((j as f64 + 0.5 - centre) / stretch))
                .collect();
            let sum: f64 = taps.iter().sum();
            if sum.abs() > 1e-12 {
                taps.iter_mut().for_each(|t| *t /= sum);
            }
            (lo, taps.into_iter().map(|t| t as f32).collect())
        })
        .collect()
}

fn lanczos3(x: f64) -> f64 {
    if x.abs() < 1e-9 {
        1.0
    } else if x.abs() >= 3.0 {
        0.0
    } else {
        let px = std::f64::consts::PI * x;
        3.0 * px.sin() * (px / 3.0).sin() / (px * px)
    }
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
        let back = decode_image(&encode_png(&rgb).unwrap()).unwrap();
        assert_eq!(back.data(), rgb.data());
    }

    #[test]
    fn garbage_is_refused_clearly() {
        let err = decode_image(b"<html>oops</html>").unwrap_err();
        assert!(err.contains("neither PNG nor JPEG"), "{err}");
        let err = decode_image(b"\x89PNG\r\n\x1a\nbroken").unwrap_err();
        assert!(err.contains("PNG"), "{err}");
    }

    #[test]
    fn resize_keeps_constants_and_identity() {
        let flat = Image::filled(10, 8, 3, 77.0);
        let r = resize_lanczos3(&flat, 23, 5);
        assert_eq!(r.size(), (23, 5));
        assert!(r.data().iter().all(|v| (v - 77.0).abs() < 1e-3));
        let ramp = Image::from_fn(9, 7, |x, y| (x * 10 + y) as f32);
        let same = resize_lanczos3(&ramp, 9, 7);
        for (a, b) in same.data().iter().zip(ramp.data()) {
            assert!((a - b).abs() < 1e-3);
        }
    }
}

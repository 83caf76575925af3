//! Input preparation of the reference mask scripts: PIL `convert("RGB")`, PIL bilinear resize of
//! the 8-bit image to a fixed square (1000²), `/255`, ImageNet mean/std, HWC → 1×3×H×W.

use burn::tensor::{Device, Tensor, TensorData};
use raster::resize::resize_pil_bilinear_u8;
use raster::Image;

use super::error::SegformerError;

/// ImageNet channel means (RGB).
pub const IMAGENET_MEAN: [f32; 3] = [0.485, 0.456, 0.406];
/// ImageNet channel standard deviations (RGB).
pub const IMAGENET_STD: [f32; 3] = [0.229, 0.224, 0.225];

/// The image as 3-channel 8-bit RGB, as PIL's `convert("RGB")` of the file would give: grey (1
/// channel) and grey+alpha (2) are replicated, RGB is kept, a 4th (alpha) channel is dropped.
/// Samples must be integers in 0..=255 (8-bit files); anything else is an error rather than a
/// silent rescale.
pub fn to_rgb_u8(image: &Image) -> Result<Image, SegformerError> {
    if image.width() == 0 || image.height() == 0 {
        return Err(SegformerError::Input("the image is empty".into()));
    }
    if let Some(bad) = image
        .data()
        .iter()
        .find(|v| !(v.fract() == 0.0 && (0.0..=255.0).contains(*v)))
    {
        return Err(SegformerError::Input(format!(
            "sample {bad} is not an 8-bit value: the segmentation network takes 8-bit RGB images \
             (integers 0..=255); convert the image first"
        )));
    }
    Ok(image.to_rgb())
}

/// Network input 1×3×H×W from an 8-bit RGB image (no resize): `((x / 255) − mean) / std` in f32.
pub fn pixel_values(rgb_u8: &Image, device: &Device) -> Result<Tensor<4>, SegformerError> {
    if rgb_u8.channels() != 3 {
        return Err(SegformerError::Input(format!(
            "pixel_values needs an RGB image, got {} channels",
            rgb_u8.channels()
        )));
    }
    let (w, h) = rgb_u8.size();
    let mut chw = vec![0f32; 3 * w * h];
    for (i, px) in rgb_u8.data().chunks_exact(3).enumerate() {
        for c in 0..3 {
            chw[c * w * h + i] = (px[c] / 255.0 - IMAGENET_MEAN[c]) / IMAGENET_STD[c];
        }
    }
    Ok(Tensor::from_data(
        TensorData::new(chw, [1, 3, h, w]),
        device,
    ))
}

/// The whole pre-processing: RGB conversion, PIL bilinear resize to `width`×`height` (1000×1000
/// in the release), normalisation.
pub fn preprocess(
    image: &Image,
    width: usize,
    height: usize,
    device: &Device,
) -> Result<Tensor<4>, SegformerError> {
    let rgb = to_rgb_u8(image)?;
    let resized = resize_pil_bilinear_u8(&rgb, width, height)?;
    pixel_values(&resized, device)
}

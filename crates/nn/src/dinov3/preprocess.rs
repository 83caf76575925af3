//! The similarity score's image pre-processing: masking, uint8 truncation and the HF
//! `DINOv3ViTImageProcessorFast` (rescale → antialiased resize → normalise).

use raster::resize::resize_antialias_bilinear;
use raster::{Image, Mask};

/// Per-channel mean and std applied after rescaling to [0, 1].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Normalization {
    /// RGB mean.
    pub mean: [f32; 3],
    /// RGB standard deviation.
    pub std: [f32; 3],
}

impl Normalization {
    /// ImageNet (0.485, 0.456, 0.406) / (0.229, 0.224, 0.225): the processor class default, and
    /// per a public comment in facebookresearch/dinov3 issue #9 also what the hub's
    /// `preprocessor_config.json` of the SAT-493M model holds. **Open point**: not confirmed
    /// from the real file (design note B.2.3).
    pub const IMAGENET: Self = Self {
        mean: [0.485, 0.456, 0.406],
        std: [0.229, 0.224, 0.225],
    };

    /// The official transform of the SAT-493M weights in the facebookresearch repository,
    /// (0.430, 0.411, 0.296) / (0.213, 0.156, 0.143); not what the HF path uses by default.
    pub const SAT493M: Self = Self {
        mean: [0.430, 0.411, 0.296],
        std: [0.213, 0.156, 0.143],
    };

    /// `imagenet` or `sat493m`.
    pub fn by_name(name: &str) -> Option<Self> {
        match name {
            "imagenet" => Some(Self::IMAGENET),
            "sat493m" => Some(Self::SAT493M),
            _ => None,
        }
    }
}

/// Processor settings: output size (square 224 upstream, aspect ratio not kept) and normalisation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Dinov3Preprocess {
    /// Output width, pixels.
    pub width: usize,
    /// Output height, pixels.
    pub height: usize,
    /// Mean/std.
    pub normalization: Normalization,
}

impl Default for Dinov3Preprocess {
    /// 224×224, ImageNet mean/std (the upstream HF default).
    fn default() -> Self {
        Self {
            width: 224,
            height: 224,
            normalization: Normalization::IMAGENET,
        }
    }
}

/// The RGB channels of an image: 3 channels as they are, 1 channel repeated, more than 3 cut
/// to the first 3 (as the upstream loader does); 2 channels are an error.
fn rgb(image: &Image, what: &str) -> Result<Image, String> {
    match image.channels() {
        3 => Ok(image.clone()),
        1 => {
            let data = image.data().iter().flat_map(|&v| [v, v, v]).collect();
            Image::new(image.width(), image.height(), 3, data).map_err(|e| e.to_string())
        }
        c if c > 3 => {
            let data = image
                .data()
                .chunks_exact(c)
                .flat_map(|p| [p[0], p[1], p[2]])
                .collect();
            Image::new(image.width(), image.height(), 3, data).map_err(|e| e.to_string())
        }
        c => Err(format!(
            "{what}: {c} channels; an RGB (3), grey (1) or RGB+extra (4+) image is expected"
        )),
    }
}

/// Upstream's `img[~mask] = 0; img.astype(np.uint8)` on an RGB image of 0–255 floats: pixels
/// outside `valid` become 0, the others are truncated toward zero (254.9999 → 254). Values
/// outside 0..=255 are clamped and NaN becomes 0 (numpy's cast of those is undefined; real
/// inputs are 0–255). `valid = None` keeps every pixel.
pub fn mask_to_u8(image: &Image, valid: Option<&Mask>, what: &str) -> Result<Image, String> {
    let mut out = rgb(image, what)?;
    if let Some(mask) = valid {
        if mask.size() != image.size() {
            return Err(format!(
                "{what}: mask is {}x{}, image is {}x{}",
                mask.width(),
                mask.height(),
                image.width(),
                image.height()
            ));
        }
    }
    for (i, px) in out.data_mut().chunks_exact_mut(3).enumerate() {
        let keep = valid.is_none_or(|m| m.data()[i]);
        for v in px {
            *v = if keep && v.is_finite() {
                v.clamp(0.0, 255.0).trunc()
            } else {
                0.0
            };
        }
    }
    Ok(out)
}

impl Dinov3Preprocess {
    /// Checks the settings.
    pub fn validate(&self) -> Result<(), String> {
        if self.width == 0 || self.height == 0 {
            return Err(format!(
                "DINOv3 input size {}x{} must be positive",
                self.width, self.height
            ));
        }
        if self
            .normalization
            .std
            .iter()
            .any(|&s| s.is_nan() || s <= 0.0)
        {
            return Err(format!(
                "DINOv3 normalisation std {:?} must be positive",
                self.normalization.std
            ));
        }
        Ok(())
    }

    /// The processor on one uint8-valued RGB image (output of [`mask_to_u8`]): `x · f32(1/255)`
    /// (a multiplication, as HF does), antialiased bilinear resize to `width × height`, then
    /// `(x − mean)/std` in f32. Returns the CHW planes (3·height·width values).
    pub fn pixel_values(&self, image_u8: &Image) -> Result<Vec<f32>, String> {
        self.validate()?;
        if image_u8.channels() != 3 {
            return Err(format!(
                "DINOv3 processor expects 3 channels, got {}",
                image_u8.channels()
            ));
        }
        let inv255 = (1.0f64 / 255.0) as f32;
        let scaled = Image::new(
            image_u8.width(),
            image_u8.height(),
            3,
            image_u8.data().iter().map(|&v| v * inv255).collect(),
        )
        .map_err(|e| e.to_string())?;
        let resized = resize_antialias_bilinear(&scaled, self.width, self.height)
            .map_err(|e| e.to_string())?;
        let n = self.width * self.height;
        let mut chw = vec![0f32; 3 * n];
        let Normalization { mean, std } = self.normalization;
        for (i, px) in resized.data().chunks_exact(3).enumerate() {
            for (c, ((&v, &m), &s)) in px.iter().zip(&mean).zip(&std).enumerate() {
                chw[c * n + i] = (v - m) / s;
            }
        }
        Ok(chw)
    }
}

use crate::{RasterError, Result};

/// A raster of `f32` samples, row-major with channels interleaved: the `(H, W, C)` layout of the
/// public release's `.iio` files. Invalid samples (a disparity that could not be matched, a cell
/// without data) are NaN.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    width: usize,
    height: usize,
    channels: usize,
    data: Vec<f32>,
}

impl Image {
    /// Wraps `data` laid out as `(height, width, channels)`.
    pub fn new(width: usize, height: usize, channels: usize, data: Vec<f32>) -> Result<Self> {
        if channels == 0 {
            return Err(RasterError::Shape(
                "an image needs at least one channel".into(),
            ));
        }
        let expected = width
            .checked_mul(height)
            .and_then(|n| n.checked_mul(channels))
            .ok_or_else(|| {
                RasterError::Shape(format!("{width}x{height}x{channels} is too large"))
            })?;
        if data.len() != expected {
            return Err(RasterError::Shape(format!(
                "{width}x{height}x{channels} image needs {expected} samples, got {}",
                data.len()
            )));
        }
        Ok(Self {
            width,
            height,
            channels,
            data,
        })
    }

    /// An image with every sample equal to `value`.
    pub fn filled(width: usize, height: usize, channels: usize, value: f32) -> Self {
        assert!(channels > 0, "an image needs at least one channel");
        Self {
            width,
            height,
            channels,
            data: vec![value; width * height * channels],
        }
    }

    /// A single-channel image computed pixel by pixel.
    pub fn from_fn(width: usize, height: usize, f: impl Fn(usize, usize) -> f32) -> Self {
        Self {
            width,
            height,
            channels: 1,
            data: row_major(width, height, f),
        }
    }

    pub fn width(&self) -> usize {
        self.width
    }

    pub fn height(&self) -> usize {
        self.height
    }

    pub fn channels(&self) -> usize {
        self.channels
    }

    /// `(width, height)`.
    pub fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// All samples, `(H, W, C)` order.
    pub fn data(&self) -> &[f32] {
        &self.data
    }

    pub fn data_mut(&mut self) -> &mut [f32] {
        &mut self.data
    }

    pub fn into_data(self) -> Vec<f32> {
        self.data
    }

    /// Sample `c` of pixel `(x, y)`.
    #[inline]
    pub fn get(&self, x: usize, y: usize, c: usize) -> f32 {
        self.data[(y * self.width + x) * self.channels + c]
    }

    #[inline]
    pub fn set(&mut self, x: usize, y: usize, c: usize, value: f32) {
        self.data[(y * self.width + x) * self.channels + c] = value;
    }

    /// The `channels` samples of pixel `(x, y)`.
    #[inline]
    pub fn pixel(&self, x: usize, y: usize) -> &[f32] {
        let i = (y * self.width + x) * self.channels;
        &self.data[i..i + self.channels]
    }

    /// Row `y`, all channels.
    #[inline]
    pub fn row(&self, y: usize) -> &[f32] {
        let n = self.width * self.channels;
        &self.data[y * n..(y + 1) * n]
    }

    /// An image of this one's size holding `data`, `channels` values per pixel (what a
    /// per-pixel conversion of this image produced).
    fn converted(&self, channels: usize, data: Vec<f32>) -> Image {
        debug_assert_eq!(data.len(), self.width * self.height * channels);
        Image {
            width: self.width,
            height: self.height,
            channels,
            data,
        }
    }

    /// One channel as a single-channel image.
    pub fn channel(&self, c: usize) -> Image {
        assert!(c < self.channels, "channel {c} out of {}", self.channels);
        let data = self
            .data
            .iter()
            .skip(c)
            .step_by(self.channels)
            .copied()
            .collect();
        self.converted(1, data)
    }

    /// The image as RGB, the way the reference scripts read rasters: grey (± alpha) repeated,
    /// channels past the third (alpha, near infrared) dropped.
    pub fn to_rgb(&self) -> Image {
        if self.channels == 3 {
            return self.clone();
        }
        let data = self
            .data
            .chunks_exact(self.channels)
            .flat_map(|p| {
                if p.len() < 3 {
                    [p[0]; 3]
                } else {
                    [p[0], p[1], p[2]]
                }
            })
            .collect();
        self.converted(3, data)
    }

    /// A grey-level version: the mean of the first three channels of a colour image (the first
    /// channel otherwise; a 4th alpha channel is ignored).
    pub fn to_gray(&self) -> Image {
        match self.channels {
            1 | 2 => self.channel(0),
            c => {
                let data = self
                    .data
                    .chunks_exact(c)
                    .map(|p| (p[0] + p[1] + p[2]) / 3.0)
                    .collect();
                self.converted(1, data)
            }
        }
    }

    /// Fails unless `other` has the same width and height, with a message naming `what`.
    pub fn check_same_size(&self, other: &Image, what: &str) -> Result<()> {
        if self.size() != other.size() {
            return Err(RasterError::Shape(format!(
                "{what}: sizes differ ({}x{} vs {}x{})",
                self.width, self.height, other.width, other.height
            )));
        }
        Ok(())
    }

    /// Fails unless `mask` covers exactly this image, with a message naming `what`.
    pub fn check_mask(&self, mask: &Mask, what: &str) -> Result<()> {
        if self.size() != mask.size() {
            return Err(RasterError::Shape(format!(
                "{what}: image is {}x{}, mask is {}x{}",
                self.width,
                self.height,
                mask.width(),
                mask.height()
            )));
        }
        Ok(())
    }

    /// The (min, max) of the finite samples, or `None` when there are none.
    pub fn finite_range(&self) -> Option<(f32, f32)> {
        self.data
            .iter()
            .filter(|v| v.is_finite())
            .fold(None, |acc, &v| match acc {
                None => Some((v, v)),
                Some((lo, hi)) => Some((lo.min(v), hi.max(v))),
            })
    }
}

/// A boolean raster (validity, occlusion, class masks), row-major.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Mask {
    width: usize,
    height: usize,
    data: Vec<bool>,
}

impl Mask {
    pub fn new(width: usize, height: usize, data: Vec<bool>) -> Result<Self> {
        if data.len() != width * height {
            return Err(RasterError::Shape(format!(
                "{width}x{height} mask needs {} values, got {}",
                width * height,
                data.len()
            )));
        }
        Ok(Self {
            width,
            height,
            data,
        })
    }

    pub fn filled(width: usize, height: usize, value: bool) -> Self {
        Self {
            width,
            height,
            data: vec![value; width * height],
        }
    }

    pub fn from_fn(width: usize, height: usize, f: impl Fn(usize, usize) -> bool) -> Self {
        Self {
            width,
            height,
            data: row_major(width, height, f),
        }
    }

    pub fn width(&self) -> usize {
        self.width
    }

    pub fn height(&self) -> usize {
        self.height
    }

    pub fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    pub fn data(&self) -> &[bool] {
        &self.data
    }

    pub fn data_mut(&mut self) -> &mut [bool] {
        &mut self.data
    }

    #[inline]
    pub fn get(&self, x: usize, y: usize) -> bool {
        self.data[y * self.width + x]
    }

    #[inline]
    pub fn set(&mut self, x: usize, y: usize, value: bool) {
        self.data[y * self.width + x] = value;
    }

    /// Number of true pixels.
    pub fn count(&self) -> usize {
        self.data.iter().filter(|&&v| v).count()
    }

    /// Pixel-wise AND; the sizes must match.
    pub fn and(&self, other: &Mask) -> Result<Mask> {
        self.zip_with(other, |a, b| a && b)
    }

    /// Pixel-wise `self AND NOT other`; the sizes must match.
    pub fn and_not(&self, other: &Mask) -> Result<Mask> {
        self.zip_with(other, |a, b| a && !b)
    }

    fn zip_with(&self, other: &Mask, f: impl Fn(bool, bool) -> bool) -> Result<Mask> {
        if self.size() != other.size() {
            return Err(RasterError::Shape(format!(
                "masks differ in size ({}x{} vs {}x{})",
                self.width, self.height, other.width, other.height
            )));
        }
        let data = self
            .data
            .iter()
            .zip(&other.data)
            .map(|(&a, &b)| f(a, b))
            .collect();
        Ok(Mask {
            width: self.width,
            height: self.height,
            data,
        })
    }

    /// 1.0 where true, 0.0 where false: for writing masks as rasters.
    pub fn to_image(&self) -> Image {
        let data = self
            .data
            .iter()
            .map(|&v| if v { 1.0 } else { 0.0 })
            .collect();
        Image::new(self.width, self.height, 1, data).expect("sizes match")
    }

    /// True where the first channel of `image` is finite and non-zero.
    pub fn from_image(image: &Image) -> Mask {
        let data = (0..image.width() * image.height())
            .map(|i| {
                let v = image.data()[i * image.channels()];
                v.is_finite() && v != 0.0
            })
            .collect();
        Mask {
            width: image.width(),
            height: image.height(),
            data,
        }
    }
}

/// `f(x, y)` of every pixel, row by row.
fn row_major<T>(width: usize, height: usize, f: impl Fn(usize, usize) -> T) -> Vec<T> {
    (0..height)
        .flat_map(|y| (0..width).map(move |x| (x, y)))
        .map(|(x, y)| f(x, y))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn new_rejects_wrong_length() {
        assert!(Image::new(2, 2, 3, vec![0.0; 11]).is_err());
        assert!(Image::new(2, 2, 0, vec![]).is_err());
        assert!(Mask::new(3, 1, vec![true; 2]).is_err());
    }

    #[test]
    fn layout_is_hwc() {
        let img = Image::new(2, 1, 3, vec![1., 2., 3., 4., 5., 6.]).unwrap();
        assert_eq!(img.pixel(1, 0), &[4., 5., 6.]);
        assert_eq!(img.channel(2).data(), &[3., 6.]);
        assert_eq!(img.to_gray().data(), &[2., 5.]);
    }

    #[test]
    fn finite_range_ignores_nan() {
        let img = Image::new(3, 1, 1, vec![f32::NAN, -1.0, 4.0]).unwrap();
        assert_eq!(img.finite_range(), Some((-1.0, 4.0)));
        assert_eq!(Image::filled(2, 2, 1, f32::NAN).finite_range(), None);
    }

    #[test]
    fn mask_logic() {
        let a = Mask::new(2, 1, vec![true, true]).unwrap();
        let b = Mask::new(2, 1, vec![true, false]).unwrap();
        assert_eq!(a.and(&b).unwrap().data(), &[true, false]);
        assert_eq!(a.and_not(&b).unwrap().data(), &[false, true]);
        assert!(a.and(&Mask::filled(1, 1, true)).is_err());
    }

    #[test]
    fn rgb_conversion() {
        let g = Image::new(2, 1, 1, vec![1.0, 2.0]).unwrap();
        assert_eq!(g.to_rgb().data(), &[1.0, 1.0, 1.0, 2.0, 2.0, 2.0]);
        let ga = Image::new(1, 1, 2, vec![7.0, 255.0]).unwrap();
        assert_eq!(ga.to_rgb().data(), &[7.0, 7.0, 7.0]);
        let rgba = Image::new(1, 1, 4, vec![1.0, 2.0, 3.0, 4.0]).unwrap();
        assert_eq!(rgba.to_rgb().data(), &[1.0, 2.0, 3.0]);
        assert_eq!(rgba.to_rgb().channels(), 3);
    }
}

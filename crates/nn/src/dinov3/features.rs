//! [`Dinov3Features`]: a loaded DINOv3 ViT with its pre-processing, giving global image
//! features (`pooler_output`) and the curation similarity score.

use std::path::{Path, PathBuf};

use burn::tensor::{Device, Tensor, TensorData};
use raster::{Image, Mask};

use super::config::{Dinov3Config, Dinov3ConfigError};
use super::load::load_dinov3;
use super::model::Dinov3Vit;
use super::preprocess::{mask_to_u8, Dinov3Preprocess};
use crate::weights::{LoadReport, WeightsError};

/// Errors of loading the DINOv3 model or scoring images.
#[derive(Debug, thiserror::Error)]
pub enum Dinov3Error {
    /// The configuration cannot build a model.
    #[error(transparent)]
    Config(#[from] Dinov3ConfigError),
    /// The weights file is missing, unreadable, or does not fit the configuration (the report
    /// lists missing, mis-shaped and unexpected keys in HF names).
    #[error("{0}\n(DINOv3 weights: the HF `model.safetensors` of e.g. facebook/dinov3-vitl16-pretrain-sat493m, with the matching configuration: vitl16, vitb16, vits16, or Dinov3Config::from_checkpoint)")]
    Weights(#[from] WeightsError),
    /// Unusable input images or settings.
    #[error("{0}")]
    Input(String),
}

/// `F.cosine_similarity(a, b, eps=1e-8)` of torch ≥ 1.12: each vector divided by
/// max(‖v‖₂, 1e-8), then the dot product. Norms and the dot product are accumulated in f64.
pub fn cosine_similarity(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len(), "cosine_similarity: lengths differ");
    const EPS: f64 = 1e-8;
    let norm = |v: &[f32]| {
        (v.iter().map(|&x| x as f64 * x as f64).sum::<f64>())
            .sqrt()
            .max(EPS) as f32
    };
    let (na, nb) = (norm(a), norm(b));
    a.iter()
        .zip(b)
        .map(|(&x, &y)| (x / na) as f64 * (y / nb) as f64)
        .sum::<f64>() as f32
}

/// A DINOv3 ViT with its weights and processor settings.
///
/// ```no_run
/// # use nn::dinov3::{Dinov3Config, Dinov3Features};
/// # use burn::tensor::Device;
/// # fn demo(left: &raster::Image, left_hat: &raster::Image, valid: &raster::Mask) -> Result<(), nn::dinov3::Dinov3Error> {
/// let path = std::path::Path::new("dinov3-vitl16-pretrain-sat493m/model.safetensors");
/// let dino = Dinov3Features::from_file(path, Dinov3Config::vitl16(), Device::flex())?;
/// let score = dino.similarity(left, left_hat, valid)?;
/// # Ok(()) }
/// ```
pub struct Dinov3Features {
    model: Dinov3Vit,
    config: Dinov3Config,
    preprocess: Dinov3Preprocess,
    device: Device,
    weights: PathBuf,
    report: LoadReport,
}

impl Dinov3Features {
    /// Builds the model for `config` on `device` and loads the HF checkpoint at `path`
    /// strictly; pre-processing starts at the upstream default ([`Dinov3Preprocess::default`]).
    pub fn from_file(
        path: &Path,
        config: Dinov3Config,
        device: Device,
    ) -> Result<Self, Dinov3Error> {
        config.validate()?;
        if !path.is_file() {
            return Err(WeightsError::Io {
                file: path.to_path_buf(),
                source: std::io::Error::new(std::io::ErrorKind::NotFound, "no such file"),
            }
            .into());
        }
        let mut model = Dinov3Vit::new(&config, &device);
        let report = load_dinov3(&mut model, path)?;
        Ok(Self {
            model,
            config,
            preprocess: Dinov3Preprocess::default(),
            device,
            weights: path.to_path_buf(),
            report,
        })
    }

    /// The same with other processor settings (size, mean/std).
    pub fn with_preprocess(mut self, preprocess: Dinov3Preprocess) -> Result<Self, Dinov3Error> {
        preprocess.validate().map_err(Dinov3Error::Input)?;
        self.preprocess = preprocess;
        Ok(self)
    }

    /// The network.
    pub fn model(&self) -> &Dinov3Vit {
        &self.model
    }

    /// Its configuration.
    pub fn config(&self) -> &Dinov3Config {
        &self.config
    }

    /// The processor settings.
    pub fn preprocess(&self) -> &Dinov3Preprocess {
        &self.preprocess
    }

    /// The weights file and what loading it did.
    pub fn weights(&self) -> (&Path, &LoadReport) {
        (&self.weights, &self.report)
    }

    /// `pooler_output` (the CLS token after the final LayerNorm) of a batch of processed images
    /// given as CHW planes (see [`Dinov3Preprocess::pixel_values`]).
    pub fn features_of_pixel_values(&self, chw: &[Vec<f32>]) -> Vec<Vec<f32>> {
        let (w, h) = (self.preprocess.width, self.preprocess.height);
        let b = chw.len();
        let data: Vec<f32> = chw.iter().flatten().copied().collect();
        let x = Tensor::<4>::from_data(TensorData::new(data, [b, 3, h, w]), &self.device);
        let pooled = Dinov3Vit::pooler(self.model.forward(x));
        let d = pooled.dims()[1];
        let flat: Vec<f32> = pooled
            .into_data()
            .try_into_vec_as::<f32>()
            .expect("f32 features");
        flat.chunks_exact(d).map(<[f32]>::to_vec).collect()
    }

    fn check_size(&self, image: &Image, what: &str) -> Result<(), Dinov3Error> {
        let p = self.config.patch_size;
        if self.preprocess.width < p || self.preprocess.height < p {
            return Err(Dinov3Error::Input(format!(
                "DINOv3 input size {}x{} is smaller than one {p}-px patch",
                self.preprocess.width, self.preprocess.height
            )));
        }
        if image.width() == 0 || image.height() == 0 {
            return Err(Dinov3Error::Input(format!("{what} is empty")));
        }
        Ok(())
    }

    /// Global features of one RGB image of 0–255 floats (truncated to uint8 first, as the
    /// score does): the D-vector `pooler_output`.
    pub fn features(&self, image: &Image) -> Result<Vec<f32>, Dinov3Error> {
        self.check_size(image, "image")?;
        let u8_image = mask_to_u8(image, None, "image").map_err(Dinov3Error::Input)?;
        let chw = self
            .preprocess
            .pixel_values(&u8_image)
            .map_err(Dinov3Error::Input)?;
        Ok(self.features_of_pixel_values(&[chw]).remove(0))
    }

    /// The SeasonStereo DINOv3 similarity of a left image and the right image warped into the
    /// left view (`left_hat`), both RGB 0–255 floats of the same size: pixels outside `valid`
    /// (the warp's final mask) are zeroed in both, both are truncated to uint8, processed as one
    /// batch [left, left_hat], and the score is the cosine similarity of their `pooler_output`.
    /// An empty `valid` mask is an error (upstream would compare two black images and report 1).
    pub fn similarity(
        &self,
        left: &Image,
        left_hat: &Image,
        valid: &Mask,
    ) -> Result<f32, Dinov3Error> {
        self.check_size(left, "left image")?;
        if left.size() != left_hat.size() {
            return Err(Dinov3Error::Input(format!(
                "DINOv3 similarity: left is {}x{}, left_hat is {}x{}",
                left.width(),
                left.height(),
                left_hat.width(),
                left_hat.height()
            )));
        }
        if valid.count() == 0 {
            return Err(Dinov3Error::Input(
                "DINOv3 similarity: the valid mask is empty (no pixel where the warp is defined)"
                    .into(),
            ));
        }
        let mut planes = Vec::with_capacity(2);
        for (image, what) in [(left, "left image"), (left_hat, "left_hat image")] {
            let u8_image = mask_to_u8(image, Some(valid), what).map_err(Dinov3Error::Input)?;
            planes.push(
                self.preprocess
                    .pixel_values(&u8_image)
                    .map_err(Dinov3Error::Input)?,
            );
        }
        let f = self.features_of_pixel_values(&planes);
        Ok(cosine_similarity(&f[0], &f[1]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cosine_of_known_vectors() {
        assert!((cosine_similarity(&[1.0, 0.0], &[0.0, 2.0])).abs() < 1e-7);
        assert!((cosine_similarity(&[1.0, 2.0], &[2.0, 4.0]) - 1.0).abs() < 1e-6);
        assert!((cosine_similarity(&[3.0, 4.0], &[4.0, 3.0]) - 24.0 / 25.0).abs() < 1e-6);
        // A zero vector gives 0, not NaN (the norm is clamped to 1e-8).
        assert_eq!(cosine_similarity(&[0.0, 0.0], &[1.0, 1.0]), 0.0);
    }
}

//! Seasonal variants that keep the geometry (paper Sec. 3.2).
//!
//! Every real image of a curated synchronic pair gets four synthetic variants (summer, autumn,
//! winter, spring) whose appearance changes while every edge stays where it was, so that the
//! teacher disparity of the real pair still supervises them. This crate holds:
//! - [`BuiltinSeasons`], an offline, deterministic appearance model built only from per-pixel
//!   colour operations and smooth low-frequency fields, so it cannot move an edge;
//! - [`api::GeminiGenerator`], a client of the generative image-editing API the paper used
//!   (Gemini `generateContent`), with retries, a concurrency limit and an on-disk cache;
//! - [`prompts::Prompts`], the user-editable geometry-preserving prompts (TOML);
//! - [`fidelity`], the check that a generated image still registers to its source at zero
//!   disparity, edge for edge, which rejects hallucinated or warped generations.

mod error;
mod season;

pub mod api;
pub mod builtin;
pub mod fidelity;
pub mod prompts;

pub use builtin::BuiltinSeasons;
pub use error::SynthError;
pub use season::Season;

use raster::Image;

/// A real image to vary: its identifier (the file stem, used for seeding and caching), its RGB
/// pixels (0–255, NaN = invalid) and optionally its class map.
#[derive(Clone, Copy, Debug)]
pub struct SourceImage<'a> {
    pub id: &'a str,
    pub image: &'a Image,
    /// One channel of OpenEarthMap class ids (1 bareland, 2 rangeland, 3 developed, 4 road,
    /// 5 tree, 6 water, 7 agriculture, 8 building, 0 background), same size as `image`.
    pub classes: Option<&'a Image>,
}

impl<'a> SourceImage<'a> {
    /// A source without a class map.
    pub fn new(id: &'a str, image: &'a Image) -> Self {
        Self {
            id,
            image,
            classes: None,
        }
    }

    /// The same source with a class map.
    pub fn with_classes(self, classes: &'a Image) -> Self {
        Self {
            classes: Some(classes),
            ..self
        }
    }

    /// Fails with a message naming the source unless the image is non-empty RGB and the class
    /// map (if any) is one channel of the same size.
    pub fn validate(&self) -> Result<(), SynthError> {
        let (w, h) = self.image.size();
        if w == 0 || h == 0 {
            return Err(SynthError::Input(format!("{}: empty image", self.id)));
        }
        if self.image.channels() != 3 {
            return Err(SynthError::Input(format!(
                "{}: seasonal variants need an RGB image, this one has {} channel(s)",
                self.id,
                self.image.channels()
            )));
        }
        if let Some(classes) = self.classes {
            if classes.channels() != 1 || classes.size() != (w, h) {
                return Err(SynthError::Input(format!(
                    "{}: the class map must be one channel of {w}x{h}, got {} channel(s) of {}x{}",
                    self.id,
                    classes.channels(),
                    classes.width(),
                    classes.height()
                )));
            }
        }
        Ok(())
    }
}

/// Something that turns a real image into a seasonal variant with the same geometry.
pub trait SeasonGenerator: Sync {
    /// A short name for reports and manifests ("builtin (seed 7)", "gemini:<model>").
    fn name(&self) -> String;

    /// The `season` variant of `source`: RGB, 0–255, same size as the source.
    fn generate(&self, source: &SourceImage<'_>, season: Season) -> Result<Image, SynthError>;
}

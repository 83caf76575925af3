//! The built-in seasonal appearance model: the offline default generator.
//!
//! Geometry is preserved by construction. Every operation is either pointwise (a function of the
//! pixel's own colour and class: land-cover recolouring, snow, shadow depth, colour temperature,
//! contrast, saturation, per-band gain/offset/gamma, noise) or a multiplication/blend with a
//! smooth low-frequency field (illumination gradient, haze, snow patches, foliage hue, ice), whose
//! features are a sizeable fraction of the image wide. Nothing is blurred, shifted or warped, so
//! every edge of the output lies exactly where an edge of the source (or of its class map) lies.
//!
//! The look is deterministic from (seed, source id, season): two images never share the same
//! random parameters, and a rerun reproduces every variant bit for bit.

mod cover;
mod field;
pub(crate) mod random;
mod style;

use rayon::prelude::*;

use raster::Image;

use crate::{Season, SeasonGenerator, SourceImage, SynthError};
use cover::{luminance, smoothstep, Cover};
use field::SmoothField;
use random::{fnv1a64, gaussian_at, Rng};
use style::{Style, Tint};

/// The built-in seasonal model. See the [module documentation](self).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BuiltinSeasons {
    seed: u64,
}

impl BuiltinSeasons {
    /// A model whose random look is drawn from `seed` (and each image's id and season).
    pub fn new(seed: u64) -> Self {
        Self { seed }
    }

    pub fn seed(&self) -> u64 {
        self.seed
    }
}

impl Default for BuiltinSeasons {
    fn default() -> Self {
        Self::new(0)
    }
}

impl SeasonGenerator for BuiltinSeasons {
    fn name(&self) -> String {
        format!("builtin (seed {})", self.seed)
    }

    fn generate(&self, source: &SourceImage<'_>, season: Season) -> Result<Image, SynthError> {
        source.validate()?;
        let key = fnv1a64(&[
            b"seasonstereo-builtin-v1",
            &self.seed.to_le_bytes(),
            source.id.as_bytes(),
            season.tag().as_bytes(),
        ]);
        Ok(render(source, &Variant::draw(season, &mut Rng::new(key))))
    }
}

/// Everything random about one variant: its style, smooth fields and sensor-noise stream.
struct Variant {
    style: Style,
    fields: Fields,
    noise_key: u64,
}

impl Variant {
    fn draw(season: Season, rng: &mut Rng) -> Self {
        let style = Style::new(season, rng);
        let fields = Fields::new(rng);
        Self {
            style,
            fields,
            noise_key: rng.next_u64(),
        }
    }
}

/// The smooth fields of one variant.
struct Fields {
    illumination: SmoothField,
    haze: SmoothField,
    foliage: SmoothField,
    crop: SmoothField,
    snow: SmoothField,
    ice: SmoothField,
    blossom: SmoothField,
    /// Linear illumination gradient (per unit of normalised x and y).
    gradient: [f32; 2],
}

impl Fields {
    fn new(rng: &mut Rng) -> Self {
        Self {
            illumination: SmoothField::new(rng, 2),
            haze: SmoothField::new(rng, 2),
            foliage: SmoothField::new(rng, 5),
            crop: SmoothField::new(rng, 4),
            snow: SmoothField::new(rng, 6),
            ice: SmoothField::new(rng, 3),
            blossom: SmoothField::new(rng, 6),
            gradient: [rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)],
        }
    }
}

fn render(source: &SourceImage<'_>, variant: &Variant) -> Image {
    let style = &variant.style;
    let (w, h) = source.image.size();
    let mut out = vec![0f32; w * h * 3];
    let (inv_w, inv_h) = (1.0 / w as f32, 1.0 / h as f32);
    out.par_chunks_mut(w * 3).enumerate().for_each(|(y, row)| {
        let v = (y as f32 + 0.5) * inv_h;
        let src = source.image.row(y);
        for x in 0..w {
            let u = (x as f32 + 0.5) * inv_w;
            let s = &src[x * 3..x * 3 + 3];
            let dst = &mut row[x * 3..x * 3 + 3];
            if s.iter().any(|v| !v.is_finite()) {
                dst.fill(f32::NAN);
                continue;
            }
            let c = [s[0], s[1], s[2]].map(|v| (v / 255.0).clamp(0.0, 1.0));
            let cover = match source.classes {
                Some(classes) => Cover::from_class(classes.get(x, y, 0)),
                None => Cover::from_colour(c),
            };
            let seasonal = variant.season_colour(c, &cover, (u, v));
            let rgb = variant.atmosphere_and_light(seasonal, luminance(c), &cover, (u, v));
            let index = ((y * w + x) * 3) as u64;
            for (k, (out, value)) in dst.iter_mut().zip(rgb).enumerate() {
                let sensed = sensor(value, k, style);
                let noise = style.noise_dn * gaussian_at(variant.noise_key, index + k as u64);
                *out = (sensed * 255.0 + noise).clamp(0.0, 255.0);
            }
        }
    });
    Image::new(w, h, 3, out).expect("output buffer has the source's size")
}

impl Variant {
    /// Land-cover recolouring and snow: what the season does to the ground itself.
    fn season_colour(&self, c: [f32; 3], cover: &Cover, (u, v): (f32, f32)) -> [f32; 3] {
        let (style, fields) = (&self.style, &self.fields);
        let l = luminance(c);
        let mut acc = [0f32; 3];
        let mut add = |weight: f32, rgb: [f32; 3]| {
            if weight > 0.0 {
                for k in 0..3 {
                    acc[k] += weight * rgb[k];
                }
            }
        };
        if cover.tree > 0.0 {
            let mut canopy = palette(
                &style.tree_palette,
                0.5 + 0.5 * fields.foliage.at(u, v),
                c,
                l,
            );
            if let Some((blossom, share)) = &style.blossom {
                let t = share * smoothstep(0.2, 0.9, fields.blossom.at(u, v));
                let petals = blossom.apply(c, l);
                canopy = std::array::from_fn(|k| canopy[k] + (petals[k] - canopy[k]) * t);
            }
            add(cover.tree, canopy);
        }
        if cover.crop > 0.0 {
            let t = style.crop_alt_share * 2.0 * smoothstep(-0.3, 0.3, fields.crop.at(u, v));
            add(
                cover.crop,
                Tint::mix(&style.crop, &style.crop_alt, t.min(1.0), c, l),
            );
        }
        if cover.water > 0.0 {
            let water = style.water.apply(c, l);
            let ice = style.ice * smoothstep(0.0, 0.7, fields.ice.at(u, v));
            let frozen = [0.62, 0.68, 0.74].map(|v| v * (0.6 + 2.5 * l).min(1.2));
            add(
                cover.water,
                std::array::from_fn(|k| water[k] + (frozen[k] - water[k]) * ice),
            );
        }
        add(cover.grass, style.grass.apply(c, l));
        add(cover.bare, style.bare.apply(c, l));
        add(cover.developed, style.developed.apply(c, l));
        add(cover.road, style.road.apply(c, l));
        add(cover.roof, style.roof.apply(c, l));
        add(cover.other, c);

        let Some(snow) = &style.snow else {
            return acc;
        };
        let base = cover.weighted(&snow.cover);
        if base <= 0.0 {
            return acc;
        }
        let amount = (base
            + snow.patchiness * fields.snow.at(u, v) * base.min(1.0 - base).max(0.0) * 2.0)
            .clamp(0.0, 1.0);
        // Shading of the snow: the pixel's brightness relative to sunlit ground of its cover, so
        // shadows and texture stay (darker, bluer snow in shade).
        let shade = (l / cover.sunlit_luminance().max(0.05)).clamp(0.0, 1.25);
        let (shadowed, sunlit) = ([0.40, 0.45, 0.58], [0.93, 0.95, 0.98]);
        let t = shade.min(1.0);
        let lift = 1.0 + 0.4 * (shade - 1.0).max(0.0);
        let snow_rgb: [f32; 3] =
            std::array::from_fn(|k| (shadowed[k] + (sunlit[k] - shadowed[k]) * t) * lift);
        std::array::from_fn(|k| acc[k] + (snow_rgb[k] - acc[k]) * amount)
    }

    /// Shadows, illumination, colour temperature, contrast, saturation and haze.
    fn atmosphere_and_light(
        &self,
        c: [f32; 3],
        source_luminance: f32,
        cover: &Cover,
        (u, v): (f32, f32),
    ) -> [f32; 3] {
        let (style, fields) = (&self.style, &self.fields);
        let shadow = (1.0 - smoothstep(0.05, 0.16, source_luminance)) * (1.0 - cover.water);
        let shadow_gain = 1.0 + shadow * (style.shadow_factor - 1.0);
        let ramp = fields.gradient[0] * (u - 0.5) + fields.gradient[1] * (v - 0.5);
        let illumination = style.gain
            * (1.0
                + style.illumination_amplitude * (0.6 * fields.illumination.at(u, v) + 0.4 * ramp));
        let t = style.temperature;
        let temperature = [1.0 + 0.08 * t, 1.0 + 0.01 * t, 1.0 - 0.09 * t];
        let mut rgb: [f32; 3] =
            std::array::from_fn(|k| c[k] * shadow_gain * illumination * temperature[k]);
        let l = luminance(rgb);
        for value in &mut rgb {
            let saturated = l + (*value - l) * style.saturation;
            *value = 0.35 + (saturated - 0.35) * style.contrast;
        }
        let haze = (style.haze + style.haze_amplitude * fields.haze.at(u, v)).clamp(0.0, 0.5);
        std::array::from_fn(|k| rgb[k] + (style.haze_colour[k] - rgb[k]) * haze)
    }
}

/// Piecewise-linear pick along the palette by `t` ∈ [0, 1].
fn palette(tints: &[Tint], t: f32, c: [f32; 3], l: f32) -> [f32; 3] {
    match tints.len() {
        0 => c,
        1 => tints[0].apply(c, l),
        n => {
            let f = t.clamp(0.0, 1.0) * (n - 1) as f32;
            let i = (f as usize).min(n - 2);
            Tint::mix(&tints[i], &tints[i + 1], f - i as f32, c, l)
        }
    }
}

/// Per-band sensor response on [0, 1].
fn sensor(value: f32, band: usize, style: &Style) -> f32 {
    let v =
        (style.band_gain[band] * value.clamp(0.0, 1.0) + style.band_offset[band]).clamp(0.0, 1.0);
    v.powf(style.band_gamma[band])
}

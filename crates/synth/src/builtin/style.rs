//! The appearance of each season: target colours per land cover, snow, light, atmosphere and
//! sensor. The nominal values follow the prompts of the method (lush canopies and warm light in
//! summer; fall foliage, harvested fields and golden light in autumn; snow on roofs, fields and
//! open ground, leafless trees, clear roads and cold muted light in winter; fresh light greens and
//! blossoms in spring). Each value is jittered per (seed, image, season), so two images of the
//! same season never look identical.

use super::cover::{luminance, Cover};
use super::random::Rng;
use crate::Season;

/// Recolouring of one land cover: the pixel's luminance is kept as texture and given the
/// chromaticity of `colour`, scaled by `gain`, then blended with the original by `strength`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Tint {
    /// `colour / luminance(colour)`: the chromaticity at unit luminance.
    hue: [f32; 3],
    gain: f32,
    strength: f32,
}

impl Tint {
    pub(crate) fn new(colour: [f32; 3], gain: f32, strength: f32) -> Self {
        let l = luminance(colour).max(1e-3);
        Self {
            hue: colour.map(|v| v / l),
            gain,
            strength: strength.clamp(0.0, 1.0),
        }
    }

    /// No change.
    pub(crate) fn identity() -> Self {
        Self {
            hue: [1.0; 3],
            gain: 1.0,
            strength: 0.0,
        }
    }

    /// Recoloured `c` (luminance `l`).
    pub(crate) fn apply(&self, c: [f32; 3], l: f32) -> [f32; 3] {
        let s = self.strength;
        std::array::from_fn(|k| c[k] + (self.hue[k] * l * self.gain - c[k]) * s)
    }

    /// The blend of two tints' results by `t` ∈ [0, 1].
    pub(crate) fn mix(a: &Tint, b: &Tint, t: f32, c: [f32; 3], l: f32) -> [f32; 3] {
        let (x, y) = (a.apply(c, l), b.apply(c, l));
        std::array::from_fn(|k| x[k] + (y[k] - x[k]) * t)
    }
}

/// Base snow cover per land cover (before the patchiness field).
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Snow {
    /// Snow share of each land cover (water takes none: it freezes to ice instead).
    pub cover: Cover,
    /// Amplitude of the smooth field added to the base cover (patchy snow).
    pub patchiness: f32,
}

/// Every parameter of one season's look for one image.
#[derive(Clone, Debug)]
pub(crate) struct Style {
    /// Canopy colours picked along a smooth field (autumn's mixed foliage; one entry otherwise).
    pub tree_palette: Vec<Tint>,
    pub grass: Tint,
    /// Fields: the smooth crop field blends `crop` and `crop_alt` (ripe, harvested, ploughed).
    pub crop: Tint,
    pub crop_alt: Tint,
    pub crop_alt_share: f32,
    pub bare: Tint,
    pub developed: Tint,
    pub road: Tint,
    pub roof: Tint,
    pub water: Tint,
    /// Spring blossom on part of the canopy: (tint, largest share).
    pub blossom: Option<(Tint, f32)>,
    /// Largest share of water turned to ice (winter), placed by a smooth field.
    pub ice: f32,
    pub snow: Option<Snow>,
    /// Multiplier of shadowed pixels: < 1 deepens shadows (low sun), > 1 lightens them.
    pub shadow_factor: f32,
    /// Global illumination gain and the amplitude of its smooth spatial variation.
    pub gain: f32,
    pub illumination_amplitude: f32,
    /// Colour temperature shift: > 0 warmer (red up, blue down), < 0 colder.
    pub temperature: f32,
    pub contrast: f32,
    pub saturation: f32,
    /// Haze share (mean and smooth variation) and its colour.
    pub haze: f32,
    pub haze_amplitude: f32,
    pub haze_colour: [f32; 3],
    /// Sensor radiometry per band: `(gain · v + offset)^gamma`, then Gaussian noise (DN).
    pub band_gain: [f32; 3],
    pub band_offset: [f32; 3],
    pub band_gamma: [f32; 3],
    pub noise_dn: f32,
}

/// `value` scaled by a random factor in [1 − rel, 1 + rel].
fn jitter(rng: &mut Rng, value: f32, rel: f32) -> f32 {
    value * rng.range(1.0 - rel, 1.0 + rel)
}

fn jitter_colour(rng: &mut Rng, c: [f32; 3], rel: f32) -> [f32; 3] {
    c.map(|v| jitter(rng, v, rel))
}

/// A nominal recolouring `(colour, gain, strength)`, jittered per image by [`draw_tint`].
type NominalTint = ([f32; 3], f32, f32);

/// A nominal value and its relative jitter, drawn by [`jitter`].
type Jittered = (f32, f32);

/// A range a value is drawn uniformly from.
type Range = (f32, f32);

/// The nominal look of a season, from the prompts of the method: what [`Style::new`] jitters.
struct SeasonLook {
    trees: &'static [NominalTint],
    grass: NominalTint,
    crop: NominalTint,
    crop_alt: NominalTint,
    crop_alt_share: Range,
    bare: NominalTint,
    /// Roads are recoloured only where the season changes them (winter's cleared asphalt).
    road: Option<NominalTint>,
    water: NominalTint,
    shadow_factor: Jittered,
    gain: Jittered,
    illumination_amplitude: Range,
    temperature: Jittered,
    contrast: Jittered,
    saturation: Jittered,
    haze: Range,
    haze_amplitude: Range,
    haze_colour: [f32; 3],
}

#[rustfmt::skip]
const SUMMER: SeasonLook = SeasonLook {
    trees: &[([0.10, 0.27, 0.06], 1.0, 0.85)],
    grass: ([0.20, 0.42, 0.10], 1.1, 0.85), crop: ([0.26, 0.46, 0.10], 1.05, 0.85),
    crop_alt: ([0.58, 0.50, 0.24], 1.25, 0.8), crop_alt_share: (0.2, 0.5),
    bare: ([0.55, 0.45, 0.32], 1.05, 0.35), road: None, water: ([0.06, 0.14, 0.16], 1.0, 0.5),
    shadow_factor: (1.2, 0.08), gain: (1.08, 0.04), illumination_amplitude: (0.03, 0.08),
    temperature: (0.5, 0.3), contrast: (1.08, 0.03), saturation: (1.15, 0.05),
    haze: (0.03, 0.09), haze_amplitude: (0.01, 0.04), haze_colour: [0.72, 0.78, 0.86],
};

#[rustfmt::skip]
const AUTUMN: SeasonLook = SeasonLook {
    trees: &[
        ([0.20, 0.30, 0.08], 1.05, 0.9), ([0.55, 0.48, 0.12], 1.25, 0.9),
        ([0.60, 0.32, 0.08], 1.2, 0.9), ([0.52, 0.18, 0.08], 1.1, 0.9),
        ([0.40, 0.28, 0.16], 1.0, 0.9),
    ],
    grass: ([0.40, 0.40, 0.18], 1.1, 0.8), crop: ([0.50, 0.40, 0.26], 1.15, 0.85),
    crop_alt: ([0.62, 0.52, 0.28], 1.3, 0.85), crop_alt_share: (0.3, 0.6),
    bare: ([0.50, 0.40, 0.30], 0.95, 0.4), road: None, water: ([0.07, 0.11, 0.12], 0.95, 0.5),
    shadow_factor: (0.82, 0.06), gain: (0.96, 0.04), illumination_amplitude: (0.04, 0.09),
    temperature: (0.9, 0.25), contrast: (0.95, 0.03), saturation: (0.95, 0.05),
    haze: (0.04, 0.11), haze_amplitude: (0.01, 0.05), haze_colour: [0.80, 0.76, 0.70],
};

#[rustfmt::skip]
const WINTER: SeasonLook = SeasonLook {
    trees: &[([0.34, 0.30, 0.27], 0.9, 0.9)],
    grass: ([0.42, 0.38, 0.30], 1.0, 0.8), crop: ([0.45, 0.40, 0.32], 1.0, 0.8),
    crop_alt: ([0.40, 0.33, 0.26], 0.9, 0.8), crop_alt_share: (0.2, 0.5),
    bare: ([0.45, 0.42, 0.38], 0.95, 0.4), road: Some(([0.25, 0.26, 0.28], 0.85, 0.6)),
    water: ([0.05, 0.08, 0.10], 0.85, 0.6),
    shadow_factor: (0.72, 0.08), gain: (0.92, 0.04), illumination_amplitude: (0.04, 0.1),
    temperature: (-0.9, 0.25), contrast: (0.9, 0.04), saturation: (0.72, 0.08),
    haze: (0.02, 0.07), haze_amplitude: (0.01, 0.03), haze_colour: [0.78, 0.82, 0.90],
};

#[rustfmt::skip]
const SPRING: SeasonLook = SeasonLook {
    trees: &[([0.30, 0.50, 0.14], 1.3, 0.85), ([0.22, 0.42, 0.12], 1.15, 0.85)],
    grass: ([0.30, 0.52, 0.14], 1.2, 0.85), crop: ([0.34, 0.52, 0.16], 1.15, 0.85),
    crop_alt: ([0.46, 0.36, 0.26], 0.95, 0.85), crop_alt_share: (0.2, 0.5),
    bare: ([0.50, 0.42, 0.32], 0.95, 0.3), road: None, water: ([0.07, 0.14, 0.15], 1.05, 0.5),
    shadow_factor: (0.95, 0.06), gain: (1.02, 0.04), illumination_amplitude: (0.03, 0.08),
    temperature: (-0.15, 0.5), contrast: (1.03, 0.03), saturation: (1.1, 0.05),
    haze: (0.03, 0.10), haze_amplitude: (0.01, 0.04), haze_colour: [0.76, 0.80, 0.86],
};

impl SeasonLook {
    fn of(season: Season) -> &'static SeasonLook {
        match season {
            Season::Summer => &SUMMER,
            Season::Autumn => &AUTUMN,
            Season::Winter => &WINTER,
            Season::Spring => &SPRING,
        }
    }
}

/// A tint of `nominal` whose colour, gain and strength are jittered by 8 %, 6 % and 8 %.
fn draw_tint(rng: &mut Rng, (colour, gain, strength): NominalTint) -> Tint {
    Tint::new(
        jitter_colour(rng, colour, 0.08),
        jitter(rng, gain, 0.06),
        jitter(rng, strength, 0.08),
    )
}

fn draw_range(rng: &mut Rng, (lo, hi): Range) -> f32 {
    rng.range(lo, hi)
}

fn draw_jittered(rng: &mut Rng, (value, rel): Jittered) -> f32 {
    jitter(rng, value, rel)
}

impl Style {
    /// The look of `season` for one image, drawn from `rng`. The draws keep a fixed order
    /// (land cover, the season's own effects, light, sensor), so a seed always gives one look.
    pub(crate) fn new(season: Season, rng: &mut Rng) -> Self {
        let look = SeasonLook::of(season);
        let mut style = Style::neutral();
        style.draw_land_cover(look, rng);
        match season {
            Season::Winter => style.draw_winter(rng),
            Season::Spring => style.draw_blossom(rng),
            Season::Summer | Season::Autumn => {}
        }
        style.draw_light(look, rng);
        style.draw_sensor(rng);
        style
    }

    /// The recolouring of each land cover (developed land and roofs keep their colour).
    fn draw_land_cover(&mut self, look: &SeasonLook, rng: &mut Rng) {
        self.tree_palette = look.trees.iter().map(|&t| draw_tint(rng, t)).collect();
        self.grass = draw_tint(rng, look.grass);
        self.crop = draw_tint(rng, look.crop);
        self.crop_alt = draw_tint(rng, look.crop_alt);
        self.crop_alt_share = draw_range(rng, look.crop_alt_share);
        self.bare = draw_tint(rng, look.bare);
        if let Some(road) = look.road {
            self.road = draw_tint(rng, road);
        }
        self.water = draw_tint(rng, look.water);
    }

    /// Ice on the water and snow on the land, most on open ground and roofs, least on roads.
    fn draw_winter(&mut self, rng: &mut Rng) {
        self.ice = rng.range(0.15, 0.6);
        self.snow = Some(Snow {
            cover: Cover {
                tree: rng.range(0.05, 0.25),
                grass: rng.range(0.75, 0.95),
                crop: rng.range(0.75, 0.95),
                bare: rng.range(0.65, 0.9),
                developed: rng.range(0.35, 0.7),
                road: rng.range(0.0, 0.08),
                roof: rng.range(0.7, 0.95),
                other: rng.range(0.3, 0.6),
                water: 0.0,
            },
            patchiness: rng.range(0.2, 0.4),
        });
    }

    /// Spring blossom on part of the canopy.
    fn draw_blossom(&mut self, rng: &mut Rng) {
        let tint = draw_tint(rng, ([0.86, 0.66, 0.72], 1.8, 0.8));
        self.blossom = Some((tint, rng.range(0.15, 0.35)));
    }

    /// Shadow depth, illumination, colour temperature, contrast, saturation and haze.
    fn draw_light(&mut self, look: &SeasonLook, rng: &mut Rng) {
        self.shadow_factor = draw_jittered(rng, look.shadow_factor);
        self.gain = draw_jittered(rng, look.gain);
        self.illumination_amplitude = draw_range(rng, look.illumination_amplitude);
        self.temperature = draw_jittered(rng, look.temperature);
        self.contrast = draw_jittered(rng, look.contrast);
        self.saturation = draw_jittered(rng, look.saturation);
        self.haze = draw_range(rng, look.haze);
        self.haze_amplitude = draw_range(rng, look.haze_amplitude);
        self.haze_colour = look.haze_colour;
    }

    /// The sensor's per-band radiometry and noise.
    fn draw_sensor(&mut self, rng: &mut Rng) {
        self.band_gain = std::array::from_fn(|_| rng.range(0.95, 1.05));
        self.band_offset = std::array::from_fn(|_| rng.range(-0.02, 0.02));
        self.band_gamma = std::array::from_fn(|_| rng.range(0.92, 1.08));
        self.noise_dn = rng.range(0.8, 2.0);
    }

    /// The neutral look (no change anywhere) that [`Style::new`] draws a season's values into.
    fn neutral() -> Style {
        let neutral = Tint::identity();
        Style {
            tree_palette: Vec::new(),
            grass: neutral,
            crop: neutral,
            crop_alt: neutral,
            crop_alt_share: 0.0,
            bare: neutral,
            developed: neutral,
            road: neutral,
            roof: neutral,
            water: neutral,
            blossom: None,
            ice: 0.0,
            snow: None,
            shadow_factor: 1.0,
            gain: 1.0,
            illumination_amplitude: 0.0,
            temperature: 0.0,
            contrast: 1.0,
            saturation: 1.0,
            haze: 0.0,
            haze_amplitude: 0.0,
            haze_colour: [0.8; 3],
            band_gain: [1.0; 3],
            band_offset: [0.0; 3],
            band_gamma: [1.0; 3],
            noise_dn: 0.0,
        }
    }
}

//! How surfaces look: the place where seasons plug in. The renderer asks an [`Appearance`] for the
//! reflected light of every ground point and wall; geometry never depends on it, so any appearance
//! model keeps the ground-truth disparity exact.

use crate::class;
use crate::scene::Surface;

/// Sun direction and sky light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lighting {
    /// Unit vector towards the sun (x east, y south, z up).
    pub sun: [f64; 3],
    /// Share of light that reaches shadowed surfaces (sky light), in [0, 1].
    pub ambient: f32,
}

impl Lighting {
    /// Sun at `elevation_deg` above the horizon and `azimuth_deg` clockwise from north.
    pub fn from_angles(elevation_deg: f64, azimuth_deg: f64, ambient: f32) -> Self {
        let (e, a) = (elevation_deg.to_radians(), azimuth_deg.to_radians());
        Lighting {
            sun: [e.cos() * a.sin(), -e.cos() * a.cos(), e.sin()],
            ambient,
        }
    }

    /// Direct-sun factor of a surface with unit `normal`, relative to flat open ground (1.0), 0 in
    /// shadow; capped so that steep sunlit faces do not saturate.
    pub fn direct(&self, normal: [f64; 3], shadowed: bool) -> f32 {
        if shadowed {
            return 0.0;
        }
        let cos = normal[0] * self.sun[0] + normal[1] * self.sun[1] + normal[2] * self.sun[2];
        (cos.max(0.0) / self.sun[2].max(0.05)).min(1.8) as f32
    }
}

/// Reflected light (RGB in [0, 1]) of the scene's surfaces.
pub trait Appearance: Sync + Send {
    /// A short name for reports ("neutral", "winter", …).
    fn name(&self) -> &str;

    /// Light reflected by a ground, roof, tree or water point receiving `direct` sun (see
    /// [`Lighting::direct`]) and the ambient share of sky light.
    fn surface(&self, s: &Surface, direct: f32, ambient: f32) -> [f32; 3];

    /// Light reflected by a wall of the object at `s` (a facade, a tree crown's side, a river bank),
    /// `above_ground_m` metres above the wall's foot.
    fn wall(&self, s: &Surface, above_ground_m: f32, direct: f32, ambient: f32) -> [f32; 3];
}

/// The reference appearance: leaf-on vegetation under a clear sky, the look the seasonal models
/// vary around.
#[derive(Clone, Copy, Debug, Default)]
pub struct Neutral;

impl Appearance for Neutral {
    fn name(&self) -> &str {
        "neutral"
    }

    fn surface(&self, s: &Surface, direct: f32, ambient: f32) -> [f32; 3] {
        let light = ambient + (1.0 - ambient) * direct;
        s.albedo.map(|a| a * light)
    }

    fn wall(&self, s: &Surface, above_ground_m: f32, direct: f32, ambient: f32) -> [f32; 3] {
        let light = ambient + (1.0 - ambient) * direct;
        // Facades show a row of windows on every 3 m storey.
        let window = s.class == class::BUILDING
            && (above_ground_m.rem_euclid(3.0)) > 1.1
            && above_ground_m.rem_euclid(3.0) < 2.2;
        let shade = if window { 0.45 } else { 1.0 };
        s.facade.map(|a| a * light * shade)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flat_sunlit_ground_gets_full_light() {
        let l = Lighting::from_angles(50.0, 135.0, 0.3);
        assert!((l.direct([0.0, 0.0, 1.0], false) - 1.0).abs() < 1e-6);
        assert_eq!(l.direct([0.0, 0.0, 1.0], true), 0.0);
        // South-east sun lights an east-facing wall, not a west-facing one.
        assert!(l.direct([1.0, 0.0, 0.0], false) > 0.0);
        assert_eq!(l.direct([-1.0, 0.0, 0.0], false), 0.0);
    }
}

//! The sun's shadows on the scene, precomputed on a grid so that lighting a sample is a lookup.

use rayon::prelude::*;

use crate::appearance::Lighting;
use crate::scene::Scene;

/// Where the sun's shadows fall: for every cell of a 1-pixel grid around the image, the altitude
/// below which a point there is in shadow (the highest sun ray grazing an obstacle towards the sun).
/// One march per cell instead of one per sample makes large worlds cheap to light.
pub(crate) struct ShadowGrid {
    x0: f64,
    y0: f64,
    width: usize,
    height: usize,
    threshold: Vec<f32>,
}

impl ShadowGrid {
    pub(crate) fn new(
        scene: &Scene,
        (x0, y0): (f64, f64),
        (width, height): (usize, usize),
        light: &Lighting,
        max_z: f64,
    ) -> Self {
        let z: Vec<f32> = (0..height)
            .into_par_iter()
            .flat_map_iter(|j| {
                (0..width).map(move |i| scene.surface(x0 + i as f64, y0 + j as f64).height)
            })
            .collect();
        let horiz = light.sun[0].hypot(light.sun[1]);
        let (dx, dy) = if horiz > 1e-9 {
            (light.sun[0] / horiz, light.sun[1] / horiz)
        } else {
            (0.0, 0.0)
        };
        // Metres the sun ray climbs per pixel travelled towards the sun.
        let rise = if horiz > 1e-9 {
            light.sun[2] / horiz * scene.params().gsd
        } else {
            f64::INFINITY
        };
        let lowest = z.iter().copied().fold(f32::INFINITY, f32::min) as f64;
        let reach = if rise.is_finite() {
            ((max_z - lowest) / rise).ceil() as usize
        } else {
            0
        };
        let at = |i: f64, j: f64| -> f32 {
            let (i, j) = (i.round(), j.round());
            if i < 0.0 || j < 0.0 || i >= width as f64 || j >= height as f64 {
                return f32::NEG_INFINITY;
            }
            z[j as usize * width + i as usize]
        };
        let threshold = (0..height)
            .into_par_iter()
            .flat_map_iter(|j| {
                let at = &at;
                (0..width).map(move |i| {
                    (1..=reach)
                        .map(|t| {
                            let t = t as f64;
                            at(i as f64 + t * dx, j as f64 + t * dy) - (t * rise) as f32
                        })
                        .fold(f32::NEG_INFINITY, f32::max)
                })
            })
            .collect();
        ShadowGrid {
            x0,
            y0,
            width,
            height,
            threshold,
        }
    }

    /// True when the point (x, y) at altitude z is in the shadow of something towards the sun.
    pub(crate) fn shadowed(&self, x: f64, y: f64, z: f64) -> bool {
        let (i, j) = ((x - self.x0).round(), (y - self.y0).round());
        if i < 0.0 || j < 0.0 || i >= self.width as f64 || j >= self.height as f64 {
            return false;
        }
        self.threshold[j as usize * self.width + i as usize] as f64 > z + 0.05
    }
}

//! Rendering of one ground row into both rectified views, with the row's exact truth.

use crate::appearance::{Appearance, Lighting};
use crate::camera::ViewCamera;
use crate::class;
use crate::render::{point_at, rasterise, span_at, visible_spans, Piece, Profile, Span};
use crate::scene::{Scene, Surface};
use crate::shadow::ShadowGrid;

/// The visible point at a pixel centre: ground x, altitude and class.
type Seen = Option<(f64, f64, u8)>;

/// One view's share of a rendered row.
pub(crate) struct RowView {
    /// Radiance of each pixel.
    pub pixels: Vec<[f32; 3]>,
    /// Altitude (NaN where nothing is seen) and class of each pixel.
    pub truth: Vec<(f32, u8)>,
}

/// Output of one rendered row.
pub(crate) struct RowOut {
    pub left: RowView,
    pub right: RowView,
    /// True disparity of each left pixel (NaN where nothing is seen).
    pub disparity: Vec<f32>,
    /// Left pixels not visible in the right view.
    pub occluded: Vec<bool>,
}

/// Everything the rows of one world share: the scene, its light and the two cameras.
pub(crate) struct RowRenderer<'a> {
    pub scene: &'a Scene,
    pub shadows: &'a ShadowGrid,
    pub appearance: &'a dyn Appearance,
    pub light: &'a Lighting,
    pub left: &'a ViewCamera,
    pub right: &'a ViewCamera,
    /// Image width, pixels.
    pub width: usize,
    /// The row is sampled at `x_lo + (k + ½)·step` for `k < samples`.
    pub x_lo: f64,
    pub step: f64,
    pub samples: usize,
}

impl RowRenderer<'_> {
    /// Renders image row `row` (ground row y = `row`) into both views.
    pub fn render(&self, row: usize) -> RowOut {
        let y = row as f64;
        let surfaces: Vec<Surface> = (0..self.samples)
            .map(|k| self.scene.surface(self.sample_x(k), y))
            .collect();
        let colours = self.shade(&surfaces, y);
        let profile = Profile::new(self.x_lo, self.step, &surfaces, &colours);
        let (left_spans, left_pixels) = self.view(&profile, self.left);
        let (right_spans, right_pixels) = self.view(&profile, self.right);
        let left_truth = self.truth(&profile, self.left, &left_spans);
        let right_truth = self.truth(&profile, self.right, &right_spans);
        let (disparity, occluded) = self.disparity(&profile, &left_truth, &right_spans);
        RowOut {
            left: RowView {
                pixels: left_pixels,
                truth: pack(left_truth),
            },
            right: RowView {
                pixels: right_pixels,
                truth: pack(right_truth),
            },
            disparity,
            occluded,
        }
    }

    /// Ground x of flat sample `k`.
    fn sample_x(&self, k: usize) -> f64 {
        self.x_lo + (k as f64 + 0.5) * self.step
    }

    /// The lit colour of every flat sample: direct sun unless the shadow grid hides it, plus sky.
    fn shade(&self, surfaces: &[Surface], y: f64) -> Vec<[f32; 3]> {
        surfaces
            .iter()
            .enumerate()
            .map(|(k, s)| {
                let shadow = self.shadows.shadowed(self.sample_x(k), y, s.height as f64);
                let normal = s.normal.map(|v| v as f64);
                self.appearance
                    .surface(s, self.light.direct(normal, shadow), self.light.ambient)
            })
            .collect()
    }

    /// The spans of the profile `cam` sees and its pixels; walls face the camera and are lit
    /// as such.
    fn view(&self, profile: &Profile, cam: &ViewCamera) -> (Vec<Span>, Vec<[f32; 3]>) {
        let surfaces = profile.surfaces;
        let spans = visible_spans(profile, cam);
        let facing = [-cam.slope.signum(), 0.0, 0.0];
        let wall_direct = self.light.direct(facing, false);
        let pixels = rasterise(profile, cam, &spans, self.width, |owner, foot, z| {
            let above = (z - surfaces[foot].height as f64) as f32;
            self.appearance
                .wall(&surfaces[owner], above, wall_direct, self.light.ambient)
        });
        (spans, pixels)
    }

    /// The point `cam` sees at each pixel centre (walls take their owner's class).
    fn truth(&self, profile: &Profile, cam: &ViewCamera, spans: &[Span]) -> Vec<Seen> {
        (0..self.width)
            .map(|u| {
                let i = span_at(spans, u as f64)?;
                let (x, z) = point_at(profile, cam, &spans[i], u as f64);
                let class = match spans[i].piece {
                    Piece::Flat(k) => profile.surfaces[k].class,
                    Piece::Wall { owner, .. } => profile.surfaces[owner].class,
                };
                Some((x, z, class))
            })
            .collect()
    }

    /// Disparity of each left pixel, and whether the right view misses its point (hidden, or
    /// projected outside the image).
    fn disparity(
        &self,
        profile: &Profile,
        left_truth: &[Seen],
        right_spans: &[Span],
    ) -> (Vec<f32>, Vec<bool>) {
        let w = self.width;
        let mut disparity = Vec::with_capacity(w);
        let mut occluded = Vec::with_capacity(w);
        for (u, t) in left_truth.iter().enumerate() {
            let Some((x, z, _)) = *t else {
                disparity.push(f32::NAN);
                occluded.push(true);
                continue;
            };
            let ur = self.right.column(x, z);
            disparity.push((u as f64 - ur) as f32);
            let seen = ur >= -0.5
                && ur < w as f64 - 0.5
                && span_at(right_spans, ur).is_some_and(|i| {
                    let (xr, zr) = point_at(profile, self.right, &right_spans[i], ur);
                    (xr - x).abs() < 1e-4 && (zr - z).abs() < 1e-4
                });
            occluded.push(!seen);
        }
        (disparity, occluded)
    }
}

/// Altitude and class per pixel, NaN and background where nothing is seen.
fn pack(truth: Vec<Seen>) -> Vec<(f32, u8)> {
    truth
        .into_iter()
        .map(|v| v.map_or((f32::NAN, class::BACKGROUND), |(_, z, c)| (z as f32, c)))
        .collect()
}

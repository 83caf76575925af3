//! A deterministic procedural satellite world with exact ground truth.
//!
//! Real satellite stereo data has no exact disparity ground truth (LiDAR is sparse, dated and
//! misregistered), so tests, benchmarks and the demo need a world where every pixel's true
//! disparity, altitude and class are known. This crate builds a seeded 2.5D urban/suburban scene
//! (terrain, a river, streets, houses with pitched roofs, flat-roofed commercial buildings, trees,
//! parks, ponds and fields), lights it with a sun that casts shadows, and renders it into a rectified
//! left/right pair seen by two pushbroom-like affine cameras with different incidence angles.
//!
//! Conventions: disparity lives on the left view, x_R = x_L − d, and grows with altitude;
//! classes use the OpenEarthMap ids of [`class`]; appearance (seasons) is pluggable through
//! [`Appearance`] and never changes the geometry.

pub mod appearance;
pub mod camera;
pub mod class;
pub mod noise;
pub mod render;
mod row;
pub mod scene;
mod shadow;

use rayon::prelude::*;

pub use appearance::{Appearance, Lighting, Neutral};
pub use camera::{AffineCamera, GeoFrame, ViewCamera};
use raster::{Homography, Image, Mask};
use row::{RowOut, RowRenderer, RowView};
pub use scene::{Scene, SceneParams, Surface};
use shadow::ShadowGrid;

/// Everything that defines a world; the same parameters always give the same world.
#[derive(Clone, Debug, PartialEq)]
pub struct WorldParams {
    /// Size of the rectified images, pixels.
    pub width: usize,
    pub height: usize,
    pub scene: SceneParams,
    /// The two views (rectified coordinates). Disparity = (left.slope − right.slope)·z +
    /// (left.offset − right.offset).
    pub left: ViewCamera,
    pub right: ViewCamera,
    pub sun_elevation_deg: f64,
    pub sun_azimuth_deg: f64,
    /// Share of sky light in shadows.
    pub ambient: f32,
    /// Flat samples per pixel along x (anti-aliasing and sub-pixel geometry).
    pub supersample: usize,
    /// Sensor noise, digital numbers (standard deviation, on a 0–255 scale).
    pub noise_dn: f32,
    /// Geographic origin of ground pixel (0, 0), degrees.
    pub lon0: f64,
    pub lat0: f64,
}

impl WorldParams {
    /// A square world of `size` pixels: 0.5 m GSD, incidence giving 0.65 px of disparity per metre,
    /// disparity 4 px at altitude 0, sun at 50° elevation from the south-east.
    pub fn new(size: usize, seed: u64) -> Self {
        WorldParams {
            width: size,
            height: size,
            scene: SceneParams {
                seed,
                ..SceneParams::default()
            },
            left: ViewCamera {
                slope: 0.40,
                offset: 0.0,
            },
            right: ViewCamera {
                slope: -0.25,
                offset: -4.0,
            },
            sun_elevation_deg: 50.0,
            sun_azimuth_deg: 140.0,
            ambient: 0.35,
            supersample: 4,
            noise_dn: 1.0,
            lon0: -81.6637,
            lat0: 30.3487,
        }
    }

    /// Disparity of a point at altitude `z` metres.
    pub fn disparity_at(&self, z: f64) -> f64 {
        (self.left.slope - self.right.slope) * z + (self.left.offset - self.right.offset)
    }

    /// Integer disparity search range guaranteed to contain every true disparity, derived from the
    /// cameras and the scene's altitude range (the way a satellite pipeline should bound it); it
    /// does not depend on the seed, so it is known before rendering.
    pub fn disparity_range(&self) -> (i32, i32) {
        let (lo, hi) = self.altitude_range();
        let (a, b) = (self.disparity_at(lo), self.disparity_at(hi));
        (a.min(b).floor() as i32, a.max(b).ceil() as i32)
    }

    /// Altitudes the scene can reach, metres, with a metre of margin each side: what bounds the
    /// disparity search, the rendered margin and the cameras' `min_alt`/`max_alt`.
    pub fn altitude_range(&self) -> (f64, f64) {
        (-1.0, self.scene.relief_m + scene::MAX_OBJECT_HEIGHT_M + 1.0)
    }

    fn check(&self) -> Result<(), String> {
        if self.width < 8 || self.height < 8 || self.width > 16384 || self.height > 16384 {
            return Err(format!(
                "world size {}x{} is outside 8..=16384 pixels",
                self.width, self.height
            ));
        }
        if self.supersample == 0 || self.supersample > 16 {
            return Err("supersample must be within 1..=16".into());
        }
        if !(5.0..=90.0).contains(&self.sun_elevation_deg) {
            return Err("sun elevation must be within 5..=90 degrees".into());
        }
        if self.scene.gsd <= 0.0 || self.scene.block_pitch <= self.scene.road_width + 8.0 {
            return Err("gsd must be positive and blocks wider than roads".into());
        }
        Ok(())
    }
}

/// One rendered view with its per-pixel truth.
pub struct View {
    /// RGB, digital numbers 0–255.
    pub image: Image,
    /// Altitude of the surface seen at each pixel, metres.
    pub height: Image,
    /// Class id of the surface seen at each pixel.
    pub classes: Image,
}

/// A generated world: the rectified pair, its exact ground truth and its cameras.
pub struct World {
    pub params: WorldParams,
    pub left: View,
    pub right: View,
    /// True disparity on the left view (x_R = x_L − d), defined at every pixel.
    pub disparity: Image,
    /// Left pixels not visible in the right view (occluded, or matched outside the image).
    pub occluded: Mask,
    /// Altitude and classes on the ground grid (north-up, 1 pixel = 1 GSD, x in [0, width)).
    pub ortho_height: Image,
    pub ortho_classes: Image,
    /// Raw → rectified homographies of the two views.
    pub rectify_left: Homography,
    pub rectify_right: Homography,
    /// Raw-image cameras (exactly affine: degree-1 RPCs).
    pub camera_left: AffineCamera,
    pub camera_right: AffineCamera,
    pub geo: GeoFrame,
    /// Name of the appearance model that coloured the images.
    pub appearance: String,
}

impl World {
    /// Integer disparity search range guaranteed to contain every true disparity
    /// ([`WorldParams::disparity_range`]).
    pub fn disparity_range(&self) -> (i32, i32) {
        self.params.disparity_range()
    }

    /// Altitudes of the scene, metres ([`WorldParams::altitude_range`]).
    pub fn altitude_range(&self) -> (f64, f64) {
        self.params.altitude_range()
    }

    /// One raw camera of the world (its left or right one) as a SatNeRF/rpcm JSON named `id`: a
    /// degree-1 RPC valid over the world's footprint (with a 20 % margin) and its altitudes.
    pub fn camera_json(&self, camera: &AffineCamera, id: &str) -> serde_json::Value {
        let (w, h) = self.disparity.size();
        let (lon_c, lat_c) = self.geo.lonlat(w as f64 / 2.0, h as f64 / 2.0);
        let (lon_0, lat_0) = self.geo.lonlat(0.0, 0.0);
        let half = ((lon_c - lon_0).abs() * 1.2, (lat_c - lat_0).abs() * 1.2);
        camera.to_satnerf_json(id, w, h, (lon_c, lat_c), half, self.altitude_range())
    }
}

/// Generates the world described by `params`, coloured by `appearance`; `progress(rows_done, rows)`
/// is called as rows complete.
pub fn generate(
    params: &WorldParams,
    appearance: &dyn Appearance,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<World, String> {
    params.check()?;
    let (w, h) = (params.width, params.height);
    let extent = Extent::of(params);
    let light = Lighting::from_angles(
        params.sun_elevation_deg,
        params.sun_azimuth_deg,
        params.ambient,
    );
    let scene = extent.scene(params);
    let shadows = extent.shadows(&scene, h, &light);
    let step = 1.0 / params.supersample as f64;
    let renderer = RowRenderer {
        scene: &scene,
        shadows: &shadows,
        appearance,
        light: &light,
        left: &params.left,
        right: &params.right,
        width: w,
        x_lo: extent.x_lo,
        step,
        samples: ((extent.x_hi - extent.x_lo) / step).round() as usize,
    };
    let rows = render_rows(&renderer, h, progress);

    let seed = params.scene.seed;
    let left_rows: Vec<&RowView> = rows.iter().map(|r| &r.left).collect();
    let right_rows: Vec<&RowView> = rows.iter().map(|r| &r.right).collect();
    let left = View::from_rows(&left_rows, w, seed ^ 0x1EF7, params.noise_dn);
    let right = View::from_rows(&right_rows, w, seed ^ 0x2167, params.noise_dn);
    let disparity = truth_image(w, h, rows.iter().flat_map(|r| r.disparity.iter().copied()));
    let occluded = Mask::new(
        w,
        h,
        rows.iter()
            .flat_map(|r| r.occluded.iter().copied())
            .collect(),
    )
    .expect("sizes match");
    let (ortho_height, ortho_classes) = ortho_truth(&scene, w, h);

    let geo = GeoFrame {
        lon0: params.lon0,
        lat0: params.lat0,
        gsd: params.scene.gsd,
    };
    let (rectify_left, rectify_right) = rectifying_homographies(seed, w, h);
    Ok(World {
        camera_left: AffineCamera::from_view(&params.left, &geo, &rectify_left),
        camera_right: AffineCamera::from_view(&params.right, &geo, &rectify_right),
        params: params.clone(),
        left,
        right,
        disparity,
        occluded,
        ortho_height,
        ortho_classes,
        rectify_left,
        rectify_right,
        geo,
        appearance: appearance.name().to_string(),
    })
}

/// The ground the renderer needs: the image columns plus a margin holding every point a view can
/// see up to the scene's highest altitude, and around it a pad from which shadows can fall in.
struct Extent {
    x_lo: f64,
    x_hi: f64,
    /// Highest altitude any surface can have, metres.
    max_z: f64,
    /// Ground pixels beyond the margin whose obstacles can shadow the image (sun-dependent).
    shadow_pad: f64,
}

impl Extent {
    fn of(params: &WorldParams) -> Self {
        let max_slope = params.left.slope.abs().max(params.right.slope.abs());
        let max_z = params.altitude_range().1;
        let margin =
            (max_slope * max_z + params.left.offset.abs().max(params.right.offset.abs()) + 4.0)
                .ceil();
        let shadow_pad = (max_z / params.sun_elevation_deg.to_radians().tan() / params.scene.gsd)
            .ceil()
            .min(400.0);
        Extent {
            x_lo: -margin,
            x_hi: params.width as f64 + margin,
            max_z,
            shadow_pad,
        }
    }

    /// The scene laid out over the extent and its shadow pad.
    fn scene(&self, params: &WorldParams) -> Scene {
        let pad = self.shadow_pad;
        Scene::new(
            params.scene.clone(),
            self.x_lo - pad,
            self.x_hi + pad,
            -pad,
            params.height as f64 + pad,
        )
    }

    /// The shadow grid over the extent and its pad, for an image `height` rows tall.
    fn shadows(&self, scene: &Scene, height: usize, light: &Lighting) -> ShadowGrid {
        let pad = self.shadow_pad;
        ShadowGrid::new(
            scene,
            (self.x_lo - pad, -pad),
            (
                (self.x_hi - self.x_lo + 2.0 * pad).ceil() as usize,
                height + 2 * pad as usize,
            ),
            light,
            self.max_z,
        )
    }
}

/// Renders the `height` rows in parallel, reporting each finished row to `progress`.
fn render_rows(
    renderer: &RowRenderer,
    height: usize,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Vec<RowOut> {
    let done = std::sync::atomic::AtomicUsize::new(0);
    (0..height)
        .into_par_iter()
        .map(|row| {
            let out = renderer.render(row);
            let k = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            progress(k, height);
            out
        })
        .collect()
}

impl View {
    /// One view assembled from its rendered rows (`width` pixels each); the sensor noise is
    /// drawn from `noise_seed`.
    fn from_rows(rows: &[&RowView], width: usize, noise_seed: u64, noise_dn: f32) -> View {
        let height = rows.len();
        View {
            image: sensor_image(rows, width, noise_seed, noise_dn),
            height: truth_image(
                width,
                height,
                rows.iter().flat_map(|r| r.truth.iter().map(|t| t.0)),
            ),
            classes: truth_image(
                width,
                height,
                rows.iter().flat_map(|r| r.truth.iter().map(|t| t.1 as f32)),
            ),
        }
    }
}

/// Digital numbers as the sensor records the rows' radiance: scaled, with Gaussian noise whose
/// stream is keyed by (seed, pixel) so that it does not depend on the rendering order.
fn sensor_image(rows: &[&RowView], width: usize, noise_seed: u64, noise_dn: f32) -> Image {
    let mut data = Vec::with_capacity(width * rows.len() * 3);
    for (row, r) in rows.iter().enumerate() {
        for (x, c) in r.pixels.iter().enumerate() {
            let mut rng = noise::Stream::new(noise::hash2(noise_seed, x as i64, row as i64));
            for v in c {
                let dn = 255.0 * 1.1 * v + noise_dn * rng.normal() as f32;
                data.push(dn.round().clamp(0.0, 255.0));
            }
        }
    }
    Image::new(width, rows.len(), 3, data).expect("sizes match")
}

/// A one-channel truth image from its values in row order.
fn truth_image(width: usize, height: usize, values: impl Iterator<Item = f32>) -> Image {
    Image::new(width, height, 1, values.collect()).expect("sizes match")
}

/// Altitude and classes seen straight down on the ground grid (the orthophoto truth).
fn ortho_truth(scene: &Scene, w: usize, h: usize) -> (Image, Image) {
    let ortho: Vec<Surface> = (0..h)
        .into_par_iter()
        .flat_map_iter(|y| (0..w).map(move |x| scene.surface(x as f64, y as f64)))
        .collect();
    (
        truth_image(w, h, ortho.iter().map(|s| s.height)),
        truth_image(w, h, ortho.iter().map(|s| s.class as f32)),
    )
}

/// Raw → rectified homographies of the left and right views, drawn from the seed. Raw images are
/// rotated by a few degrees and shifted: raw → rectified is the inverse motion.
fn rectifying_homographies(seed: u64, w: usize, h: usize) -> (Homography, Homography) {
    let mut rng = noise::Stream::new(seed ^ 0x4E0);
    let mut rectifying = || {
        let a = rng.range(-4.0, 4.0f64).to_radians();
        let (tx, ty) = (rng.range(-15.0, 15.0), rng.range(-15.0, 15.0));
        let (cx, cy) = (w as f64 / 2.0, h as f64 / 2.0);
        let (c, s) = (a.cos(), a.sin());
        Homography([
            [c, -s, cx - c * cx + s * cy + tx],
            [s, c, cy - s * cx - c * cy + ty],
            [0.0, 0.0, 1.0],
        ])
    };
    let left = rectifying();
    (left, rectifying())
}

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
pub mod noise;
pub mod render;
pub mod scene;

use rayon::prelude::*;

pub use appearance::{Appearance, Lighting, Neutral};
pub use camera::{AffineCamera, GeoFrame, ViewCamera};
use raster::{Homography, Image, Mask};
use render::{point_at, rasterise, span_at, visible_spans, Piece, Profile, Span};
pub use scene::{Scene, SceneParams, Surface};

/// OpenEarthMap class ids, as used by the SegFormer masks of the method.
pub mod class {
    pub const BACKGROUND: u8 = 0;
    pub const BARELAND: u8 = 1;
    pub const RANGELAND: u8 = 2;
    pub const DEVELOPED: u8 = 3;
    pub const ROAD: u8 = 4;
    pub const TREE: u8 = 5;
    pub const WATER: u8 = 6;
    pub const AGRICULTURE: u8 = 7;
    pub const BUILDING: u8 = 8;
    /// Names indexed by id.
    pub const NAMES: [&str; 9] = [
        "background",
        "bareland",
        "rangeland",
        "developed space",
        "road",
        "tree",
        "water",
        "agriculture land",
        "building",
    ];
}

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
        let scene_max = self.scene.relief_m + scene::MAX_OBJECT_HEIGHT_M + 1.0;
        let (a, b) = (self.disparity_at(-1.0), self.disparity_at(scene_max));
        (a.min(b).floor() as i32, a.max(b).ceil() as i32)
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
}

/// Output of one rendered row.
struct RowOut {
    left: Vec<[f32; 3]>,
    right: Vec<[f32; 3]>,
    left_truth: Vec<(f32, u8)>,
    right_truth: Vec<(f32, u8)>,
    disparity: Vec<f32>,
    occluded: Vec<bool>,
}

/// Where the sun's shadows fall: for every cell of a 1-pixel grid around the image, the altitude
/// below which a point there is in shadow (the highest sun ray grazing an obstacle towards the sun).
/// One march per cell instead of one per sample makes large worlds cheap to light.
struct ShadowGrid {
    x0: f64,
    y0: f64,
    width: usize,
    height: usize,
    threshold: Vec<f32>,
}

impl ShadowGrid {
    fn new(
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
    fn shadowed(&self, x: f64, y: f64, z: f64) -> bool {
        let (i, j) = ((x - self.x0).round(), (y - self.y0).round());
        if i < 0.0 || j < 0.0 || i >= self.width as f64 || j >= self.height as f64 {
            return false;
        }
        self.threshold[j as usize * self.width + i as usize] as f64 > z + 0.05
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
    let gsd = params.scene.gsd;
    let max_slope = params.left.slope.abs().max(params.right.slope.abs());
    let max_z = params.scene.relief_m + scene::MAX_OBJECT_HEIGHT_M + 1.0;
    let margin =
        (max_slope * max_z + params.left.offset.abs().max(params.right.offset.abs()) + 4.0).ceil();
    let (x_lo, x_hi) = (-margin, w as f64 + margin);
    let light = Lighting::from_angles(
        params.sun_elevation_deg,
        params.sun_azimuth_deg,
        params.ambient,
    );
    let shadow_pad = (max_z / params.sun_elevation_deg.to_radians().tan() / gsd)
        .ceil()
        .min(400.0);
    let scene = Scene::new(
        params.scene.clone(),
        x_lo - shadow_pad,
        x_hi + shadow_pad,
        -shadow_pad,
        h as f64 + shadow_pad,
    );

    let grid = ShadowGrid::new(
        &scene,
        (x_lo - shadow_pad, -shadow_pad),
        (
            (x_hi - x_lo + 2.0 * shadow_pad).ceil() as usize,
            h + 2 * shadow_pad as usize,
        ),
        &light,
        max_z,
    );
    let step = 1.0 / params.supersample as f64;
    let n = ((x_hi - x_lo) / step).round() as usize;
    let done = std::sync::atomic::AtomicUsize::new(0);
    let rows: Vec<RowOut> = (0..h)
        .into_par_iter()
        .map(|row| {
            let y = row as f64;
            let surfaces: Vec<Surface> = (0..n)
                .map(|k| scene.surface(x_lo + (k as f64 + 0.5) * step, y))
                .collect();
            let colours: Vec<[f32; 3]> = surfaces
                .iter()
                .enumerate()
                .map(|(k, s)| {
                    let x = x_lo + (k as f64 + 0.5) * step;
                    let shadow = grid.shadowed(x, y, s.height as f64);
                    let normal = s.normal.map(|v| v as f64);
                    appearance.surface(s, light.direct(normal, shadow), light.ambient)
                })
                .collect();
            let profile = Profile::new(x_lo, step, &surfaces, &colours);
            let render_view = |cam: &ViewCamera| {
                let spans = visible_spans(&profile, cam);
                let facing = [-cam.slope.signum(), 0.0, 0.0];
                let wall_direct = light.direct(facing, false);
                let pixels = rasterise(&profile, cam, &spans, w, |owner, foot, z| {
                    let above = (z - surfaces[foot].height as f64) as f32;
                    appearance.wall(&surfaces[owner], above, wall_direct, light.ambient)
                });
                (spans, pixels)
            };
            let (left_spans, left_px) = render_view(&params.left);
            let (right_spans, right_px) = render_view(&params.right);
            let truth = |cam: &ViewCamera, spans: &[Span]| -> Vec<Option<(f64, f64, u8)>> {
                (0..w)
                    .map(|u| {
                        let i = span_at(spans, u as f64)?;
                        let (x, z) = point_at(&profile, cam, &spans[i], u as f64);
                        let class = match spans[i].piece {
                            Piece::Flat(k) => surfaces[k].class,
                            Piece::Wall { owner, .. } => surfaces[owner].class,
                        };
                        Some((x, z, class))
                    })
                    .collect()
            };
            let left_truth = truth(&params.left, &left_spans);
            let right_truth = truth(&params.right, &right_spans);
            let mut disparity = Vec::with_capacity(w);
            let mut occluded = Vec::with_capacity(w);
            for (u, t) in left_truth.iter().enumerate() {
                let Some((x, z, _)) = *t else {
                    disparity.push(f32::NAN);
                    occluded.push(true);
                    continue;
                };
                let ur = params.right.column(x, z);
                disparity.push((u as f64 - ur) as f32);
                let seen = ur >= -0.5
                    && ur < w as f64 - 0.5
                    && span_at(&right_spans, ur).is_some_and(|i| {
                        let (xr, zr) = point_at(&profile, &params.right, &right_spans[i], ur);
                        (xr - x).abs() < 1e-4 && (zr - z).abs() < 1e-4
                    });
                occluded.push(!seen);
            }
            let pack = |t: Vec<Option<(f64, f64, u8)>>| {
                t.into_iter()
                    .map(|v| v.map_or((f32::NAN, class::BACKGROUND), |(_, z, c)| (z as f32, c)))
                    .collect()
            };
            let k = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            progress(k, h);
            RowOut {
                left: left_px,
                right: right_px,
                left_truth: pack(left_truth),
                right_truth: pack(right_truth),
                disparity,
                occluded,
            }
        })
        .collect();

    let seed = params.scene.seed;
    let sensor = |which: u64, px: &dyn Fn(&RowOut) -> &Vec<[f32; 3]>| -> Image {
        let mut data = Vec::with_capacity(w * h * 3);
        for (row, r) in rows.iter().enumerate() {
            for (x, c) in px(r).iter().enumerate() {
                let mut rng = noise::Stream::new(noise::hash2(seed ^ which, x as i64, row as i64));
                for v in c {
                    let dn = 255.0 * 1.1 * v + params.noise_dn * rng.normal() as f32;
                    data.push(dn.round().clamp(0.0, 255.0));
                }
            }
        }
        Image::new(w, h, 3, data).expect("sizes match")
    };
    let truth_image = |f: &dyn Fn(&RowOut) -> Vec<f32>| -> Image {
        Image::new(w, h, 1, rows.iter().flat_map(f).collect()).expect("sizes match")
    };
    let left = View {
        image: sensor(0x1EF7, &|r| &r.left),
        height: truth_image(&|r| r.left_truth.iter().map(|t| t.0).collect()),
        classes: truth_image(&|r| r.left_truth.iter().map(|t| t.1 as f32).collect()),
    };
    let right = View {
        image: sensor(0x2167, &|r| &r.right),
        height: truth_image(&|r| r.right_truth.iter().map(|t| t.0).collect()),
        classes: truth_image(&|r| r.right_truth.iter().map(|t| t.1 as f32).collect()),
    };
    let disparity = truth_image(&|r| r.disparity.clone());
    let occluded = Mask::new(
        w,
        h,
        rows.iter()
            .flat_map(|r| r.occluded.iter().copied())
            .collect(),
    )
    .expect("sizes match");

    let ortho: Vec<Surface> = (0..h)
        .into_par_iter()
        .flat_map_iter(|y| {
            let scene = &scene;
            (0..w).map(move |x| scene.surface(x as f64, y as f64))
        })
        .collect();
    let ortho_height =
        Image::new(w, h, 1, ortho.iter().map(|s| s.height).collect()).expect("sizes match");
    let ortho_classes =
        Image::new(w, h, 1, ortho.iter().map(|s| s.class as f32).collect()).expect("sizes match");

    let geo = GeoFrame {
        lon0: params.lon0,
        lat0: params.lat0,
        gsd,
    };
    let mut rng = noise::Stream::new(seed ^ 0x4E0);
    let mut rectifying = || {
        // Raw images are rotated by a few degrees and shifted: raw → rectified is the inverse motion.
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
    let rectify_left = rectifying();
    let rectify_right = rectifying();
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

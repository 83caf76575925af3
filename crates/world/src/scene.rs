//! The 2.5D scene: terrain, an optional river, and a rotated street grid whose blocks hold houses with
//! pitched roofs, flat-roofed commercial buildings, parks with trees and ponds, fields and bare land.
//! The scene is analytic: [`Scene::surface`] answers "what is at ground point (x, y)" at any
//! resolution, so both views are rendered from exactly the same geometry.

use crate::class;
use crate::noise::{fbm, hash2, unit, value_noise, Stream};

/// Scene parameters (lengths in ground pixels unless stated).
#[derive(Clone, Debug, PartialEq)]
pub struct SceneParams {
    pub seed: u64,
    /// Ground sampling distance, metres per pixel.
    pub gsd: f64,
    /// Amplitude of the terrain relief, metres.
    pub relief_m: f64,
    /// Street-grid pitch (block + road), pixels.
    pub block_pitch: f64,
    /// Road width, pixels.
    pub road_width: f64,
    /// Probability that a river crosses the scene.
    pub river_probability: f64,
}

impl Default for SceneParams {
    fn default() -> Self {
        Self {
            seed: 1,
            gsd: 0.5,
            relief_m: 6.0,
            block_pitch: 84.0,
            road_width: 12.0,
            river_probability: 0.6,
        }
    }
}

/// Highest point the generator can produce above the terrain, metres (tallest building and rooftop box).
pub const MAX_OBJECT_HEIGHT_M: f64 = 50.0;

/// What the ground is at one point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Surface {
    /// Altitude, metres.
    pub height: f32,
    /// OpenEarthMap class id (see [`crate::class`]).
    pub class: u8,
    /// Base reflectance in [0, 1], texture included.
    pub albedo: [f32; 3],
    /// Reflectance of a wall rising from this point (facades for buildings).
    pub facade: [f32; 3],
    /// Unit normal (x east, y south, z up).
    pub normal: [f32; 3],
    /// A texture value in [0, 1] an appearance model may use (snow patches, leaf density).
    pub texture: f32,
}

#[derive(Clone, Debug)]
struct Building {
    /// Footprint in the grid frame, pixels.
    p0: f64,
    q0: f64,
    p1: f64,
    q1: f64,
    base_m: f64,
    eave_m: f64,
    ridge_m: f64,
    ridge_along_p: bool,
    roof: [f32; 3],
    facade: [f32; 3],
    id: u64,
}

#[derive(Clone, Debug)]
struct Tree {
    p: f64,
    q: f64,
    radius: f64,
    base_m: f64,
    crown_m: f64,
    id: u64,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum BlockKind {
    Residential,
    Commercial,
    Park,
    Field,
    Bare,
}

impl BlockKind {
    /// The kind of a new block: mostly houses and commercial buildings, some parks and fields.
    fn draw(rng: &mut Stream) -> Self {
        match rng.next_unit() {
            r if r < 0.45 => BlockKind::Residential,
            r if r < 0.72 => BlockKind::Commercial,
            r if r < 0.86 => BlockKind::Park,
            r if r < 0.95 => BlockKind::Field,
            _ => BlockKind::Bare,
        }
    }

    /// `ground` covered as this kind of block covers its open land (grass, parking lots with
    /// painted stalls, crop rows, bare soil), at position `(lp, lq)` within the grid cell.
    fn cover(self, ground: Surface, (lp, lq): (f64, f64), tex: &Texture) -> Surface {
        let fine = tex.fine;
        match self {
            BlockKind::Residential | BlockKind::Park => Surface {
                class: class::RANGELAND,
                albedo: vary(
                    [0.20, 0.33, 0.13],
                    (0.6 * tex.broad(8.0) + 0.4 * fine).min(1.0),
                    0.7,
                ),
                texture: tex.broad(8.0),
                ..ground
            },
            BlockKind::Commercial => {
                let stall = lp.rem_euclid(6.0) < 0.4 && lq.rem_euclid(20.0) > 8.0;
                Surface {
                    class: class::DEVELOPED,
                    albedo: if stall {
                        [0.80, 0.80, 0.78]
                    } else {
                        vary([0.36, 0.36, 0.37], fine, 0.35)
                    },
                    ..ground
                }
            }
            BlockKind::Field => {
                let rows = (lp * 0.9).sin() * 0.5 + 0.5;
                Surface {
                    class: class::AGRICULTURE,
                    albedo: vary(
                        [0.40, 0.42, 0.20],
                        (0.5 * rows as f32 + 0.5 * fine).min(1.0),
                        0.6,
                    ),
                    texture: rows as f32,
                    ..ground
                }
            }
            BlockKind::Bare => ground,
        }
    }
}

#[derive(Clone, Debug)]
struct Block {
    kind: BlockKind,
    buildings: Vec<Building>,
    trees: Vec<Tree>,
    /// Pond (centre p, q and radius) in parks.
    pond: Option<(f64, f64, f64)>,
}

#[derive(Clone, Debug)]
struct River {
    cos: f64,
    sin: f64,
    offset: f64,
    amplitude: f64,
    wavelength: f64,
    phase: f64,
    half_width: f64,
}

impl River {
    /// Signed distance (pixels, approximately) from the river's centre line.
    fn distance(&self, x: f64, y: f64) -> f64 {
        let a = self.cos * x + self.sin * y;
        let b = -self.sin * x + self.cos * y;
        (b - self.offset - self.amplitude * (a / self.wavelength + self.phase).sin()).abs()
    }
}

/// A generated scene over a rectangle of the ground plane.
pub struct Scene {
    params: SceneParams,
    centre: (f64, f64),
    cos: f64,
    sin: f64,
    river: Option<River>,
    block_i0: i64,
    block_j0: i64,
    blocks_i: usize,
    blocks_j: usize,
    blocks: Vec<Block>,
}

const ROOF_COLOURS: [[f32; 3]; 6] = [
    [0.55, 0.27, 0.20],
    [0.42, 0.42, 0.44],
    [0.70, 0.69, 0.66],
    [0.30, 0.30, 0.33],
    [0.50, 0.40, 0.32],
    [0.62, 0.58, 0.50],
];
const FACADE_COLOURS: [[f32; 3]; 4] = [
    [0.72, 0.68, 0.60],
    [0.60, 0.60, 0.62],
    [0.66, 0.55, 0.45],
    [0.80, 0.78, 0.74],
];
const WATER_LEVEL_M: f64 = 0.0;
const BANK_RISE_M: f64 = 0.6;

impl Scene {
    /// Lays out a scene covering ground x in [x0, x1], y in [y0, y1] (pixels).
    pub fn new(params: SceneParams, x0: f64, x1: f64, y0: f64, y1: f64) -> Scene {
        let mut rng = Stream::new(params.seed ^ 0x5CE4E);
        let angle = rng.range(0.0, std::f64::consts::FRAC_PI_2);
        let centre = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
        let river = rng.chance(params.river_probability).then(|| {
            let a = rng.range(0.0, std::f64::consts::PI);
            River {
                cos: a.cos(),
                sin: a.sin(),
                offset: rng.range(-0.3, 0.3) * (y1 - y0),
                amplitude: rng.range(5.0, 30.0),
                wavelength: rng.range(40.0, 120.0),
                phase: rng.range(0.0, std::f64::consts::TAU),
                half_width: rng.range(8.0, 22.0),
            }
        });
        let half_diag = ((x1 - x0).hypot(y1 - y0)) / 2.0;
        let pitch = params.block_pitch;
        let block_i0 = (-half_diag / pitch).floor() as i64 - 1;
        let blocks_i = (2.0 * half_diag / pitch).ceil() as usize + 3;
        let mut scene = Scene {
            params,
            centre,
            cos: angle.cos(),
            sin: angle.sin(),
            river,
            block_i0,
            block_j0: block_i0,
            blocks_i,
            blocks_j: blocks_i,
            blocks: Vec::new(),
        };
        let mut blocks = Vec::with_capacity(blocks_i * blocks_i);
        for j in 0..blocks_i {
            for i in 0..blocks_i {
                blocks.push(scene.layout_block(block_i0 + i as i64, block_i0 + j as i64));
            }
        }
        scene.blocks = blocks;
        scene
    }

    pub fn params(&self) -> &SceneParams {
        &self.params
    }

    /// Upper bound of any altitude in the scene, metres.
    pub fn max_height_m(&self) -> f64 {
        self.params.relief_m + BANK_RISE_M + MAX_OBJECT_HEIGHT_M
    }

    fn to_grid(&self, x: f64, y: f64) -> (f64, f64) {
        let (dx, dy) = (x - self.centre.0, y - self.centre.1);
        (
            self.cos * dx + self.sin * dy,
            -self.sin * dx + self.cos * dy,
        )
    }

    fn to_ground(&self, p: f64, q: f64) -> (f64, f64) {
        (
            self.centre.0 + self.cos * p - self.sin * q,
            self.centre.1 + self.sin * p + self.cos * q,
        )
    }

    fn river_distance(&self, x: f64, y: f64) -> f64 {
        self.river.as_ref().map_or(f64::INFINITY, |r| {
            r.distance(x - self.centre.0, y - self.centre.1)
        })
    }

    /// Terrain altitude (metres) with the river valley carved in.
    fn terrain_m(&self, x: f64, y: f64) -> f64 {
        let seed = self.params.seed ^ 0x7E44;
        let hills = self.params.relief_m * fbm(seed, x / 260.0, y / 260.0, 3);
        let valley = match &self.river {
            Some(r) => {
                let t = ((self.river_distance(x, y) - r.half_width) / 60.0).clamp(0.0, 1.0);
                t * t * (3.0 - 2.0 * t)
            }
            None => 1.0,
        };
        WATER_LEVEL_M + BANK_RISE_M + hills * valley
    }

    /// Lays out block (bi, bj) of the street grid from its own random stream, so a block does
    /// not depend on which others the scene covers.
    fn layout_block(&self, bi: i64, bj: i64) -> Block {
        let key = hash2(self.params.seed ^ 0xB10C, bi, bj);
        let mut rng = Stream::new(key);
        let pitch = self.params.block_pitch;
        let inset = self.params.road_width / 2.0 + 2.0;
        let (p0, q0) = (bi as f64 * pitch + inset, bj as f64 * pitch + inset);
        let (p1, q1) = (
            (bi + 1) as f64 * pitch - inset,
            (bj + 1) as f64 * pitch - inset,
        );
        let kind = BlockKind::draw(&mut rng);
        let mut block = Block {
            kind,
            buildings: Vec::new(),
            trees: Vec::new(),
            pond: None,
        };
        let id_base = key & 0xFFFF_FFFF_0000;
        let bounds = (p0, q0, p1, q1);
        match kind {
            BlockKind::Residential => self.lay_out_houses(&mut block, &mut rng, bounds, id_base),
            BlockKind::Commercial => {
                self.lay_out_commercial(&mut block, &mut rng, bounds, id_base);
                add_plant_rooms(&mut block, &mut rng);
            }
            BlockKind::Park => self.lay_out_park(&mut block, &mut rng, bounds),
            BlockKind::Field | BlockKind::Bare => {}
        }
        self.clear_river(&mut block);
        block
    }

    /// A 2×2 grid of lots, each with a pitched-roof house near its centre and a few trees.
    fn lay_out_houses(
        &self,
        block: &mut Block,
        rng: &mut Stream,
        (p0, q0, p1, q1): (f64, f64, f64, f64),
        id_base: u64,
    ) {
        let (nx, ny) = (2, 2);
        let (lw, lh) = ((p1 - p0) / nx as f64, (q1 - q0) / ny as f64);
        for a in 0..nx {
            for b in 0..ny {
                let (lp0, lq0) = (p0 + a as f64 * lw, q0 + b as f64 * lh);
                let (w, h) = (lw * rng.range(0.45, 0.72), lh * rng.range(0.45, 0.72));
                let cp = lp0 + lw / 2.0 + rng.range(-0.1, 0.1) * lw;
                let cq = lq0 + lh / 2.0 + rng.range(-0.1, 0.1) * lh;
                block.buildings.push(self.building(
                    rng,
                    (cp - w / 2.0, cq - h / 2.0, cp + w / 2.0, cq + h / 2.0),
                    (4.0, 8.0),
                    true,
                    id_base + block.buildings.len() as u64 + 1,
                ));
                let n_trees = (rng.next_unit() * 3.0) as usize;
                for _ in 0..n_trees {
                    let (tp, tq) = (rng.range(lp0, lp0 + lw), rng.range(lq0, lq0 + lh));
                    self.push_tree(block, rng, tp, tq, (3.0, 6.0));
                }
            }
        }
    }

    /// One flat-roofed building filling the block, or two wings of different heights (an L or a
    /// step).
    fn lay_out_commercial(
        &self,
        block: &mut Block,
        rng: &mut Stream,
        (p0, q0, p1, q1): (f64, f64, f64, f64),
        id_base: u64,
    ) {
        let m = rng.range(3.0, 10.0);
        let (bp0, bq0, bp1, bq1) = (p0 + m, q0 + m, p1 - m * rng.range(0.5, 2.0), q1 - m);
        if rng.chance(0.5) {
            let split = rng.range(0.35, 0.65);
            let pm = bp0 + (bp1 - bp0) * split;
            let qm = bq0 + (bq1 - bq0) * rng.range(0.3, 0.7);
            let id = id_base + 1;
            let wing = self.building(rng, (bp0, bq0, pm, bq1), (10.0, 42.0), false, id);
            block.buildings.push(wing);
            let wing = self.building(rng, (pm, bq0, bp1, qm), (8.0, 30.0), false, id + 1);
            block.buildings.push(wing);
        } else {
            let whole = self.building(rng, (bp0, bq0, bp1, bq1), (10.0, 45.0), false, id_base + 1);
            block.buildings.push(whole);
        }
    }

    /// Sometimes a pond, and trees scattered over the block.
    fn lay_out_park(
        &self,
        block: &mut Block,
        rng: &mut Stream,
        (p0, q0, p1, q1): (f64, f64, f64, f64),
    ) {
        if rng.chance(0.4) {
            let r = rng.range(8.0, 0.3 * (p1 - p0));
            block.pond = Some((rng.range(p0 + r, p1 - r), rng.range(q0 + r, q1 - r), r));
        }
        for _ in 0..(rng.range(6.0, 18.0) as usize) {
            let (tp, tq) = (rng.range(p0, p1), rng.range(q0, q1));
            self.push_tree(block, rng, tp, tq, (4.0, 9.0));
        }
    }

    /// Removes the buildings and trees that would stand in (or too close to) the river.
    fn clear_river(&self, block: &mut Block) {
        let Some(river) = &self.river else {
            return;
        };
        let margin = 6.0;
        block.buildings.retain(|b| {
            let (x, y) = self.to_ground((b.p0 + b.p1) / 2.0, (b.q0 + b.q1) / 2.0);
            let reach = (b.p1 - b.p0).hypot(b.q1 - b.q0) / 2.0;
            self.river_distance(x, y) > river.half_width + reach + margin
        });
        block.trees.retain(|t| {
            let (x, y) = self.to_ground(t.p, t.q);
            self.river_distance(x, y) > river.half_width + t.radius + 2.0
        });
    }

    fn building(
        &self,
        rng: &mut Stream,
        (p0, q0, p1, q1): (f64, f64, f64, f64),
        height_range: (f64, f64),
        pitched: bool,
        id: u64,
    ) -> Building {
        let (cx, cy) = self.to_ground((p0 + p1) / 2.0, (q0 + q1) / 2.0);
        Building {
            p0,
            q0,
            p1,
            q1,
            base_m: self.terrain_m(cx, cy),
            eave_m: rng.range(height_range.0, height_range.1),
            ridge_m: if pitched { rng.range(1.5, 4.0) } else { 0.0 },
            ridge_along_p: (p1 - p0) >= (q1 - q0),
            roof: ROOF_COLOURS[(rng.next_unit() * ROOF_COLOURS.len() as f64) as usize],
            facade: FACADE_COLOURS[(rng.next_unit() * FACADE_COLOURS.len() as f64) as usize],
            id,
        }
    }

    fn push_tree(&self, block: &mut Block, rng: &mut Stream, p: f64, q: f64, radius_m: (f64, f64)) {
        let radius = rng.range(radius_m.0, radius_m.1) / self.params.gsd;
        let clear = block.buildings.iter().all(|b| {
            p < b.p0 - radius * 0.5
                || p > b.p1 + radius * 0.5
                || q < b.q0 - radius * 0.5
                || q > b.q1 + radius * 0.5
        });
        if clear {
            let (x, y) = self.to_ground(p, q);
            let id = hash2(self.params.seed ^ 0x7EE, p as i64, q as i64);
            block.trees.push(Tree {
                p,
                q,
                radius,
                base_m: self.terrain_m(x, y) + rng.range(2.0, 4.0),
                crown_m: rng.range(3.0, 8.0),
                id,
            });
        }
    }

    fn block(&self, p: f64, q: f64) -> Option<&Block> {
        let pitch = self.params.block_pitch;
        let i = (p / pitch).floor() as i64 - self.block_i0;
        let j = (q / pitch).floor() as i64 - self.block_j0;
        if i < 0 || j < 0 || i as usize >= self.blocks_i || j as usize >= self.blocks_j {
            return None;
        }
        Some(&self.blocks[j as usize * self.blocks_i + i as usize])
    }

    /// Converts a gradient in the grid frame (metres per pixel) to a unit normal in the ground frame.
    fn normal_from_grid_gradient(&self, dp: f64, dq: f64) -> [f32; 3] {
        let gx = (self.cos * dp - self.sin * dq) / self.params.gsd;
        let gy = (self.sin * dp + self.cos * dq) / self.params.gsd;
        let n = (gx * gx + gy * gy + 1.0).sqrt();
        [(-gx / n) as f32, (-gy / n) as f32, (1.0 / n) as f32]
    }

    /// What is at ground point (x, y) (pixels): the highest of terrain, water, buildings and trees.
    pub fn surface(&self, x: f64, y: f64) -> Surface {
        let tex = Texture::at(self.params.seed, x, y);
        // Water first: rivers and ponds are flat.
        if let Some(r) = &self.river {
            if self.river_distance(x, y) < r.half_width {
                return water(tex.fine);
            }
        }
        let (p, q) = self.to_grid(x, y);
        let block = self.block(p, q);
        if let Some((cp, cq, r)) = block.and_then(|b| b.pond) {
            if (p - cp).hypot(q - cq) < r {
                return water(tex.fine);
            }
        }
        let pitch = self.params.block_pitch;
        let local = (p.rem_euclid(pitch), q.rem_euclid(pitch));
        let ground = self.bare_ground(x, y, &tex);
        if let Some(street) = self.street(ground, local, &tex) {
            return street;
        }
        let Some(block) = block else {
            return ground;
        };
        let covered = block.kind.cover(ground, local, &tex);
        let built = block
            .buildings
            .iter()
            .fold(covered, |best, b| self.roof_over(best, b, (p, q), tex.fine));
        block
            .trees
            .iter()
            .fold(built, |best, t| self.crown_over(best, t, (x, y), (p, q)))
    }

    /// Bare soil on the terrain, its normal from forward differences (the terrain is smooth at
    /// the scale of a pixel).
    fn bare_ground(&self, x: f64, y: f64, tex: &Texture) -> Surface {
        let ground_m = self.terrain_m(x, y);
        let h = 0.5;
        let gx = (self.terrain_m(x + h, y) - ground_m) / (h * self.params.gsd);
        let gy = (self.terrain_m(x, y + h) - ground_m) / (h * self.params.gsd);
        let n = (gx * gx + gy * gy + 1.0).sqrt();
        let soil = tex.broad(20.0);
        Surface {
            height: ground_m as f32,
            class: class::BARELAND,
            albedo: vary([0.52, 0.44, 0.34], soil, 0.5),
            facade: [0.45, 0.40, 0.33],
            normal: [(-gx / n) as f32, (-gy / n) as f32, (1.0 / n) as f32],
            texture: soil,
        }
    }

    /// `ground` paved as a road (on the grid lines, with a dashed centre line) or a pavement
    /// beside one, at grid position `(lp, lq)` within its cell; `None` inside a block.
    fn street(&self, ground: Surface, (lp, lq): (f64, f64), tex: &Texture) -> Option<Surface> {
        let pitch = self.params.block_pitch;
        let half_road = self.params.road_width / 2.0;
        let dist_p = lp.min(pitch - lp);
        let dist_q = lq.min(pitch - lq);
        let street = dist_p.min(dist_q);
        if street < half_road {
            let along = if dist_p < dist_q { lq } else { lp };
            let marking = street < 0.5 && along.rem_euclid(12.0) < 6.0;
            return Some(Surface {
                class: class::ROAD,
                albedo: if marking {
                    [0.85, 0.85, 0.80]
                } else {
                    vary([0.30, 0.30, 0.31], tex.fine, 0.35)
                },
                texture: tex.fine,
                ..ground
            });
        }
        (street < half_road + 2.0).then(|| Surface {
            class: class::DEVELOPED,
            albedo: vary([0.58, 0.56, 0.52], tex.fine, 0.3),
            ..ground
        })
    }

    /// `best`, or building `b`'s roof (shingled) where that is higher at grid (p, q).
    fn roof_over(&self, best: Surface, b: &Building, (p, q): (f64, f64), fine: f32) -> Surface {
        if !(p >= b.p0 && p < b.p1 && q >= b.q0 && q < b.q1) {
            return best;
        }
        let (roof_m, dp, dq) = b.roof_height(p, q);
        let z = (b.base_m + roof_m) as f32;
        if z > best.height {
            let shingles =
                (unit(hash2(b.id, (p * 2.0) as i64, (q * 2.0) as i64)) as f32) * 0.5 + 0.5 * fine;
            Surface {
                height: z,
                class: class::BUILDING,
                albedo: vary(b.roof, shingles, 0.25),
                facade: b.facade,
                normal: self.normal_from_grid_gradient(dp, dq),
                texture: shingles,
            }
        } else {
            best
        }
    }

    /// `best`, or tree `t`'s crown (a lumpy dome whose leaves give it its texture) where that is
    /// higher at ground (x, y), grid (p, q).
    fn crown_over(
        &self,
        best: Surface,
        t: &Tree,
        (x, y): (f64, f64),
        (p, q): (f64, f64),
    ) -> Surface {
        let r2 = ((p - t.p).powi(2) + (q - t.q).powi(2)) / (t.radius * t.radius);
        let inside = r2 < 1.0;
        if !inside {
            return best;
        }
        let leaves = value_noise(t.id, x / 1.5, y / 1.5) as f32;
        let z = (t.base_m + t.crown_m * (1.0 - r2).sqrt() + 0.6 * leaves as f64) as f32;
        let higher = z > best.height;
        if !higher {
            return best;
        }
        let slope = t.crown_m / (self.params.gsd * t.radius);
        let (ux, uy) = self.to_ground_dir(p - t.p, q - t.q);
        let s = (r2.sqrt() / (1.0 - r2).sqrt().max(0.2)).min(3.0) * slope / t.radius.max(1.0);
        let (gx, gy) = (-ux * s, -uy * s);
        let n = (gx * gx + gy * gy + 1.0).sqrt();
        Surface {
            height: z,
            class: class::TREE,
            albedo: vary([0.10, 0.24, 0.08], leaves, 0.9),
            facade: [0.08, 0.18, 0.06],
            normal: [(-gx / n) as f32, (-gy / n) as f32, (1.0 / n) as f32],
            texture: leaves,
        }
    }

    fn to_ground_dir(&self, dp: f64, dq: f64) -> (f64, f64) {
        (self.cos * dp - self.sin * dq, self.sin * dp + self.cos * dq)
    }
}

impl Building {
    /// Roof height above the base (metres) and its gradient in the grid frame (metres per pixel).
    fn roof_height(&self, p: f64, q: f64) -> (f64, f64, f64) {
        if self.ridge_m == 0.0 {
            return (self.eave_m, 0.0, 0.0);
        }
        let (c, half, sign_p) = if self.ridge_along_p {
            let c = (self.q0 + self.q1) / 2.0;
            (q - c, (self.q1 - self.q0) / 2.0, false)
        } else {
            let c = (self.p0 + self.p1) / 2.0;
            (p - c, (self.p1 - self.p0) / 2.0, true)
        };
        let t = (c.abs() / half).min(1.0);
        let slope = -self.ridge_m / half * c.signum();
        let h = self.eave_m + self.ridge_m * (1.0 - t);
        if sign_p {
            (h, slope, 0.0)
        } else {
            (h, 0.0, slope)
        }
    }
}

/// Rooftop plant rooms on the block's buildings: a few boxes a little above each roof.
fn add_plant_rooms(block: &mut Block, rng: &mut Stream) {
    let roofs: Vec<Building> = block.buildings.clone();
    for roof in roofs {
        for _ in 0..(rng.next_unit() * 3.0) as usize {
            let (w, h) = (rng.range(4.0, 9.0), rng.range(4.0, 9.0));
            let cp = rng.range(roof.p0 + w, (roof.p1 - w).max(roof.p0 + w + 0.1));
            let cq = rng.range(roof.q0 + h, (roof.q1 - h).max(roof.q0 + h + 0.1));
            let mut b = roof.clone();
            (b.p0, b.q0, b.p1, b.q1) = (cp - w / 2.0, cq - h / 2.0, cp + w / 2.0, cq + h / 2.0);
            b.eave_m = roof.eave_m + rng.range(2.0, 4.0);
            b.roof = ROOF_COLOURS[(rng.next_unit() * 6.0) as usize];
            b.id = roof.id + 100 + block.buildings.len() as u64;
            block.buildings.push(b);
        }
    }
}

/// The texture fields at one ground point, from which surfaces vary their reflectance.
struct Texture {
    seed: u64,
    x: f64,
    y: f64,
    /// Pixel-scale texture in [0, 1].
    fine: f32,
}

impl Texture {
    fn at(seed: u64, x: f64, y: f64) -> Self {
        let fine = fbm(seed ^ 0xF1E, x / 3.0, y / 3.0, 3) as f32;
        Texture { seed, x, y, fine }
    }

    /// Texture whose features are about `scale` pixels wide, in [0, 1].
    fn broad(&self, scale: f64) -> f32 {
        fbm(self.seed ^ 0x7E7, self.x / scale, self.y / scale, 3) as f32
    }
}

/// Reflectance `c` scaled between `1 − amount/2` and `1 + amount/2` by texture `t`.
fn vary(c: [f32; 3], t: f32, amount: f32) -> [f32; 3] {
    c.map(|v| (v * (1.0 - amount / 2.0 + amount * t)).clamp(0.0, 1.0))
}

fn water(fine: f32) -> Surface {
    Surface {
        height: WATER_LEVEL_M as f32,
        class: class::WATER,
        albedo: [0.05 + 0.02 * fine, 0.11 + 0.03 * fine, 0.16 + 0.03 * fine],
        facade: [0.05, 0.10, 0.14],
        normal: [0.0, 0.0, 1.0],
        texture: fine,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene(seed: u64) -> Scene {
        Scene::new(
            SceneParams {
                seed,
                ..Default::default()
            },
            0.0,
            400.0,
            0.0,
            400.0,
        )
    }

    #[test]
    fn scene_has_every_kind_of_ground() {
        let mut seen = [0usize; 9];
        for seed in 1..4 {
            let s = scene(seed);
            for y in (0..400).step_by(3) {
                for x in (0..400).step_by(3) {
                    let su = s.surface(x as f64, y as f64);
                    assert!(su.height.is_finite() && su.height <= s.max_height_m() as f32);
                    assert!(su.albedo.iter().all(|v| (0.0..=1.0).contains(v)));
                    seen[su.class as usize] += 1;
                }
            }
        }
        for c in [
            class::ROAD,
            class::TREE,
            class::BUILDING,
            class::RANGELAND,
            class::DEVELOPED,
        ] {
            assert!(seen[c as usize] > 0, "class {c} never generated: {seen:?}");
        }
    }

    #[test]
    fn pitched_roof_peaks_at_the_ridge() {
        let b = Building {
            p0: 0.0,
            q0: 0.0,
            p1: 20.0,
            q1: 10.0,
            base_m: 0.0,
            eave_m: 5.0,
            ridge_m: 3.0,
            ridge_along_p: true,
            roof: [0.5; 3],
            facade: [0.5; 3],
            id: 1,
        };
        assert_eq!(b.roof_height(10.0, 5.0).0, 8.0);
        assert!((b.roof_height(10.0, 0.0).0 - 5.0).abs() < 1e-12);
        assert!(b.roof_height(3.0, 2.0).2 > 0.0 && b.roof_height(3.0, 8.0).2 < 0.0);
    }

    #[test]
    fn same_seed_same_scene() {
        let (a, b) = (scene(9), scene(9));
        for i in 0..200 {
            let (x, y) = (i as f64 * 1.7, i as f64 * 1.9);
            assert_eq!(a.surface(x, y), b.surface(x, y));
        }
    }
}

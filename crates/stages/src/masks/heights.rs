//! Heights above the local ground in an image's own frame, from the stereo the pipeline already
//! has: every rectified pair the image belongs to (`rectify` records + the teacher's
//! disparities) is triangulated through the RPCs, the points of all its pairs are gridded on one
//! 0.5 m UTM grid (median per cell), the grid's holes filled ground-first, the ground estimated
//! and the height above it projected back into the image ([`super::project`]).
//!
//! Two heights per pixel: `measured` (cells a point fell in; NaN elsewhere: stereo misses much of
//! the canopy, and a filled hole there says "ground" when it does not know) and `filled` (after
//! hole filling and a 7×7 median: complete roofs for the building rule).

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use anyhow::{bail, Context, Result};
use camera::{rasterize, DsmGrid, Gridding};
use camera::{Points, RpcModel, UtmZone};
use raster::Image;

use super::project::render_into_image;
use reconstruct::dsm::{read_camera, triangulate_files};
use reconstruct::finishing::{finish_dsm, DEFAULT_FILL_CELLS, FUSED_MEDIAN_CELLS};
use workflow::pairs::{PairFolder, RectifiedFiles, RectifyRecord};

/// Cell size of the heights grid, metres.
const RESOLUTION: f64 = 0.5;
/// The ground is the lower envelope of the DSM at this scale: an opening of 60 m removes trees
/// and most buildings (wider roofs are rare; see BENCHMARKS.md, masks).
const GROUND_WINDOW_M: f64 = 60.0;
/// Blocks of the ground estimate (cells) and the percentile taken in each: robust to the few
/// wrong low points a block's minimum would follow.
const GROUND_BLOCK: usize = 8;
const GROUND_PERCENTILE: f64 = 0.10;

/// One rectified pair with its disparity.
#[derive(Clone, Debug)]
pub struct StereoPair {
    pub stem: String,
    pub left: PathBuf,
    pub right: PathBuf,
    /// Camera files (SatNeRF JSON or the GeoTIFF itself).
    pub rpc_left: PathBuf,
    pub rpc_right: PathBuf,
    pub homography: PathBuf,
    pub disparity: PathBuf,
}

/// The pairs of a `rectify` folder that have a disparity, by raw image stem.
#[derive(Clone, Debug, Default)]
pub struct PairIndex {
    by_image: BTreeMap<String, Vec<StereoPair>>,
    /// Pairs whose disparity is missing (not matched yet).
    pub without_disparity: Vec<String>,
    /// Every pair's points are triangulated once and shared by its two images.
    cache: PointCache,
}

/// Finite points (lon, lat, alt) of a pair.
type PairPoints = Arc<Vec<[f64; 3]>>;

/// Triangulated pairs by stem, with the number of their images still to ask for them: a pair is
/// dropped when its second image has taken it (at most every pair's points held at once, in the
/// worst order; in `masks`' sorted order a few).
#[derive(Clone, Default)]
struct PointCache(Arc<Mutex<HashMap<String, (usize, PairPoints)>>>);

impl std::fmt::Debug for PointCache {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let held = self.0.lock().map(|m| m.len()).unwrap_or(0);
        write!(f, "PointCache({held} pairs held)")
    }
}

fn stem_of(path: &Path) -> String {
    path.file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("")
        .to_string()
}

impl PairIndex {
    /// Reads `pairs/rectify/*.json` (written by `rectify`); the disparity of pair `<stem>` is
    /// `disparities/<stem>.iio` (a `teacher` folder, or a `reconstruct` work folder's
    /// `disparity/`).
    pub fn read(pairs: &Path, disparities: &Path) -> Result<Self> {
        let mut index = PairIndex::default();
        for record in PairFolder::new(pairs).rectify_records()? {
            let RectifyRecord {
                stem,
                left,
                right,
                rpc_left,
                rpc_right,
                files: RectifiedFiles { homography, .. },
                ..
            } = record;
            let disparity = disparities.join(format!("{stem}.iio"));
            if !disparity.is_file() {
                index.without_disparity.push(stem);
                continue;
            }
            let pair = StereoPair {
                rpc_left: rpc_left.unwrap_or_else(|| left.clone()),
                rpc_right: rpc_right.unwrap_or_else(|| right.clone()),
                stem,
                left,
                right,
                homography,
                disparity,
            };
            for image in [&pair.left, &pair.right] {
                index
                    .by_image
                    .entry(stem_of(image))
                    .or_default()
                    .push(pair.clone());
            }
        }
        Ok(index)
    }

    /// The pairs image `stem` belongs to.
    pub fn pairs_of(&self, stem: &str) -> &[StereoPair] {
        self.by_image.get(stem).map_or(&[], Vec::as_slice)
    }

    /// The finite points of `pair`, triangulated on the first call and kept for the pair's other
    /// image (dropped after its second call).
    pub fn points(&self, pair: &StereoPair) -> Result<PairPoints> {
        let mut cache = self.cache_lock();
        if let Some((left, points)) = cache.get_mut(&pair.stem) {
            let points = points.clone();
            *left -= 1;
            if *left == 0 {
                cache.remove(&pair.stem);
            }
            return Ok(points);
        }
        drop(cache);
        let points: PairPoints = Arc::new(
            triangulate(pair)?
                .lonlatalt
                .into_iter()
                .filter(|p| p[2].is_finite())
                .collect(),
        );
        self.cache_lock()
            .insert(pair.stem.clone(), (1, points.clone()));
        Ok(points)
    }

    fn cache_lock(&self) -> std::sync::MutexGuard<'_, HashMap<String, (usize, PairPoints)>> {
        self.cache.0.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Number of pairs with a disparity.
    pub fn len(&self) -> usize {
        let mut stems: Vec<&str> = self
            .by_image
            .values()
            .flatten()
            .map(|p| p.stem.as_str())
            .collect();
        stems.sort_unstable();
        stems.dedup();
        stems.len()
    }

    pub fn is_empty(&self) -> bool {
        self.by_image.is_empty()
    }
}

/// Heights above the ground (metres) in an image's frame, NaN where unknown.
#[derive(Clone, Debug)]
pub struct ImageHeights {
    pub measured: Image,
    pub filled: Image,
    /// The pairs used.
    pub pairs: Vec<String>,
}

/// Triangulates one pair's disparity (every finite pixel whose match is inside the right image).
fn triangulate(pair: &StereoPair) -> Result<Points> {
    triangulate_files(
        &pair.disparity,
        &pair.homography,
        [&pair.rpc_left, &pair.rpc_right],
        0,
    )
}

/// The UTM grid over the image's footprint at the points' median altitude, 10 m margin.
fn footprint_grid(rpc: &RpcModel, (w, h): (usize, usize), alt: f64) -> Result<DsmGrid> {
    let zone = UtmZone::from_lonlat(rpc.lon_offset, rpc.lat_offset);
    let mut b = [
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    ];
    for (c, r) in [
        (0.0, 0.0),
        (w as f64, 0.0),
        (0.0, h as f64),
        (w as f64, h as f64),
    ] {
        let (lon, lat) = rpc.localization(c, r, alt)?;
        let (e, n) = zone.forward(lon, lat);
        b = [b[0].min(e), b[1].min(n), b[2].max(e), b[3].max(n)];
    }
    let m = 10.0;
    Ok(DsmGrid::from_bounds(
        b[0] - m,
        b[1] - m,
        b[2] + m,
        b[3] + m,
        RESOLUTION,
        zone.epsg(),
    )?)
}

/// The ground under a DSM: per block of `GROUND_BLOCK` cells a low percentile, a grey opening
/// (min then max filter) of `GROUND_WINDOW_M`, a box mean of half that, bilinear back to cells.
pub fn ground_level(dsm: &Image, resolution: f64) -> Image {
    let (w, h) = dsm.size();
    let b = GROUND_BLOCK;
    let (bw, bh) = (w.div_ceil(b), h.div_ceil(b));
    let mut blocks = vec![f32::NAN; bw * bh];
    let mut vals = Vec::with_capacity(b * b);
    for by in 0..bh {
        for bx in 0..bw {
            vals.clear();
            for y in by * b..((by + 1) * b).min(h) {
                for x in bx * b..((bx + 1) * b).min(w) {
                    let v = dsm.get(x, y, 0);
                    if v.is_finite() {
                        vals.push(v);
                    }
                }
            }
            if !vals.is_empty() {
                vals.sort_unstable_by(f32::total_cmp);
                let k = ((vals.len() - 1) as f64 * GROUND_PERCENTILE).round() as usize;
                blocks[by * bw + bx] = vals[k];
            }
        }
    }
    // Blocks without data must not pull the ground down: they take the highest block.
    let top = blocks
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .fold(f32::NAN, f32::max);
    blocks
        .iter_mut()
        .filter(|v| v.is_nan())
        .for_each(|v| *v = top);
    let r = ((GROUND_WINDOW_M / (resolution * b as f64)) as usize / 2).max(1);
    let filter = |src: &[f32], r: usize, f: fn(&[f32]) -> f32| -> Vec<f32> {
        let mut out = vec![0f32; src.len()];
        let mut win = Vec::new();
        for y in 0..bh {
            for x in 0..bw {
                win.clear();
                for yy in y.saturating_sub(r)..(y + r + 1).min(bh) {
                    win.extend_from_slice(
                        &src[yy * bw + x.saturating_sub(r)..yy * bw + (x + r + 1).min(bw)],
                    );
                }
                out[y * bw + x] = f(&win);
            }
        }
        out
    };
    let min = |w: &[f32]| w.iter().copied().fold(f32::INFINITY, f32::min);
    let max = |w: &[f32]| w.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    let mean = |w: &[f32]| w.iter().sum::<f32>() / w.len() as f32;
    let opened = filter(&filter(&blocks, r, min), r, max);
    let smooth = filter(&opened, (r / 2).max(1), mean);
    Image::from_fn(w, h, |x, y| {
        let fx = ((x as f64 + 0.5) / b as f64 - 0.5).clamp(0.0, (bw - 1) as f64);
        let fy = ((y as f64 + 0.5) / b as f64 - 0.5).clamp(0.0, (bh - 1) as f64);
        let (x0, y0) = (fx.floor() as usize, fy.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(bw - 1), (y0 + 1).min(bh - 1));
        let (tx, ty) = ((fx - x0 as f64) as f32, (fy - y0 as f64) as f32);
        let at = |x: usize, y: usize| smooth[y * bw + x];
        let top = at(x0, y0) * (1.0 - tx) + at(x1, y0) * tx;
        let bottom = at(x0, y1) * (1.0 - tx) + at(x1, y1) * tx;
        top * (1.0 - ty) + bottom * ty
    })
}

/// Heights above the ground of the `size` image `stem` from its pairs, or `None` when it is in no
/// pair. `camera` is the image's own camera file (from its pairs' records).
pub fn image_heights(
    index: &PairIndex,
    stem: &str,
    size: (usize, usize),
) -> Result<Option<ImageHeights>> {
    let pairs = index.pairs_of(stem);
    let Some(first) = pairs.first() else {
        return Ok(None);
    };
    let camera_file = if stem_of(&first.left) == stem {
        &first.rpc_left
    } else {
        &first.rpc_right
    };
    let rpc = read_camera(camera_file)?;
    let mut all = Vec::new();
    for pair in pairs {
        all.extend_from_slice(&index.points(pair)?);
    }
    if all.is_empty() {
        bail!("{stem}: its pairs' disparities triangulate to no point (all NaN?)");
    }
    let mut alts: Vec<f64> = all.iter().map(|p| p[2]).collect();
    alts.sort_unstable_by(f64::total_cmp);
    let grid = footprint_grid(&rpc, size, alts[alts.len() / 2]).with_context(|| {
        format!(
            "the ground footprint of {stem} through {}",
            camera_file.display()
        )
    })?;
    let points = Points {
        width: all.len(),
        height: 1,
        lonlatalt: all,
    };
    let measured = rasterize(&points, &grid, Gridding::Median);
    let filled = finish_dsm(
        measured.clone(),
        Some(camera::HoleFill::spanning(DEFAULT_FILL_CELLS)),
        Some(FUSED_MEDIAN_CELLS),
    )?;
    let ground = ground_level(&filled, RESOLUTION);
    let above = |dsm: &Image| {
        let data = dsm
            .data()
            .iter()
            .zip(ground.data())
            .map(|(a, g)| a - g)
            .collect();
        Image::new(dsm.width(), dsm.height(), 1, data).expect("same grid")
    };
    let depth = Image::from_fn(grid.width, grid.height, |x, y| {
        let f = filled.get(x, y, 0);
        if f.is_finite() {
            f
        } else {
            measured.get(x, y, 0)
        }
    });
    let rendered = render_into_image(
        &depth,
        &[&above(&measured), &above(&filled)],
        &grid,
        &rpc,
        size,
    );
    Ok(Some(ImageHeights {
        measured: rendered.channel(0),
        filled: rendered.channel(1),
        pairs: pairs.iter().map(|p| p.stem.clone()).collect(),
    }))
}

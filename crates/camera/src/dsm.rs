//! DSM gridding as the benchmark does it: ground points projected to the ground truth's UTM grid,
//! floored to a cell, highest point per cell, NaN where no point falls.

use std::path::Path;

use raster::formats::{read_tiff, GeoRaster, GeoReference, GeoTiffMeta};
use raster::Image;
use rayon::prelude::*;

use crate::{Band, CameraError, Crs, Points, Result, UtmZone};

/// A north-up grid of square cells in a map projection (UTM by default, any EPSG code): cell
/// (col, row) covers x (eastings) [x0 + col·res, x0 + (col+1)·res) and y (northings)
/// (y0 − (row+1)·res, y0 − row·res].
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct DsmGrid {
    /// Easting (x) of the west edge, in the CRS's units (metres, or degrees of longitude).
    pub x0: f64,
    /// Northing (y) of the north edge, in the CRS's units.
    pub y0: f64,
    /// Cell size, in the CRS's units.
    pub resolution: f64,
    pub width: usize,
    pub height: usize,
    /// EPSG code of the CRS (WGS84/UTM 326zz or 327zz by default).
    pub epsg: u32,
}

impl DsmGrid {
    /// A grid, checked: positive finite resolution, non-empty, a known EPSG code.
    pub fn new(
        x0: f64,
        y0: f64,
        resolution: f64,
        width: usize,
        height: usize,
        epsg: u32,
    ) -> Result<Self> {
        if !(resolution.is_finite() && resolution > 0.0) {
            return Err(CameraError::Input(format!(
                "DSM resolution must be positive, got {resolution}"
            )));
        }
        if !(x0.is_finite() && y0.is_finite()) {
            return Err(CameraError::Input("DSM origin must be finite".into()));
        }
        if width == 0 || height == 0 || width > 1 << 20 || height > 1 << 20 {
            return Err(CameraError::Input(format!(
                "DSM size {width}x{height} is empty or too large"
            )));
        }
        Crs::from_epsg(epsg)?;
        Ok(DsmGrid {
            x0,
            y0,
            resolution,
            width,
            height,
            epsg,
        })
    }

    /// The grid covering [x_min, x_max] × [y_min, y_max] (the CRS's units) at `resolution`.
    pub fn from_bounds(
        x_min: f64,
        y_min: f64,
        x_max: f64,
        y_max: f64,
        resolution: f64,
        epsg: u32,
    ) -> Result<Self> {
        if !(x_max > x_min && y_max > y_min) {
            return Err(CameraError::Input(format!(
                "empty DSM bounds [{x_min}, {x_max}] × [{y_min}, {y_max}]"
            )));
        }
        let cells = |extent: f64| ((extent / resolution).ceil().max(1.0)) as usize;
        DsmGrid::new(
            x_min,
            y_max,
            resolution,
            cells(x_max - x_min),
            cells(y_max - y_min),
            epsg,
        )
    }

    /// The grid of a georeferenced raster of `width` × `height` pixels: north-up, square cells,
    /// an EPSG code.
    pub fn from_georeference(georef: &GeoReference, width: usize, height: usize) -> Result<Self> {
        let gt = georef.geotransform;
        if gt[2] != 0.0 || gt[4] != 0.0 {
            return Err(CameraError::Georeference(format!(
                "rotated or sheared georeference {gt:?}: the DSM grid must be north-up"
            )));
        }
        if !(gt[1] > 0.0 && gt[5] < 0.0) {
            return Err(CameraError::Georeference(format!(
                "georeference {gt:?} is not north-up with eastward columns"
            )));
        }
        if ((gt[1] + gt[5]) / gt[1]).abs() > 1e-9 {
            return Err(CameraError::Georeference(format!(
                "non-square cells {} × {} m",
                gt[1], -gt[5]
            )));
        }
        let epsg = georef
            .epsg
            .ok_or_else(|| CameraError::Georeference("the georeference has no EPSG code".into()))?;
        DsmGrid::new(gt[0], gt[3], gt[1], width, height, epsg)
    }

    /// The grid of a raster read with [`read_tiff`]; an error if it is not georeferenced.
    pub fn of_raster(raster: &GeoRaster, origin: &str) -> Result<Self> {
        let georef = raster.georef.as_ref().ok_or_else(|| {
            CameraError::Georeference(format!("{origin}: the raster has no georeference"))
        })?;
        let (w, h) = raster.image.size();
        Self::from_georeference(georef, w, h).map_err(|e| match e {
            CameraError::Georeference(m) => CameraError::Georeference(format!("{origin}: {m}")),
            e => e,
        })
    }

    /// The grid of a (ground-truth) DSM GeoTIFF.
    pub fn read_geotiff(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        Self::of_raster(&read_tiff(path)?, &path.display().to_string())
    }

    /// The grid of a DSM file as users have it: a GeoTIFF, or a plain TIFF whose DFC2019
    /// georeference sits beside it ([`read_dsm`]).
    pub fn read(path: impl AsRef<Path>, zone: Option<UtmZone>) -> Result<Self> {
        Ok(read_dsm(path, zone)?.grid)
    }

    /// The grid described by a DFC2019 `<AOI>_DSM.txt` (four numbers: lower-left easting and
    /// northing, size in cells, cell size) for a raster of `width × height` cells in `zone`. The
    /// upper-left corner of cell (0, 0) is `(E, N + size·res)`.
    pub fn from_dfc_txt(
        text: &str,
        origin: &str,
        width: usize,
        height: usize,
        zone: UtmZone,
    ) -> Result<Self> {
        let values: Vec<f64> = text
            .split_whitespace()
            .map(|t| t.parse::<f64>())
            .collect::<std::result::Result<_, _>>()
            .map_err(|e| {
                CameraError::Georeference(format!(
                    "{origin}: not a DFC2019 georeference (four numbers \"E N size res\"): {e}"
                ))
            })?;
        let [e, n, size, res] = values[..] else {
            return Err(CameraError::Georeference(format!(
                "{origin}: a DFC2019 georeference has four numbers (E N size res), found {}",
                values.len()
            )));
        };
        if size.fract() != 0.0 || size as usize != height {
            return Err(CameraError::Georeference(format!(
                "{origin}: says {size} cells but the DSM has {height} rows"
            )));
        }
        DsmGrid::new(e, n + size * res, res, width, height, zone.epsg())
            .map_err(|err| CameraError::Georeference(format!("{origin}: {err}")))
    }

    /// The grid's UTM zone, when its CRS is one (what a DFC2019 `.txt` georeference lacks).
    pub fn zone(&self) -> Option<UtmZone> {
        self.crs().utm_zone()
    }

    /// The UTM zone of the grid, or of its centre when its CRS is not UTM: the zone a DFC2019
    /// `.txt` georeference of the same area is in.
    pub fn nearest_zone(&self) -> UtmZone {
        self.zone().unwrap_or_else(|| {
            let (lon, lat) = self.centre_lonlat();
            UtmZone::from_lonlat(lon, lat)
        })
    }

    /// WGS84 (lon, lat) of the centre of the grid's middle cell: where a scale of the CRS or a
    /// zone is taken for the whole grid.
    pub fn centre_lonlat(&self) -> (f64, f64) {
        let (x, y) = self.cell_centre(self.width / 2, self.height / 2);
        self.crs().inverse(x, y)
    }

    /// Refuses a DSM image that is not one channel of the grid's size, naming `origin` (the
    /// file it is for).
    pub fn check_heights(&self, image: &Image, origin: &str) -> Result<()> {
        if image.size() == (self.width, self.height) && image.channels() == 1 {
            return Ok(());
        }
        Err(CameraError::Input(format!(
            "{origin}: the DSM is {}x{}x{} but its grid is {}x{}",
            image.width(),
            image.height(),
            image.channels(),
            self.width,
            self.height
        )))
    }

    /// The grid's map projection.
    pub fn crs(&self) -> &'static Crs {
        Crs::from_epsg(self.epsg).expect("checked at construction")
    }

    /// The (x, y) of the centre of cell (col, row).
    #[inline]
    pub fn cell_centre(&self, col: usize, row: usize) -> (f64, f64) {
        (
            self.x0 + (col as f64 + 0.5) * self.resolution,
            self.y0 - (row as f64 + 0.5) * self.resolution,
        )
    }

    /// The GDAL-style georeference to write the grid with.
    pub fn georeference(&self) -> GeoReference {
        GeoReference::from_origin_utm(self.x0, self.y0, self.resolution, self.epsg)
    }

    /// The (col, row) of the cell containing (easting, northing): floor, as the benchmark.
    #[inline]
    pub fn cell_of(&self, easting: f64, northing: f64) -> Option<(usize, usize)> {
        let c = ((easting - self.x0) / self.resolution).floor();
        let r = ((self.y0 - northing) / self.resolution).floor();
        (c >= 0.0 && r >= 0.0 && c < self.width as f64 && r < self.height as f64)
            .then_some((c as usize, r as usize))
    }
}

/// `555x586 cells of 0.5 m, EPSG:32617`: the grid as the log says it.
impl std::fmt::Display for DsmGrid {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{}x{} cells of {}, EPSG:{}",
            self.width,
            self.height,
            self.crs().length(self.resolution),
            self.epsg
        )
    }
}

/// The heights of `image` (lying on `from`) at the centres of the cells of `onto`: the nearest
/// cell, NaN outside `from`. For one cell size and zone this is the benchmark's crop of any DSM
/// onto the truth's window (GDAL's `projWin` snaps the window to whole cells, which is the
/// nearest cell here); across cell sizes or CRSs it is a nearest-cell resampling (through
/// longitude and latitude when the CRSs differ).
pub fn resample_nearest(image: &Image, from: &DsmGrid, onto: &DsmGrid) -> Image {
    let src = image.channel(0);
    let data = src.data();
    let (crs_from, crs_onto) = (from.crs(), onto.crs());
    let same_zone = from.epsg == onto.epsg;
    let out: Vec<f32> = (0..onto.height)
        .into_par_iter()
        .flat_map_iter(|r| {
            let northing = onto.y0 - (r as f64 + 0.5) * onto.resolution;
            (0..onto.width).map(move |c| {
                let easting = onto.x0 + (c as f64 + 0.5) * onto.resolution;
                let (e, n) = if same_zone {
                    (easting, northing)
                } else {
                    let (lon, lat) = crs_onto.inverse(easting, northing);
                    crs_from.forward(lon, lat)
                };
                from.cell_of(e, n)
                    .map_or(f32::NAN, |(col, row)| data[row * from.width + col])
            })
        })
        .collect();
    Image::new(onto.width, onto.height, 1, out).expect("one value per cell")
}

/// A DSM read from disk: heights (nodata mapped to NaN) and the grid they lie on.
#[derive(Clone, Debug)]
pub struct DsmRaster {
    pub image: Image,
    pub grid: DsmGrid,
    /// The nodata value of the file, if it declares one.
    pub nodata: Option<f64>,
}

/// The sibling DFC2019 georeference of a DSM: `X.txt` beside `X.tif`.
pub fn dfc_georeference_path(path: &Path) -> std::path::PathBuf {
    path.with_extension("txt")
}

/// Reads a DSM as users have it: a GeoTIFF (georeference and EPSG inside), or a plain TIFF with
/// its DFC2019 georeference in `X.txt` beside `X.tif` (the Data Fusion Contest 2019 truth as
/// distributed). The `.txt` has no UTM zone: `zone` gives it (the caller knows it from the
/// cameras, or the user from a flag); a GeoTIFF's own EPSG code always wins. First band only;
/// a declared nodata value becomes NaN.
pub fn read_dsm(path: impl AsRef<Path>, zone: Option<UtmZone>) -> Result<DsmRaster> {
    let path = path.as_ref();
    let origin = path.display().to_string();
    let raster = read_tiff(path)?;
    let (w, h) = raster.image.size();
    let grid = if raster.georef.is_some() {
        DsmGrid::of_raster(&raster, &origin)?
    } else {
        let txt = dfc_georeference_path(path);
        if !txt.is_file() {
            return Err(CameraError::Georeference(format!(
                "{origin}: the DSM has no georeference and no DFC2019 georeference file {} \
                 beside it (give a GeoTIFF, or the \"E N size res\" text file)",
                txt.display()
            )));
        }
        let text = std::fs::read_to_string(&txt).map_err(|e| {
            CameraError::Georeference(format!("{}: cannot read: {e}", txt.display()))
        })?;
        let Some(zone) = zone else {
            return Err(CameraError::Georeference(format!(
                "{origin}: its georeference {} has no UTM zone; give one (e.g. --utm-zone 17N) \
                 or cameras to take it from",
                txt.display()
            )));
        };
        DsmGrid::from_dfc_txt(&text, &txt.display().to_string(), w, h, zone)?
    };
    let mut image = raster.image.channel(0);
    if let Some(nd) = raster.nodata {
        for v in image.data_mut() {
            if f64::from(*v) == nd || (nd.is_nan() && v.is_nan()) {
                *v = f32::NAN;
            }
        }
    }
    Ok(DsmRaster {
        image,
        grid,
        nodata: raster.nodata,
    })
}

/// How the points falling in one DSM cell become its height.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Gridding {
    /// The highest point: the benchmark's protocol (and the right choice to compare with its
    /// numbers), but one wrong point above a roof decides the cell.
    #[default]
    Max,
    /// The median of the points (the upper one of an even count): robust to isolated wrong
    /// points, for DSMs meant to be used.
    Median,
}

/// The flat cell index and altitude of every point that falls on `grid` (projections in
/// parallel).
fn cells_of(points: &Points, grid: &DsmGrid) -> Vec<(usize, f32)> {
    cells_with(points, grid, |_, alt| alt as f32)
}

/// The flat cell index of every point that falls on `grid`, with `value(point index, altitude)`
/// (projections in parallel).
fn cells_with<T: Send>(
    points: &Points,
    grid: &DsmGrid,
    value: impl Fn(usize, f64) -> T + Sync,
) -> Vec<(usize, T)> {
    let crs = grid.crs();
    points
        .lonlatalt
        .par_iter()
        .enumerate()
        .with_min_len(4096)
        .filter_map(|(i, &[lon, lat, alt])| {
            if !(lon.is_finite() && lat.is_finite() && alt.is_finite()) {
                return None;
            }
            let (e, n) = crs.forward(lon, lat);
            grid.cell_of(e, n)
                .map(|(c, r)| (r * grid.width + c, value(i, alt)))
        })
        .collect()
}

/// The highest altitude of the points falling in each cell of `grid`, NaN where none does.
/// Projections run in parallel; the max makes the result independent of the order.
pub fn rasterize_max(points: &Points, grid: &DsmGrid) -> Image {
    rasterize(points, grid, Gridding::Max)
}

/// The points gridded on `grid` with `gridding`, NaN where no point falls. The result does not
/// depend on the order of the points.
pub fn rasterize(points: &Points, grid: &DsmGrid, gridding: Gridding) -> Image {
    let cells = cells_of(points, grid);
    let (heights, _) = grid_cells(cells, grid.width * grid.height, |i| i, gridding);
    Image::new(grid.width, grid.height, 1, heights).expect("one value per cell")
}

/// The points of one tile gridded on the part of `grid` they cover (see [`rasterize_window`]).
#[derive(Clone, Debug, PartialEq)]
pub struct GridWindow {
    /// Column and row of the window's first cell in the full grid.
    pub col: usize,
    pub row: usize,
    pub width: usize,
    pub height: usize,
    /// Height of each window cell, NaN where no point falls.
    pub heights: Vec<f32>,
    /// Number of points in each cell (saturating), what merges of overlapping windows weigh.
    pub counts: Vec<u16>,
    /// The matcher's confidence of each cell ([`rasterize_window_with`]), NaN where none; `None`
    /// when the matcher gives none.
    pub confidence: Option<Vec<f32>>,
}

/// Like [`rasterize`], on the smallest window of `grid` holding every point, with the number of
/// points per cell: a tile of a whole scene fills a few thousand cells of a grid of hundreds of
/// millions. `None` when no point falls on the grid.
pub fn rasterize_window(points: &Points, grid: &DsmGrid, gridding: Gridding) -> Option<GridWindow> {
    window_of(cells_of(points, grid), None, grid, gridding)
}

/// [`rasterize_window`] with a per-point attribute (`values`, one per point of `points`,
/// row-major like them; the matcher's confidence) gridded on the same cells, from the same
/// projections: the median (upper middle) of the finite values of the points falling in each
/// cell, NaN where none.
pub fn rasterize_window_with(
    points: &Points,
    values: &[f32],
    grid: &DsmGrid,
    gridding: Gridding,
) -> Option<GridWindow> {
    assert_eq!(values.len(), points.lonlatalt.len(), "one value per point");
    let both = cells_with(points, grid, |i, alt| (alt as f32, values[i]));
    let cells = both.iter().map(|&(i, (alt, _))| (i, alt)).collect();
    let attribute = both
        .into_iter()
        .filter(|(_, (_, v))| v.is_finite())
        .map(|(i, (_, v))| (i, v))
        .collect();
    window_of(cells, Some(attribute), grid, gridding)
}

/// The window of `grid` holding `cells` (flat index, altitude), gridded, and the `attribute`'s
/// median per cell when given.
fn window_of(
    cells: Vec<(usize, f32)>,
    attribute: Option<Vec<(usize, f32)>>,
    grid: &DsmGrid,
    gridding: Gridding,
) -> Option<GridWindow> {
    let (mut c0, mut r0, mut c1, mut r1) = (usize::MAX, usize::MAX, 0, 0);
    for &(i, _) in &cells {
        let (c, r) = (i % grid.width, i / grid.width);
        (c0, r0, c1, r1) = (c0.min(c), r0.min(r), c1.max(c), r1.max(r));
    }
    if cells.is_empty() {
        return None;
    }
    let (width, height) = (c1 - c0 + 1, r1 - r0 + 1);
    let local = |i: usize| (i / grid.width - r0) * width + (i % grid.width - c0);
    let (heights, counts) = grid_cells(cells, width * height, local, gridding);
    let confidence = attribute.map(|a| grid_cells(a, width * height, local, Gridding::Median).0);
    Some(GridWindow {
        col: c0,
        row: r0,
        width,
        height,
        heights,
        counts,
        confidence,
    })
}

/// Heights and point counts of `len` cells from `(cell, altitude)` pairs, `index` mapping a
/// cell to its position.
fn grid_cells(
    mut cells: Vec<(usize, f32)>,
    len: usize,
    index: impl Fn(usize) -> usize,
    gridding: Gridding,
) -> (Vec<f32>, Vec<u16>) {
    let mut heights = vec![f32::NAN; len];
    let mut counts = vec![0u16; len];
    match gridding {
        Gridding::Max => {
            for (i, alt) in cells {
                let k = index(i);
                let v = &mut heights[k];
                if v.is_nan() || alt > *v {
                    *v = alt;
                }
                counts[k] = counts[k].saturating_add(1);
            }
        }
        Gridding::Median => {
            cells.par_sort_unstable_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)));
            for run in cells.chunk_by(|a, b| a.0 == b.0) {
                let k = index(run[0].0);
                heights[k] = run[run.len() / 2].1;
                counts[k] = run.len().min(u16::MAX as usize) as u16;
            }
        }
    }
    (heights, counts)
}

/// How far [`fill_holes`] goes from the measured cells.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct HoleFill {
    /// Cells each of the 8 rays walks to find a height: a cell is enclosed when the two rays of
    /// one line both find one, so holes up to twice this wide are filled across.
    pub span: usize,
    /// Cells at most between a filled cell and the nearest height its rays find: the interior
    /// of a wider hole stays empty. Invented that far from any measurement, a height is a guess
    /// (a courtyard at its roofs' height, a low roof at the ground's): on the 45 dev pairs those
    /// cells were mostly far off (BENCHMARKS.md, "The filling stops 16 cells from the data").
    pub reach: usize,
}

impl HoleFill {
    /// Rays of `span` cells, no limit of reach (a cell's nearest ray end is within `span`).
    pub fn spanning(span: usize) -> Self {
        HoleFill { span, reach: span }
    }
}

/// Fills the holes of a DSM that are enclosed by data, ground-first: the usual holes of a
/// stereo DSM are ground hidden behind buildings in one view and unmatched patches of weak
/// texture, and a surface model with holes cannot be used for orthorectification, volumes or
/// line-of-sight.
///
/// For each empty cell, 8 rays (the axes and diagonals) walk at most `fill.span` cells to the
/// first cell with a height. Along each of the 4 lines whose two rays both hit, the lower of the
/// two heights is kept (an occluded strip lies between a roof and the ground, and belongs to the
/// ground); the cell gets the median of those values. A cell without such an enclosing line
/// (outside the images' footprint, or in a hole wider than `2 · span`), or whose nearest hit is
/// farther than `fill.reach` cells, stays empty. Returns the filled DSM and the number of cells
/// filled.
pub fn fill_holes(dsm: &Image, fill: HoleFill) -> (Image, usize) {
    let (w, h) = dsm.size();
    let src = dsm.channel(0);
    let data = src.data();
    // Opposite rays side by side: a cell between data on both sides of one line.
    const DIRS: [(i64, i64); 8] = raster::geometry::EIGHT_DIRECTIONS;
    // The first height along a ray, and the steps to it.
    let ray = |x: usize, y: usize, (dx, dy): (i64, i64)| -> Option<(f32, usize)> {
        let (mut cx, mut cy) = (x as i64, y as i64);
        for step in 1..=fill.span {
            cx += dx;
            cy += dy;
            if cx < 0 || cy < 0 || cx >= w as i64 || cy >= h as i64 {
                return None;
            }
            let v = data[cy as usize * w + cx as usize];
            if v.is_finite() {
                return Some((v, step));
            }
        }
        None
    };
    let rows: Vec<(Vec<f32>, usize)> = (0..h)
        .into_par_iter()
        .map(|y| {
            let mut row = data[y * w..(y + 1) * w].to_vec();
            let mut filled = 0;
            let mut lows: Vec<f32> = Vec::with_capacity(4);
            for (x, v) in row.iter_mut().enumerate() {
                if v.is_finite() {
                    continue;
                }
                lows.clear();
                let mut nearest = usize::MAX;
                for pair in DIRS.chunks_exact(2) {
                    let (a, b) = (ray(x, y, pair[0]), ray(x, y, pair[1]));
                    for (_, steps) in a.iter().chain(&b) {
                        nearest = nearest.min(*steps);
                    }
                    if let (Some((a, _)), Some((b, _))) = (a, b) {
                        lows.push(a.min(b));
                    }
                }
                if lows.is_empty() || nearest > fill.reach {
                    continue;
                }
                lows.sort_unstable_by(f32::total_cmp);
                *v = lows[(lows.len() - 1) / 2];
                filled += 1;
            }
            (row, filled)
        })
        .collect();
    let filled = rows.iter().map(|r| r.1).sum();
    let out: Vec<f32> = rows.into_iter().flat_map(|r| r.0).collect();
    (
        Image::new(w, h, 1, out).expect("same size as the input"),
        filled,
    )
}

/// NaN-aware median filter of a DSM over `window × window` cells (odd): each cell with a height
/// gets the median (the upper one of an even count) of the heights in its window; empty cells
/// stay empty. Run after [`fill_holes`], it removes the roughness that single-pair matching
/// leaves on roofs and ground while keeping building edges, which a mean would blur.
pub fn median_filter(dsm: &Image, window: usize) -> Image {
    let (w, h) = dsm.size();
    let src = dsm.channel(0);
    let data = src.data();
    let r = window / 2;
    let out: Vec<f32> = (0..h)
        .into_par_iter()
        .flat_map_iter(|y| {
            let mut values: Vec<f32> = Vec::with_capacity(window * window);
            (0..w)
                .map(|x| {
                    let v = data[y * w + x];
                    if !v.is_finite() || r == 0 {
                        return v;
                    }
                    values.clear();
                    for yy in y.saturating_sub(r)..(y + r + 1).min(h) {
                        let row = &data[yy * w..(yy + 1) * w];
                        values.extend(
                            row[x.saturating_sub(r)..(x + r + 1).min(w)]
                                .iter()
                                .filter(|v| v.is_finite()),
                        );
                    }
                    let mid = values.len() / 2;
                    *values.select_nth_unstable_by(mid, f32::total_cmp).1
                })
                .collect::<Vec<_>>()
        })
        .collect();
    Image::new(w, h, 1, out).expect("same size as the input")
}

/// Writes a DSM of ellipsoidal heights as a float32 Cloud-Optimized GeoTIFF on `grid`
/// (georeference, EPSG, nodata NaN, 256² tiles, overviews), atomically.
pub fn write_dsm(path: impl AsRef<Path>, image: &Image, grid: &DsmGrid) -> Result<()> {
    write_grid_raster(path, image, grid, Band::Heights(crate::Heights::Ellipsoid))
}

/// [`write_dsm`] for any one-band raster on `grid` (a DSM of other heights, a sidecar), its
/// metadata saying what `band` holds.
pub fn write_grid_raster(
    path: impl AsRef<Path>,
    image: &Image,
    grid: &DsmGrid,
    band: Band,
) -> Result<()> {
    let path = path.as_ref();
    grid.check_heights(image, &path.display().to_string())?;
    raster::formats::write_cog(path, image, &dsm_meta(grid, band))?;
    Ok(())
}

/// A writer of a raster on `grid` (holding `band`) given by blocks of rows, top to bottom: the
/// file [`write_grid_raster`] writes, without holding it whole (call `finish` after the last
/// row).
pub fn grid_writer(
    path: impl AsRef<Path>,
    grid: &DsmGrid,
    band: Band,
) -> Result<raster::formats::CogWriter> {
    let size = (grid.width, grid.height, 1);
    Ok(raster::formats::CogWriter::new(
        path,
        size,
        &dsm_meta(grid, band),
    )?)
}

/// The tags of a raster on `grid`: its georeference, NaN as nodata, and what its band holds.
fn dsm_meta(grid: &DsmGrid, band: Band) -> GeoTiffMeta {
    GeoTiffMeta {
        georef: Some(grid.georeference()),
        nodata: Some(f64::NAN),
        rpc: None,
        gdal_metadata: Some(band.gdal_metadata()),
    }
}

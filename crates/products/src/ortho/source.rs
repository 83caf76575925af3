//! A view's image as the orthoimage samples it: only the window the DSM can project into (with a
//! margin) is read, strip by strip, so a 40,000² scene is never held whole; its values become
//! 8-bit RGB once ([`Levels`]) and are sampled bilinearly.

use camera::{DsmGrid, RpcModel};
use raster::formats::TiffReader;

use super::radiometry::Levels;
use super::view::OrthoView;
use crate::Result;

/// Pixels added around the projected footprint: the bilinear taps and the RPC's curvature
/// between the footprint's sample points.
const MARGIN_PX: f64 = 4.0;
/// Sample points across the DSM's extent (per side) whose projections bound the footprint.
const FOOTPRINT_STEPS: usize = 8;
/// Rows read at a time (a multiple of the usual tile and strip heights).
const STRIP_ROWS: usize = 512;

/// The window of a view's image the DSM projects into, as 8-bit RGB; `[0, 0, 0]` where the image
/// has no data.
pub(super) struct ViewImage {
    x0: usize,
    y0: usize,
    width: usize,
    height: usize,
    rgb: Vec<[u8; 3]>,
}

/// A window of an image: `(x0, y0, width, height)`, pixels.
type Window = (usize, usize, usize, usize);

impl ViewImage {
    /// Reads the part of `view`'s image that `grid` projects into at heights within `heights`
    /// (low, high); `None` when that part is empty (the view does not see the DSM).
    pub(super) fn read(
        view: &OrthoView,
        grid: &DsmGrid,
        heights: (f32, f32),
    ) -> Result<Option<ViewImage>> {
        let mut reader = TiffReader::open(&view.image)?;
        let Some(window) = footprint(&view.rpc, grid, heights, reader.size()) else {
            return Ok(None);
        };
        let (values, channels) = read_values(&mut reader, window)?;
        let levels = Levels::of(&values);
        let rgb = values
            .chunks_exact(channels)
            .map(|px| {
                if px[0].is_nan() {
                    [0; 3]
                } else if channels == 1 {
                    [levels.apply(px[0]); 3]
                } else {
                    [
                        levels.apply(px[0]),
                        levels.apply(px[1]),
                        levels.apply(px[2]),
                    ]
                }
            })
            .collect();
        let (x0, y0, width, height) = window;
        Ok(Some(ViewImage {
            x0,
            y0,
            width,
            height,
            rgb,
        }))
    }

    /// The colour at image point (col, row) of the whole image (pixel centres at whole numbers),
    /// bilinear; `None` outside the window or next to a pixel without data.
    #[inline]
    pub(super) fn sample(&self, col: f64, row: f64) -> Option<[u8; 3]> {
        let u = col - self.x0 as f64;
        let v = row - self.y0 as f64;
        if !(u >= 0.0 && v >= 0.0 && u <= (self.width - 1) as f64 && v <= (self.height - 1) as f64)
        {
            return None;
        }
        let (i, j) = (u as usize, v as usize);
        let (i1, j1) = ((i + 1).min(self.width - 1), (j + 1).min(self.height - 1));
        let (fx, fy) = ((u - i as f64) as f32, (v - j as f64) as f32);
        let px = |x: usize, y: usize| self.rgb[y * self.width + x];
        let taps = [px(i, j), px(i1, j), px(i, j1), px(i1, j1)];
        if taps.iter().any(|t| t[0] == 0) {
            return None;
        }
        let weights = [
            (1.0 - fx) * (1.0 - fy),
            fx * (1.0 - fy),
            (1.0 - fx) * fy,
            fx * fy,
        ];
        let mut out = [0u8; 3];
        for (c, o) in out.iter_mut().enumerate() {
            let v: f32 = taps.iter().zip(weights).map(|(t, w)| t[c] as f32 * w).sum();
            *o = v.round().clamp(1.0, 255.0) as u8;
        }
        Some(out)
    }
}

/// The window of an image of `size` pixels that the grid's extent projects into through `rpc`
/// at heights within `heights`, with a margin; `None` when it misses the image.
fn footprint(
    rpc: &RpcModel,
    grid: &DsmGrid,
    heights: (f32, f32),
    size: (usize, usize),
) -> Option<Window> {
    let crs = grid.crs();
    let (ext_x, ext_y) = (
        grid.width as f64 * grid.resolution,
        grid.height as f64 * grid.resolution,
    );
    let mut bounds = [
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    ];
    for i in 0..=FOOTPRINT_STEPS {
        for j in 0..=FOOTPRINT_STEPS {
            let x = grid.x0 + ext_x * i as f64 / FOOTPRINT_STEPS as f64;
            let y = grid.y0 - ext_y * j as f64 / FOOTPRINT_STEPS as f64;
            let (lon, lat) = crs.inverse(x, y);
            for h in [heights.0, heights.1] {
                let (c, r) = rpc.projection(lon, lat, h as f64);
                if c.is_finite() && r.is_finite() {
                    bounds = [
                        bounds[0].min(c),
                        bounds[1].min(r),
                        bounds[2].max(c),
                        bounds[3].max(r),
                    ];
                }
            }
        }
    }
    let clamp = |v: f64, n: usize| v.clamp(0.0, n as f64) as usize;
    let x0 = clamp((bounds[0] - MARGIN_PX).floor(), size.0);
    let y0 = clamp((bounds[1] - MARGIN_PX).floor(), size.1);
    let x1 = clamp((bounds[2] + MARGIN_PX).ceil() + 1.0, size.0);
    let y1 = clamp((bounds[3] + MARGIN_PX).ceil() + 1.0, size.1);
    (x1 > x0 && y1 > y0).then_some((x0, y0, x1 - x0, y1 - y0))
}

/// The values of `window`, one channel (one band) or three (the first three bands) per pixel,
/// row-major; NaN in every channel where a used band is NaN or the nodata value. Read in strips
/// aligned to [`STRIP_ROWS`], keeping only the used bands.
fn read_values(reader: &mut TiffReader, window: Window) -> Result<(Vec<f32>, usize)> {
    let (x0, y0, width, height) = window;
    let bands = reader.bands();
    let channels = if bands >= 3 { 3 } else { 1 };
    let nodata = reader.nodata.map(|v| v as f32);
    let mut values = Vec::with_capacity(width * height * channels);
    let mut row = y0;
    while row < y0 + height {
        let end = ((row / STRIP_ROWS + 1) * STRIP_ROWS).min(y0 + height);
        let strip = reader.read_window(x0, row, width, end - row)?;
        for px in strip.data().chunks_exact(bands) {
            let used = &px[..channels];
            if used.iter().any(|&v| v.is_nan() || Some(v) == nodata) {
                values.extend(std::iter::repeat_n(f32::NAN, channels));
            } else {
                values.extend_from_slice(used);
            }
        }
        row = end;
    }
    Ok((values, channels))
}

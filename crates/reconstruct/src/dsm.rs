//! Disparity → DSM for one rectified pair: triangulate every valid pixel with the full RPCs and
//! grid the points (highest per cell) onto a ground-truth DSM's grid or a grid of the user's
//! choosing; optionally compare with a reference DSM after the benchmark's alignment.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use camera::{
    rasterize, triangulate_disparity, write_dsm, Crs, DsmGrid, DsmRaster, Points, RpcModel, UtmZone,
};
use raster::{Image, Mask};

use crate::finishing::Finishing;
use eval::aggregate::median;
use eval::align::{align, apply, AlignParams};
use workflow::outputs::{check_dsm_extension, check_output_file};

/// Where the DSM cells are.
#[derive(Clone, Debug)]
pub enum GridChoice {
    /// The grid of an existing georeferenced DSM (e.g. the ground truth).
    Like(PathBuf),
    /// Cells of `resolution` metres on the ground (in the CRS's units where they are not ground
    /// metres: see [`camera::Crs::cell_size`]); bounds (x_min, y_min, x_max, y_max) in the CRS's
    /// units, or the points' extent; the CRS by EPSG code (any projected or geographic one), or
    /// the UTM zone of the points' centre.
    Resolution {
        resolution: f64,
        bounds: Option<[f64; 4]>,
        epsg: Option<u32>,
    },
    /// Exactly this grid: what `reconstruct-many` hands each pair so that all of them lie on the
    /// fused grid.
    Exact(DsmGrid),
}

/// Inputs of [`disparity_to_dsm`].
#[derive(Clone, Debug)]
pub struct DsmOptions {
    /// Disparity of the rectified pair (left view, x_R = x_L − d).
    pub disparity: PathBuf,
    /// `Hleft`/`Hright` (raw → rectified) of the pair.
    pub homography: PathBuf,
    /// Cameras of the raw images: SatNeRF/rpcm JSON, or a GeoTIFF with the RPC tag.
    pub rpc_left: PathBuf,
    pub rpc_right: PathBuf,
    pub grid: GridChoice,
    /// Pixels trimmed on every side before triangulating (the benchmark trims 32).
    pub border: usize,
    /// Gridding (highest point per cell: the benchmark's protocol; or the median), hole
    /// filling and median filter.
    pub finishing: Finishing,
    /// Output GeoTIFF.
    pub output: PathBuf,
    /// A reference DSM to compare with after alignment.
    pub compare: Option<PathBuf>,
}

impl DsmOptions {
    /// Refuses an output DSM that is not a GeoTIFF, is one of the inputs, or exists (it or a
    /// sidecar of an earlier DSM there, which the run removes) unless `overwrite`: the rule of
    /// every caller (command line, Python), before any work.
    pub fn check_output(&self, overwrite: bool) -> Result<()> {
        let inputs = [
            &self.disparity,
            &self.homography,
            &self.rpc_left,
            &self.rpc_right,
        ];
        let inputs = inputs.map(|p| p.as_path());
        check_dsm_output("-o", &self.output, &inputs, overwrite)
    }
}

/// Agreement of a DSM with a reference after the benchmark's alignment.
#[derive(Clone, Debug, PartialEq)]
pub struct Comparison {
    /// Cells finite in both.
    pub shared: usize,
    pub median_abs: f64,
    pub mean_abs: f64,
    pub dx: i32,
    pub dy: i32,
    pub offset: f64,
}

/// What [`disparity_to_dsm`] did.
#[derive(Clone, Debug)]
pub struct DsmSummary {
    pub points: usize,
    pub grid: DsmGrid,
    /// Cells with a triangulated point.
    pub measured_cells: usize,
    /// Cells with a height in the output (measured, plus those filled).
    pub filled_cells: usize,
    pub comparison: Option<Comparison>,
}

/// Reads a camera from any file that holds one: SatNeRF/rpcm JSON, `.RPB`, `_RPC.TXT`, DIMAP
/// `RPC_*.XML`, or a GeoTIFF's RPC tag ([`camera::read_camera_file`]).
pub fn read_camera(path: &Path) -> Result<RpcModel> {
    camera::read_camera_file(path)
        .with_context(|| format!("reading the camera of {}", path.display()))
}

/// Pixels whose disparity is finite and whose match lies inside the right image, `border` pixels
/// away from the edges.
pub fn valid_pixels(disparity: &Image, border: usize) -> Mask {
    let (w, h) = disparity.size();
    Mask::from_fn(w, h, |x, y| {
        let d = disparity.get(x, y, 0) as f64;
        let xr = x as f64 - d;
        x >= border
            && y >= border
            && x + border < w
            && y + border < h
            && d.is_finite()
            && xr >= 0.0
            && xr < w as f64
    })
}

/// Triangulates a rectified pair's disparity file through its homographies and the two camera
/// files (every finite pixel whose match falls inside the right image, `border` pixels ignored).
pub fn triangulate_files(
    disparity: &Path,
    homography: &Path,
    [rpc_left, rpc_right]: [&Path; 2],
    border: usize,
) -> Result<Points> {
    let d = raster::read_image(disparity)
        .with_context(|| format!("reading the disparity {}", disparity.display()))?;
    if d.channels() != 1 {
        bail!(
            "{}: a disparity has one channel, this raster has {}",
            disparity.display(),
            d.channels()
        );
    }
    let (h_left, h_right) = raster::formats::read_homographies(homography)?;
    let rpc_l = read_camera(rpc_left)?;
    let rpc_r = read_camera(rpc_right)?;
    let mask = valid_pixels(&d, border);
    triangulate_disparity(&d, &h_left, &h_right, &rpc_l, &rpc_r, &mask)
        .with_context(|| format!("triangulating {}", disparity.display()))
}

/// Triangulates the disparity and writes the DSM.
pub fn disparity_to_dsm(opts: &DsmOptions) -> Result<DsmSummary> {
    let points = triangulate_files(
        &opts.disparity,
        &opts.homography,
        [&opts.rpc_left, &opts.rpc_right],
        opts.border,
    )?;
    let rpc_left = read_camera(&opts.rpc_left)?;
    if points.valid_count() == 0 {
        bail!(
            "{}: no pixel could be triangulated (no finite disparity inside the right image)",
            opts.disparity.display()
        );
    }
    // A DFC2019 truth (plain TIFF + .txt) has no zone: the left camera's is the AOI's.
    let zone = UtmZone::from_lonlat(rpc_left.lon_offset, rpc_left.lat_offset);
    let grid = match &opts.grid {
        GridChoice::Like(path) => DsmGrid::read(path, Some(zone))
            .with_context(|| format!("reading the grid of {}", path.display()))?,
        GridChoice::Exact(grid) => grid.clone(),
        GridChoice::Resolution {
            resolution,
            bounds,
            epsg,
        } => grid_for(&points, *resolution, *bounds, *epsg)?,
    };
    let dsm = rasterize(&points, &grid, opts.finishing.gridding);
    let measured_cells = dsm.data().iter().filter(|v| v.is_finite()).count();
    let dsm = opts.finishing.finish(dsm)?;
    remove_other_sidecars(&opts.output, &[])?;
    write_dsm(&opts.output, &dsm, &grid)
        .with_context(|| format!("writing {}", opts.output.display()))?;
    let comparison = match &opts.compare {
        Some(reference) => Some(compare_with(&dsm, &grid, reference, zone)?),
        None => None,
    };
    Ok(DsmSummary {
        points: points.valid_count(),
        measured_cells,
        filled_cells: dsm.data().iter().filter(|v| v.is_finite()).count(),
        grid,
        comparison,
    })
}

/// Suffix of `reconstruct`'s filled-cell sidecar, beside the DSM (`<stem>_filled.tif`).
pub const FILLED_SUFFIX: &str = "_filled.tif";

/// What each sidecar's band holds, as its file's metadata says.
pub mod bands {
    use camera::Band;

    /// `_filled.tif`.
    pub const FILLED: Band = Band::Values {
        description: "0 measured, 1 filled by hole filling, NaN no height",
        unit: None,
    };
    /// `_confidence.tif`.
    pub const CONFIDENCE: Band = Band::Values {
        description: "matching confidence of the measured cell, 1 - S1/S2, 0 to 1",
        unit: None,
    };
    /// `reconstruct-many`'s `_confidence.tif`: the pairs' confidences summed over the kept
    /// cluster, so up to the number of pairs.
    pub const SUMMED_CONFIDENCE: Band = Band::Values {
        description: "summed matching confidence of the pairs in the kept cluster",
        unit: None,
    };
    /// `reconstruct-many`'s `_count.tif`.
    pub const COUNT: Band = Band::Values {
        description: "pairs that measured the cell",
        unit: None,
    };
    /// `reconstruct-many`'s `_spread.tif`.
    pub const SPREAD: Band = Band::Values {
        description: "spread of the pairs' heights in the kept cluster",
        unit: Some("metre"),
    };
}

/// `<stem><suffix>` in the folder of `dsm`: where the files that describe a DSM go.
pub fn sidecar_path(dsm: &Path, suffix: &str) -> PathBuf {
    let stem = dsm.file_stem().map(|s| s.to_string_lossy().into_owned());
    dsm.with_file_name(format!("{}{suffix}", stem.as_deref().unwrap_or("dsm")))
}

/// The filled-cell sidecar of `dsm`: `<stem>_filled.tif` in the DSM's folder.
pub fn filled_path(dsm: &Path) -> PathBuf {
    sidecar_path(dsm, FILLED_SUFFIX)
}

/// Suffix of `reconstruct`'s confidence sidecar, beside the DSM (`<stem>_confidence.tif`).
pub const CONFIDENCE_SUFFIX: &str = "_confidence.tif";

/// The confidence sidecar of `dsm`: `<stem>_confidence.tif` in the DSM's folder. It holds the
/// classical matcher's confidence of each measured cell (`1 − S₁/S₂`, the winner's margin over
/// its best rival, in `[0, 1]`; NaN on filled and empty cells), what `reconstruct-many` weighs
/// the pairs' heights by.
pub fn confidence_path(dsm: &Path) -> PathBuf {
    sidecar_path(dsm, CONFIDENCE_SUFFIX)
}

/// Suffixes of the files named after a DSM that describe it: `reconstruct`'s filled cells and
/// confidence, `reconstruct-many`'s count, spread, confidence and report.
pub const SIDECAR_SUFFIXES: [&str; 5] = [
    FILLED_SUFFIX,
    CONFIDENCE_SUFFIX,
    "_count.tif",
    "_spread.tif",
    "_report.json",
];

/// Every sidecar a DSM at `dsm` may have ([`SIDECAR_SUFFIXES`]).
pub fn sidecars(dsm: &Path) -> Vec<PathBuf> {
    SIDECAR_SUFFIXES
        .iter()
        .map(|s| sidecar_path(dsm, s))
        .collect()
}

/// Removes the sidecars of `dsm` whose suffix is not in `written`, before a new DSM is written
/// there: a file describing the DSM it replaces (another command's, an earlier run's) must not
/// stay beside the new one.
pub fn remove_other_sidecars(dsm: &Path, written: &[&str]) -> Result<()> {
    for suffix in SIDECAR_SUFFIXES.iter().filter(|s| !written.contains(*s)) {
        let path = sidecar_path(dsm, suffix);
        if path.is_file() {
            std::fs::remove_file(&path).with_context(|| {
                format!(
                    "removing {}, which describes the DSM being replaced",
                    path.display()
                )
            })?;
        }
    }
    Ok(())
}

/// Which cells of a finished DSM were measured and which invented, so that users and the fusion of
/// several pairs need not trust filled heights as much as triangulated ones: 0 where `measured`
/// had a height before post-processing, 1 where only `finished` has one (hole filling), NaN where
/// `finished` has none.
pub fn filled_mask(measured: &Image, finished: &Image) -> Result<Image> {
    let cells = measured.data().iter().zip(finished.data());
    let values = cells
        .map(|(&m, &f)| match (m.is_finite(), f.is_finite()) {
            (_, false) => f32::NAN,
            (true, true) => 0.0,
            (false, true) => 1.0,
        })
        .collect();
    Ok(Image::new(finished.width(), finished.height(), 1, values)?)
}

/// A grid of `resolution` metres over `bounds`, or over the points' extent, in `epsg` or the
/// points' UTM zone.
fn grid_for(
    points: &Points,
    resolution: f64,
    bounds: Option<[f64; 4]>,
    epsg: Option<u32>,
) -> Result<DsmGrid> {
    let valid = || {
        points
            .lonlatalt
            .iter()
            .filter(|p| p.iter().all(|v| v.is_finite()))
    };
    let n = valid().count() as f64;
    let (lon, lat) = valid().fold((0.0, 0.0), |(a, b), p| (a + p[0] / n, b + p[1] / n));
    let crs = Crs::from_epsg(epsg.unwrap_or(UtmZone::from_lonlat(lon, lat).epsg()))?;
    let resolution = crs.cell_size(resolution, lon, lat);
    let [x_min, y_min, x_max, y_max] = match bounds {
        Some(b) => b,
        None => valid().fold(
            [
                f64::INFINITY,
                f64::INFINITY,
                f64::NEG_INFINITY,
                f64::NEG_INFINITY,
            ],
            |b, p| {
                let (e, n) = crs.forward(p[0], p[1]);
                [
                    b[0].min(e),
                    b[1].min(n),
                    b[2].max(e + resolution),
                    b[3].max(n + resolution),
                ]
            },
        ),
    };
    Ok(DsmGrid::from_bounds(
        x_min,
        y_min,
        x_max,
        y_max,
        resolution,
        crs.epsg(),
    )?)
}

/// Aligns `dsm` to the reference DSM (same grid required) and measures |Δh|.
fn compare_with(
    dsm: &Image,
    grid: &DsmGrid,
    reference: &Path,
    zone: UtmZone,
) -> Result<Comparison> {
    let DsmRaster {
        image: truth,
        grid: ref_grid,
        ..
    } = camera::read_dsm(reference, Some(zone))?;
    if &ref_grid != grid {
        bail!(
            "{}: the reference DSM is on another grid; build the DSM with --like {}",
            reference.display(),
            reference.display()
        );
    }
    let a = align(&truth, dsm, &AlignParams::default()).with_context(|| {
        format!(
            "{}: the DSM and the reference share no cell",
            reference.display()
        )
    })?;
    let aligned = apply(dsm, a.dx, a.dy, a.offset);
    let diffs: Vec<f64> = aligned
        .data()
        .iter()
        .zip(truth.data())
        .filter(|(p, t)| p.is_finite() && t.is_finite())
        .map(|(p, t)| (p - t).abs() as f64)
        .collect();
    let Some(median_abs) = median(&diffs) else {
        bail!("{}: no shared cell after alignment", reference.display());
    };
    let n = diffs.len();
    Ok(Comparison {
        shared: n,
        median_abs,
        mean_abs: diffs.iter().sum::<f64>() / n as f64,
        dx: a.dx,
        dy: a.dy,
        offset: a.offset,
    })
}

/// The checks of a DSM output with its sidecars ([`sidecars`]): a GeoTIFF path, none
/// of them an input, none existing unless `overwrite`.
fn check_dsm_output(flag: &str, output: &Path, inputs: &[&Path], overwrite: bool) -> Result<()> {
    // An output onto an input is named as such first: the most important refusal.
    check_output_file(flag, output, inputs, true)?;
    check_dsm_extension(flag, output)?;
    check_output_file(flag, output, inputs, overwrite)?;
    for sidecar in sidecars(output) {
        check_output_file(
            &format!("{flag} (its sidecar)"),
            &sidecar,
            inputs,
            overwrite,
        )?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::finishing::finish_dsm;
    use camera::HoleFill;

    /// The sidecar marks exactly the cells that were NaN before filling and have a height after.
    #[test]
    fn filled_mask_marks_the_cells_filling_added() {
        let mut heights = vec![5.0f32; 12 * 12];
        for y in 4..8 {
            for x in 4..8 {
                heights[y * 12 + x] = f32::NAN;
            }
        }
        let measured = Image::new(12, 12, 1, heights).unwrap();
        let finished = finish_dsm(measured.clone(), Some(HoleFill::spanning(40)), None).unwrap();
        let mask = filled_mask(&measured, &finished).unwrap();
        for ((&m, &f), &k) in measured.data().iter().zip(finished.data()).zip(mask.data()) {
            assert!(f.is_finite(), "the enclosed hole is filled");
            assert_eq!(k, if m.is_nan() { 1.0 } else { 0.0 });
        }
        assert_eq!(mask.data().iter().filter(|&&k| k == 1.0).count(), 16);
    }

    #[test]
    fn filled_path_is_beside_the_dsm() {
        let p = filled_path(Path::new("out/jax.tif"));
        assert_eq!(p, Path::new("out/jax_filled.tif"));
    }
}

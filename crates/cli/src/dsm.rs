//! `seasonstereo dsm`: a rectified disparity to a georeferenced DSM.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use seasonstereo::{flags, DsmOptions};

#[derive(Args)]
pub struct DsmArgs {
    /// Disparity of the rectified pair (left view, x_R = x_L − d; .iio/.npy, .tif, .pfm).
    disparity: PathBuf,
    /// Homographies of the pair (`homography/<stem>.npz`, raw → rectified).
    #[arg(long)]
    homography: PathBuf,
    /// Camera of the left raw image: SatNeRF/rpcm JSON, or the raw GeoTIFF carrying the RPC tag.
    #[arg(long)]
    rpc_left: PathBuf,
    /// Camera of the right raw image (JSON or GeoTIFF).
    #[arg(long)]
    rpc_right: PathBuf,
    /// Output DSM: float32 GeoTIFF, heights above the WGS84 ellipsoid.
    ///
    /// NaN where no point fell (and no hole was filled: --fill-holes).
    #[arg(short, long)]
    output: PathBuf,
    /// Use the grid of this georeferenced DSM, e.g. the ground truth.
    ///
    /// Its origin, resolution, size and CRS. Otherwise the grid is built from --resolution and
    /// --bounds.
    #[arg(long, conflicts_with_all = ["resolution", "bounds", "epsg"])]
    like: Option<PathBuf>,
    /// Cell size on the ground, metres.
    ///
    /// Converted at the points' centre in a CRS whose unit is not a ground metre.
    #[arg(long, default_value_t = flags::RESOLUTION, value_parser = crate::args::parse_resolution)]
    resolution: f64,
    /// Bounds XMIN,YMIN,XMAX,YMAX in the CRS's units (default: the extent of the points).
    #[arg(long, value_name = "XMIN,YMIN,XMAX,YMAX", value_parser = parse_bounds, allow_hyphen_values = true)]
    bounds: Option<[f64; 4]>,
    /// EPSG code of the DSM's CRS (default: the UTM zone of the points).
    ///
    /// Projected or geographic.
    #[arg(long)]
    epsg: Option<u32>,
    /// Height of a cell from its points.
    ///
    /// Default max: the benchmark's protocol, so DSMs compare with its numbers; `median` is
    /// robust to isolated wrong points (the DSM to use).
    #[arg(long, value_enum, default_value_t = crate::args::GriddingArg::Max)]
    gridding: crate::args::GriddingArg,
    /// Fill holes enclosed by data within this many cells; 0 leaves them empty.
    ///
    /// Ground first; 0 (the default) leaves them empty, as the benchmark's protocol does.
    #[arg(long, value_name = "CELLS", default_value_t = 0)]
    fill_holes: usize,
    /// Median filter of the DSM over this odd window of cells; 0 or 1: none.
    ///
    /// After any filling.
    #[arg(long, value_name = "CELLS", default_value_t = 0)]
    median_filter: usize,
    /// Pixels trimmed on every side of the disparity (the benchmark trims 32).
    #[arg(long, default_value_t = 0)]
    border: usize,
    /// Compare with this reference DSM and print median and mean |Δh|.
    ///
    /// On the same grid (use --like), after the benchmark's alignment (integer shift + vertical
    /// offset).
    #[arg(long)]
    compare: Option<PathBuf>,
}

fn parse_bounds(s: &str) -> Result<[f64; 4], String> {
    crate::args::parse_box(s, "XMIN,YMIN,XMAX,YMAX")
}

pub fn run(a: DsmArgs) -> Result<()> {
    let grid = flags::grid(a.like, a.resolution, a.bounds, a.epsg);
    let options = DsmOptions {
        disparity: a.disparity,
        homography: a.homography,
        rpc_left: a.rpc_left,
        rpc_right: a.rpc_right,
        grid,
        border: a.border,
        finishing: seasonstereo::Finishing::new(
            a.gridding.into(),
            flags::fill_cells(a.fill_holes),
            None,
            flags::median_cells(a.median_filter),
        ),
        output: a.output.clone(),
        compare: a.compare,
    };
    options.check_output(crate::exit::overwrite())?;
    let s = seasonstereo::dsm(&options)?;
    println!(
        "wrote {} ({}, {} points, {} cells filled)",
        a.output.display(),
        s.grid,
        s.points,
        s.filled_cells
    );
    if let Some(c) = s.comparison {
        println!(
            "vs reference: median |Δh| {:.3} m, mean |Δh| {:.3} m on {} shared cells (shift {},{} cells, offset {:+.3} m)",
            c.median_abs, c.mean_abs, c.shared, c.dx, c.dy, c.offset
        );
    }
    Ok(())
}

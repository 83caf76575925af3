//! `seasonstereo rectify`: a raw pair rectified from its RPC cameras.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use seasonstereo::{rectify, Progress, RectifyOptions, Roi};

use crate::args::{parse_alt_range, parse_roi};

#[derive(Args)]
#[command(
    after_help = "Writes OUT/L/<stem>.iio and OUT/R/<stem>.iio (NPY float32, NaN outside the \
    raw images), OUT/homography/<stem>.npz (Hleft, Hright: raw → rectified, flip included) and \
    OUT/rectify/<STEM>.json (ranges, region, sizes). Disparity x_L − x_R is positive and grows with \
    altitude; pass the printed range to `seasonstereo predict --range`.\n\n\
    Example (s2p's Pléiades test pair):\n  seasonstereo rectify img_01.tif img_02.tif -o out/s2p \\\n      \
    --roi 150,150,700,700 --alt-range 2200:2450"
)]
pub struct RectifyArgs {
    /// Left raw image: a GeoTIFF carrying its RPC (tag 50844), or any raster with --rpc-left.
    left: PathBuf,
    /// Right raw image, idem with --rpc-right.
    right: PathBuf,
    /// Output folder.
    #[arg(short, long)]
    output: PathBuf,
    /// Region of interest X,Y,W,H in the left raw image, pixels. Default: the whole image.
    #[arg(long, value_name = "X,Y,W,H", value_parser = parse_roi)]
    roi: Option<Roi>,
    /// Left camera, instead of the image's RPC tag: SatNeRF/rpcm JSON (`.json`), or another
    /// GeoTIFF carrying the RPC tag 50844.
    #[arg(long, value_name = "CAMERA")]
    rpc_left: Option<PathBuf>,
    /// Right camera, instead of the image's RPC tag: SatNeRF/rpcm JSON (`.json`), or another
    /// GeoTIFF carrying the RPC tag 50844.
    #[arg(long, value_name = "CAMERA")]
    rpc_right: Option<PathBuf>,
    /// Altitudes of the scene MIN:MAX, metres; the disparity range is derived from it. Default:
    /// min_alt/max_alt of the JSON cameras, else the RPCs' altitude offset ± scale (often
    /// thousands of metres: a slow, huge search).
    #[arg(long, value_name = "MIN:MAX", value_parser = parse_alt_range, allow_hyphen_values = true)]
    alt_range: Option<(f64, f64)>,
    /// Pair name <stem> of the output files. Default: <LEFT file stem>-<RIGHT file stem>.
    #[arg(long, value_name = "NAME")]
    stem: Option<String>,
}

pub fn run(a: RectifyArgs, progress: &dyn Progress) -> Result<()> {
    let opts = RectifyOptions {
        left: a.left,
        right: a.right,
        out_dir: a.output,
        roi: a.roi,
        rpc_left: a.rpc_left,
        rpc_right: a.rpc_right,
        alt_range: a.alt_range,
        stem: a.stem,
    };
    opts.check_output()?;
    let s = rectify(&opts, progress)?;
    let (lo, hi) = s.disparity_range;
    println!(
        "wrote pair {} ({}x{} px) to {}: disparity range {lo}:{hi} px for altitudes {}:{} m ({}, {:.3} px/m), rows aligned to {:.3} px",
        s.stem, s.size.0, s.size.1, opts.out_dir.display(), s.alt_range.0, s.alt_range.1,
        s.alt_source, s.pixels_per_metre, s.max_row_error
    );
    if s.right_coverage < 0.5 {
        println!(
            "warning: the right image covers only {:.0} % of the region",
            100.0 * s.right_coverage
        );
    }
    println!(
        "next: seasonstereo predict --range {lo}:{hi} {} {} -o {}",
        s.left.display(),
        s.right.display(),
        opts.out_dir
            .join("disparity")
            .join(format!("{}.iio", s.stem))
            .display()
    );
    Ok(())
}

//! `seasonstereo world`: a procedural satellite world with exact ground truth.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use seasonstereo::world::{
    generate, save_raw_views, save_world, write_dated_stack, Neutral, WorldParams, ACQUISITIONS,
};
use seasonstereo::{track, Progress};

#[derive(Args)]
pub struct WorldArgs {
    /// Output folder (L/, R/, homography/, disparity/, occlusion/, height/, classes/, rpc/, world.json).
    #[arg(short, long, default_value = "out/world")]
    output: PathBuf,
    /// Image width and height, pixels (64 for tests … 2048 for benchmarks).
    #[arg(long, default_value_t = 512, value_parser = parse_size)]
    size: usize,
    /// Random seed: the same seed always gives the same world.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Name of the world; images are <NAME>_A and <NAME>_B, the pair <NAME>_A-<NAME>_B.
    /// Default: WORLD_<SEED>.
    #[arg(long)]
    name: Option<String>,
    /// Also write the raw (unrectified) views as tiled uint8 GeoTIFFs raw/<ID>.tif, the input of
    /// `seasonstereo reconstruct` (with --rpc-left/--rpc-right rpc/<ID>.json).
    #[arg(long)]
    raw: bool,
    /// Instead of one pair, render the same scene on six dates of a year (spring, summer and
    /// winter, two acquisitions a week apart from opposite sides each; the sun and the seasonal
    /// colours change, the geometry does not): raw/<NAME>_D1..D6.tif, their cameras with dates
    /// and sun angles in rpc/, and truth/<NAME>_DSM.tif — the input of `reconstruct-many`.
    #[arg(long, conflicts_with = "raw")]
    dates: bool,
}

/// The views' side: a world needs room for its buildings and the matcher's windows.
fn parse_size(s: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(n) if n >= 32 => Ok(n),
        Ok(n) => Err(format!(
            "{n} is too small: a world needs at least 32 pixels a side"
        )),
        Err(e) => Err(format!("expected a number of pixels, got {s:?}: {e}")),
    }
}

pub fn run(a: WorldArgs, progress: &dyn Progress) -> Result<()> {
    if a.dates {
        return run_dates(a, progress);
    }
    let params = WorldParams::new(a.size, a.seed);
    let world = track(progress, "rendering the world", a.size, |cb| {
        generate(&params, &Neutral, cb)
    })
    .map_err(anyhow::Error::msg)?;
    let name = a.name.unwrap_or_else(|| format!("WORLD_{}", a.seed));
    let paths = save_world(&world, &a.output, &name)?;
    if a.raw {
        let (l, r) = save_raw_views(&world, &a.output, &name)?;
        println!("raw views: {} {}", l.display(), r.display());
    }
    let (lo, hi) = world.disparity_range();
    println!(
        "wrote pair {} to {} ({}x{} px, disparity range {lo}..{hi} px, {:.1} % occluded)",
        paths.stem,
        a.output.display(),
        a.size,
        a.size,
        100.0 * world.occluded.count() as f64 / (a.size * a.size) as f64
    );
    Ok(())
}

/// `--dates`: the multi-date stack.
fn run_dates(a: WorldArgs, progress: &dyn Progress) -> Result<()> {
    let name = a.name.unwrap_or_else(|| format!("WORLD_{}", a.seed));
    let stack = write_dated_stack(a.size, a.seed, &name, &ACQUISITIONS, &a.output, progress)?;
    for (path, acq) in stack.images.iter().zip(&ACQUISITIONS) {
        println!(
            "{} {} {}, {:+.2} px/m, sun {:.0}° at {:.0}°",
            path.display(),
            &acq.date[..8],
            acq.season,
            acq.slope,
            acq.sun_elevation_deg,
            acq.sun_azimuth_deg
        );
    }
    println!(
        "wrote {} acquisitions of {name} to {} (cameras {}, truth {}); fuse them with\n  \
         seasonstereo reconstruct-many {}/raw/*.tif --rpc-dir {} --like {} --truth {} -o DSM.tif",
        stack.images.len(),
        a.output.display(),
        stack.rpc_dir.display(),
        stack.truth.display(),
        a.output.display(),
        stack.rpc_dir.display(),
        stack.truth.display(),
        stack.truth.display()
    );
    Ok(())
}

//! `seasonstereo`: dense stereo matching of multi-date satellite imagery.
//!
//! This binary only parses arguments and draws progress; the work lives in the library crates.

mod bars;

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{bail, Context, Result};
use clap::{Args, Parser, Subcommand, ValueEnum};
use matching::{Paths, SgmParams};
use pipeline::demo::{percent, pixels, run_demo, DemoOptions};
use pipeline::predict::{predict_sgm, read_pair, write_disparity};
use pipeline::progress::track;

#[derive(Parser)]
#[command(
    name = "seasonstereo",
    version,
    about = "Dense stereo matching of multi-date satellite imagery: disparity maps and DSMs",
    long_about = "Dense stereo matching of multi-date satellite imagery.\n\n\
        Conventions: pairs are rectified (epipolar lines are rows); disparity lives on the left view, \
        x_R = x_L − d, positive and growing with altitude; invalid pixels are NaN.\n\n\
        Start with `seasonstereo demo`: it renders a procedural satellite world with exact ground truth, \
        matches it and writes an HTML report."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render a procedural satellite world (rectified pair, exact disparity, heights, classes,
    /// homographies and RPC cameras) in the public release's folder layout.
    World(WorldArgs),
    /// Predict the disparity of a rectified pair.
    Predict(PredictArgs),
    /// Run the whole chain on a procedural world and write an HTML report (offline, CPU, seconds).
    Demo(DemoArgs),
}

#[derive(Args)]
struct WorldArgs {
    /// Output folder (L/, R/, homography/, disparity/, occlusion/, height/, classes/, rpc/, world.json).
    #[arg(short, long, default_value = "out/world")]
    output: PathBuf,
    /// Image width and height, pixels (64 for tests … 2048 for benchmarks).
    #[arg(long, default_value_t = 512)]
    size: usize,
    /// Random seed: the same seed always gives the same world.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Name of the world; images are <NAME>_A and <NAME>_B, the pair <NAME>_A-<NAME>_B.
    /// Default: WORLD_<SEED>.
    #[arg(long)]
    name: Option<String>,
}

#[derive(Clone, Copy, ValueEnum)]
enum Method {
    /// Census transform + Semi-Global Matching with a left-right check.
    Sgm,
}

#[derive(Args)]
struct PredictArgs {
    /// Left image of the rectified pair (.iio/.npy, .tif, .png, .pfm).
    left: PathBuf,
    /// Right image of the rectified pair, same size as the left one.
    right: PathBuf,
    /// Output disparity; the extension picks the format: .iio/.npy, .tif, .pfm keep the values
    /// (NaN = invalid); .png writes a colour-mapped picture.
    #[arg(short, long)]
    output: PathBuf,
    /// Matching method.
    #[arg(long, value_enum, default_value_t = Method::Sgm)]
    method: Method,
    /// Disparity search range MIN:MAX (inclusive, pixels), e.g. from the cameras and an altitude
    /// range. Estimated from the images when absent (less reliable on multi-date pairs).
    #[arg(long, value_parser = parse_range, allow_hyphen_values = true)]
    range: Option<(i32, i32)>,
    /// Also write a colour-mapped picture of the disparity to this PNG.
    #[arg(long)]
    color: Option<PathBuf>,
    #[command(flatten)]
    sgm: SgmArgs,
}

#[derive(Args)]
struct SgmArgs {
    /// SGM penalty of ±1 px disparity changes (census bits).
    #[arg(long, default_value_t = SgmParams::default().p1)]
    p1: u16,
    /// SGM penalty of larger disparity jumps (census bits).
    #[arg(long, default_value_t = SgmParams::default().p2)]
    p2: u16,
    /// Use 4 aggregation paths instead of 8 (faster, slightly less accurate).
    #[arg(long)]
    four_paths: bool,
    /// Left-right consistency tolerance, pixels; 0 disables the check.
    #[arg(long, default_value_t = 1.0)]
    lr_tolerance: f32,
}

impl SgmArgs {
    fn params(&self) -> Result<SgmParams> {
        if self.p1 == 0 || self.p2 <= self.p1 {
            bail!(
                "SGM penalties must satisfy 0 < --p1 < --p2 (got {} and {})",
                self.p1,
                self.p2
            );
        }
        Ok(SgmParams {
            p1: self.p1,
            p2: self.p2,
            paths: if self.four_paths {
                Paths::Four
            } else {
                Paths::Eight
            },
            lr_tolerance: (self.lr_tolerance > 0.0).then_some(self.lr_tolerance),
            ..SgmParams::default()
        })
    }
}

#[derive(Args)]
struct DemoArgs {
    /// Output folder of the report (report.html), its images and the world.
    #[arg(short, long, default_value = "out/demo")]
    output: PathBuf,
    /// World size, pixels.
    #[arg(long, default_value_t = 512)]
    size: usize,
    /// World seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    #[command(flatten)]
    sgm: SgmArgs,
}

fn parse_range(s: &str) -> Result<(i32, i32), String> {
    let (a, b) = s
        .split_once(':')
        .ok_or_else(|| format!("expected MIN:MAX, e.g. -10:54, got {s:?}"))?;
    let parse = |v: &str| {
        v.trim()
            .parse::<i32>()
            .map_err(|e| format!("{v:?} in {s:?}: {e}"))
    };
    let (lo, hi) = (parse(a)?, parse(b)?);
    if lo > hi {
        return Err(format!("MIN must not exceed MAX in {s:?}"));
    }
    Ok((lo, hi))
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> Result<()> {
    let progress = bars::Bars::default();
    match cli.command {
        Command::World(a) => {
            let params = world::WorldParams::new(a.size, a.seed);
            let world = track(&progress, "rendering the world", a.size, |cb| {
                world::generate(&params, &world::Neutral, cb)
            })
            .map_err(anyhow::Error::msg)?;
            let name = a.name.unwrap_or_else(|| format!("WORLD_{}", a.seed));
            let paths = pipeline::world_io::save_world(&world, &a.output, &name)?;
            let (lo, hi) = world.disparity_range();
            println!(
                "wrote pair {} to {} ({}x{} px, disparity range {lo}..{hi} px, {:.1} % occluded)",
                paths.stem,
                a.output.display(),
                a.size,
                a.size,
                100.0 * world.occluded.count() as f64 / (a.size * a.size) as f64
            );
        }
        Command::Predict(a) => {
            let (left, right) = read_pair(&a.left, &a.right)?;
            let params = a.sgm.params()?;
            let (disparity, (lo, hi)) = match a.method {
                Method::Sgm => predict_sgm(&left, &right, a.range, &params, &progress)?,
            };
            write_disparity(&a.output, &disparity)
                .with_context(|| format!("writing {}", a.output.display()))?;
            if let Some(c) = &a.color {
                write_disparity(c, &disparity)
                    .with_context(|| format!("writing {}", c.display()))?;
            }
            let valid = disparity.data().iter().filter(|v| v.is_finite()).count();
            println!(
                "wrote {} (range {lo}..{hi} px, {:.1} % of pixels matched)",
                a.output.display(),
                100.0 * valid as f64 / disparity.data().len().max(1) as f64
            );
        }
        Command::Demo(a) => {
            let opts = DemoOptions {
                size: a.size,
                seed: a.seed,
                out_dir: a.output,
                sgm: a.sgm.params()?,
            };
            let s = run_demo(&opts, &progress)?;
            let v = &s.visible;
            println!(
                "disparity range {}..{} px (from the cameras); on pixels visible in both views: coverage {}, MAE {}, bad-1 {}, bad-2 {}",
                s.range.0,
                s.range.1,
                percent(v.coverage),
                pixels(v.mae),
                percent(v.bad1),
                percent(v.bad2)
            );
            let total: f64 = s.seconds.iter().map(|(_, t)| t).sum();
            println!("report: {} ({total:.1} s)", s.report.display());
        }
    }
    Ok(())
}

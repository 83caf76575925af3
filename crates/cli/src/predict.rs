//! `seasonstereo predict`: the disparity of a rectified pair.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;
use seasonstereo::{predict, read_pair, write_disparity, Matched, Matcher, Progress, RangeSource};

use crate::args::{parse_range, MatcherArgs};

/// The examples, ending both `-h` and `--help`.
macro_rules! examples {
    () => {
        "Examples:
  seasonstereo predict --method sgm --range 0:48 L.iio R.iio -o d.iio
  seasonstereo predict --model monsterpp --weights mix_all.pth --config vitl \\
      --iters 32 L.iio R.iio -o d.iio --color d.png"
    };
}

#[derive(Args)]
#[command(
    after_help = examples!(),
    after_long_help = concat!(
        "Methods: census + MGM by default (--method sgm: SGM), over --range or a range estimated \
        from the images; the MonSter++ network with --model monsterpp --weights FILE (the \
        released .pth checkpoints are --config vitl; no range needed, disparities up to \
        --max-disp).\n\n\
        MonSter++ expects 8-bit RGB values (0–255): grey images are repeated to RGB, alpha is \
        dropped; rescale uint16 satellite images with --normalise percentile (2–98th percentile \
        → 0–255). Pixels with NaN in the left image are NaN in the output. Sizes are padded to \
        multiples of 32 (replicate, as upstream). One forward pass may use at most --net-memory; \
        larger pairs are cut into overlapping strips of full rows (epipolar lines) that are \
        blended.\n\n",
        examples!()
    )
)]
pub struct PredictArgs {
    /// Left image of the rectified pair (.iio/.npy, .tif, .png, .pfm).
    left: PathBuf,
    /// Right image of the rectified pair, same size as the left one.
    right: PathBuf,
    /// Output disparity; the extension picks the format.
    ///
    /// .iio/.npy, .tif, .pfm keep the values (NaN = invalid); .png writes a colour-mapped
    /// picture.
    #[arg(short, long)]
    output: PathBuf,
    #[command(flatten)]
    matcher: MatcherArgs,
    /// Disparity search range MIN:MAX, pixels (default: estimated from the images).
    ///
    /// Inclusive, e.g. from the cameras and an altitude range. Estimated from the images when
    /// absent (less reliable on multi-date pairs). Classical matcher only.
    #[arg(long, value_parser = parse_range, allow_hyphen_values = true, conflicts_with = "model")]
    range: Option<(i32, i32)>,
    /// Also write a colour-mapped picture of the disparity to this PNG.
    #[arg(long)]
    color: Option<PathBuf>,
}

pub fn run(a: PredictArgs, progress: &dyn Progress) -> Result<()> {
    let matcher = a.matcher.matcher()?;
    for out in std::iter::once(&a.output).chain(&a.color) {
        crate::exit::guard_output("-o", out, &[&a.left, &a.right])?;
    }
    let (left, right) = read_pair(&a.left, &a.right)?;
    let range = RangeSource::flag_or_estimate(a.range);
    let matched = predict(&left, &right, &matcher, range, progress)?;
    for path in std::iter::once(&a.output).chain(&a.color) {
        write_disparity(path, &matched.disparity)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    let valid = matched
        .disparity
        .data()
        .iter()
        .filter(|v| v.is_finite())
        .count();
    println!(
        "wrote {} ({}, {:.1} % of pixels matched)",
        a.output.display(),
        describe(&matcher, &matched),
        100.0 * valid as f64 / matched.disparity.data().len().max(1) as f64
    );
    Ok(())
}

/// Which matcher ran and over which range, for the closing line.
fn describe(matcher: &Matcher, matched: &Matched) -> String {
    match (matcher, matched.range) {
        (Matcher::Network(n), _) => {
            format!("MonSter++ {}, {} iterations", n.options.preset, n.iters)
        }
        (_, Some((lo, hi))) => format!("{}, range {lo}..{hi} px", matcher.name()),
        (_, None) => matcher.name(),
    }
}

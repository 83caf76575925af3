//! `seasonstereo eval`: the benchmark's altitude MAE over test splits (the paper's Table 1).

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::{Args, ValueEnum};
use seasonstereo::benchmark::{AoiRule, Method, Protocol, Split};
use seasonstereo::defaults::OMAHA_MAX_DISPARITY;
use seasonstereo::{eval, Aggregation, EvalOptions, Matcher, Progress};

use crate::args::{NetworkArgs, SgmArgs};

#[derive(Clone, Copy, ValueEnum)]
enum EvalMethod {
    /// Census + MGM on each (cropped) rectified pair, range from the cameras.
    Mgm,
    /// Census + SGM on each (cropped) rectified pair, range from the cameras.
    Sgm,
    /// The split's own disparity/<stem>.iio (LiDAR-derived): the error of the chain itself.
    GroundTruth,
}

/// The example, ending both `-h` and `--help`.
macro_rules! example {
    () => {
        "Example:
  seasonstereo eval --split Jacksonville=test/jax \\
      --split \"Omaha Diach.\"=test/oma_dia --rpc-dir root_dir \\
      --truth-dir Track3-Truth --predictions preds/monster -o out/eval"
    };
}

/// The headings of `eval`'s options.
const SPLITS: &str = crate::args::heading::INPUTS;
const OUTPUTS: &str = crate::args::heading::OUTPUTS;
const DISPARITIES: &str = "Disparities";
const PROTOCOL: &str = "Benchmark protocol";

#[derive(Args)]
#[command(
    after_help = example!(),
    after_long_help = concat!(
        "Layout: SPLIT_DIR/{L,R}/<stem>.iio, SPLIT_DIR/homography/<stem>.npz, optional \
        SPLIT_DIR/disparity/<stem>.iio; <stem> = <LEFTID>-<RIGHTID>; RPC_DIR/<IMAGEID>.json \
        (SatNeRF/rpcm); TRUTH_DIR/<AOI>_DSM.tif, <AOI>_CLS.tif, optional <AOI>_WATER.png. Outputs: \
        OUT/pairs.csv (one row per method, split and pair), OUT/table1.md, \
        OUT/dsm/<method>/<split>/<stem>.tif with --save-dsm.\n\n",
        example!()
    )
)]
pub struct EvalArgs {
    /// A test split NAME=DIR (repeat).
    ///
    /// Table 1's names: Jacksonville, "Buenos Aires", "Omaha Synch.", "Omaha Diach." (aliases
    /// jax, ba, omaha-sync, omaha-dia); other names get columns of their own. Omaha splits drop
    /// pairs whose true disparity exceeds the limit.
    #[arg(long = "split", value_name = "NAME=DIR", value_parser = Split::parse,
          required_unless_present = "world", help_heading = SPLITS)]
    splits: Vec<Split>,
    /// Evaluate a folder written by `seasonstereo world` instead.
    ///
    /// Split "World", with DIR/rpc and DIR/truth.
    #[arg(long, value_name = "DIR", conflicts_with_all = ["splits", "rpc_dir", "truth_dir"],
          help_heading = SPLITS)]
    world: Option<PathBuf>,
    /// Folder of the cameras <IMAGEID>.json (SatNeRF/rpcm JSON, the `root_dir`).
    #[arg(long, value_name = "DIR", required_unless_present = "world", help_heading = SPLITS)]
    rpc_dir: Option<PathBuf>,
    /// Folder of the ground truth <AOI>_DSM.tif, <AOI>_CLS.tif, <AOI>_WATER.png.
    ///
    /// The DSM as a GeoTIFF, or the DFC2019 plain TIFF with its <AOI>_DSM.txt georeference
    /// beside it (the UTM zone is taken from the pair's cameras).
    #[arg(long, value_name = "DIR", required_unless_present = "world", help_heading = SPLITS)]
    truth_dir: Option<PathBuf>,
    /// Compute the disparities with this method (or with --model)...
    #[arg(long, value_enum, default_value_t = EvalMethod::Mgm, help_heading = DISPARITIES)]
    method: EvalMethod,
    /// ...or read them from DIR/[<SPLIT>/]<stem>.{iio,npy,tif,pfm}.
    ///
    /// Full rectified or crop size.
    #[arg(long, value_name = "DIR", conflicts_with_all = ["method", "model"],
          help_heading = DISPARITIES)]
    predictions: Option<PathBuf>,
    /// Row name of the method in the CSV and Table 1.
    ///
    /// Default: from the method or DIR.
    #[arg(long, help_heading = OUTPUTS)]
    name: Option<String>,
    /// Output folder.
    #[arg(short, long, default_value = "out/eval", help_heading = OUTPUTS)]
    output: PathBuf,
    /// Also write each predicted DSM as a GeoTIFF on the ground truth's grid.
    #[arg(long, help_heading = OUTPUTS)]
    save_dsm: bool,
    /// Evaluate at most the first N pairs (by stem) of each split.
    #[arg(long, value_name = "N", help_heading = SPLITS)]
    max_pairs: Option<usize>,
    /// AOI of an image id = its first N '_'-separated fields (JAX_068_001_RGB → JAX_068 with 2).
    #[arg(long, value_name = "N", default_value_t = 2, value_parser = clap::value_parser!(u16).range(1..),
          help_heading = PROTOCOL, hide_short_help = true)]
    aoi_fields: u16,
    /// Put every pair in this AOI instead (one ground-truth DSM for all).
    #[arg(long, value_name = "AOI", conflicts_with = "aoi_fields",
          help_heading = PROTOCOL, hide_short_help = true)]
    aoi: Option<String>,
    /// Centre-crop rectified pairs larger than this, pixels.
    #[arg(long, default_value_t = 1024, help_heading = PROTOCOL, hide_short_help = true)]
    crop: usize,
    /// Omaha pairs whose ground-truth disparity exceeds this are dropped, pixels.
    #[arg(long, default_value_t = OMAHA_MAX_DISPARITY,
          help_heading = PROTOCOL, hide_short_help = true)]
    omaha_max_disparity: f64,
    /// Scoring rules: `release` (the benchmark's evaluator exactly) or `robust`.
    ///
    /// `release` = the benchmark's released evaluator exactly (per-score registration on the
    /// masked truth, its NCC pyramid, _WATER.png 0 = water, truth nodata not masked); `robust` =
    /// one registration on the whole truth, NaN for the truth's nodata, a centre-preferring NCC
    /// with a minimum overlap (rows named "<method> [robust]").
    #[arg(long, value_name = "release|robust", default_value = "release",
          value_parser = Protocol::parse,
          help_heading = PROTOCOL, hide_short_help = true)]
    protocol: Protocol,
    #[command(flatten)]
    sgm: SgmArgs,
    #[command(flatten)]
    net: NetworkArgs,
}

impl EvalMethod {
    /// The classical aggregation of `mgm`/`sgm`; `None` for the ground truth.
    fn aggregation(self) -> Option<Aggregation> {
        match self {
            EvalMethod::Mgm => Some(Aggregation::Mgm),
            EvalMethod::Sgm => Some(Aggregation::Sgm),
            EvalMethod::GroundTruth => None,
        }
    }
}

pub fn run(a: EvalArgs, progress: &dyn Progress) -> Result<()> {
    let opts = a.options()?;
    let r = eval(&opts, progress)?;
    println!("{}", r.table.to_text());
    println!(
        "{} pairs scored, {} already scored (skipped), {} dropped (Omaha disparity > {}); per pair: {}; table: {}",
        r.scored, r.skipped, r.dropped, opts.omaha_max_disparity, r.csv.display(), r.markdown.display()
    );
    for (pair, cause) in &r.failed {
        eprintln!("warning: pair {pair} failed: {cause}");
    }
    let total = r.scored + r.skipped + r.dropped + r.failed.len();
    let names = r.failed.iter().map(|(p, _)| p.clone()).collect();
    crate::exit::partial_if_any(
        "pairs",
        total,
        names,
        "fix them and rerun: scored pairs are skipped",
    )
}

impl EvalArgs {
    /// Where the disparities come from: a folder of predictions, a matcher, or the truth.
    fn method(&self) -> Result<Method> {
        Ok(
            match (
                &self.predictions,
                self.net.network()?,
                self.method.aggregation(),
            ) {
                (Some(dir), _, _) => Method::Predictions(dir.clone()),
                (None, Some(network), _) => Method::Matcher(network),
                (None, None, Some(aggregation)) => {
                    Method::Matcher(Matcher::Classical(self.sgm.params(aggregation)?))
                }
                (None, None, None) => Method::GroundTruth,
            },
        )
    }

    /// The evaluation's options for these flags.
    fn options(self) -> Result<EvalOptions> {
        let method = self.method()?;
        let mut opts = match &self.world {
            Some(dir) => EvalOptions::world(dir, "World", method, &self.output),
            None => EvalOptions::new(
                self.splits,
                self.rpc_dir.context("--rpc-dir is required")?,
                self.truth_dir.context("--truth-dir is required")?,
                method,
                &self.output,
            ),
        };
        match self.name {
            Some(n) => opts.method_name = n,
            None if self.protocol != Protocol::Release => {
                opts.method_name = format!("{} [{}]", opts.method_name, self.protocol.name());
            }
            None => {}
        }
        opts.protocol = self.protocol;
        opts.save_dsm = self.save_dsm;
        opts.max_pairs = self.max_pairs;
        opts.aoi_rule = self
            .aoi
            .map_or(AoiRule::Fields(self.aoi_fields as usize), AoiRule::Fixed);
        opts.crop = self.crop;
        opts.omaha_max_disparity = self.omaha_max_disparity;
        Ok(opts)
    }
}

//! `seasonstereo synthesize`: seasonal variants of the selected pairs' images.

use std::path::PathBuf;

use anyhow::Result;
use clap::{Args, ValueEnum};
use seasonstereo::defaults::{GEMINI_API_KEY_ENV, GEMINI_BASE_URL, GEMINI_MODEL, SYNTHESIZE_CROP};
use seasonstereo::stages::{
    synthesize, BuiltinSeasons, GeminiConfig, GeminiGenerator, Prompts, Season, SeasonGenerator,
    SynthesizeOptions,
};
use seasonstereo::Progress;

use crate::args::ShardArg;

/// The headings of the options `-h` leaves out.
const API: &str = "Generative API (--generator gemini)";
const FIDELITY: &str = "Geometry-fidelity check";

fn parse_season(s: &str) -> Result<Season, String> {
    s.parse::<Season>().map_err(|e| e.to_string())
}

/// Which seasonal generator makes the variants.
#[derive(Clone, Copy, ValueEnum)]
pub enum GeneratorKind {
    /// The built-in geometry-preserving appearance model (offline, deterministic).
    Builtin,
    /// A generative image-editing API (Gemini `generateContent`); key from --api-key-env.
    Gemini,
}

/// The examples, ending both `-h` and `--help`.
macro_rules! examples {
    () => {
        "Examples:
  seasonstereo synthesize --pairs data/synchronic_only --raw data/Train-Track3 \\
      --selected out/curate/selected.txt -o out/synthetic
  GEMINI_API_KEY=… seasonstereo synthesize --generator gemini \\
      --prompts seasons.toml --pairs P --raw RAW -o out/synthetic"
    };
}

/// `synthesize --help`'s epilogue: the files read and written, then the examples.
const AFTER_LONG_HELP: &str = concat!(
    "Inputs: PAIRS/L/<pair>.iio, PAIRS/R/<pair>.iio, PAIRS/homography/<pair>.npz \
    (the release's synchronic_only/ or `seasonstereo rectify` outputs) and the raw images \
    RAW/**/<id>.{tif,png,npy,iio} of the pairs' image ids (the release's Track3-RGB-* folders work \
    as they are). Per image: OUT/cropped/<id>.tif (+ .json, where the crop lies), \
    OUT/cropped-synthetic/<id>_<season>.tif (variants that passed the geometry-fidelity check), \
    OUT/rejected/<id>_<season>.tif and OUT/rejected.csv (those that failed: never used), \
    OUT/variants/<id>.json (written last). `dataset build` rectifies the accepted variants with \
    the pair's homographies adapted to the crop.\n\n\
    Resumable: finished images are skipped, a variant already on disk is checked again, not \
    regenerated. Shardable over the sorted image ids.\n\n",
    examples!()
);

#[derive(Args)]
#[command(after_help = examples!(), after_long_help = AFTER_LONG_HELP)]
pub struct SynthesizeArgs {
    /// Synchronic pairs folder (L/, R/, homography/).
    #[arg(long)]
    pairs: PathBuf,
    /// Folder of the raw images (searched recursively by image id).
    #[arg(long)]
    raw: PathBuf,
    /// Output folder.
    #[arg(short, long, default_value = "out/synthetic")]
    output: PathBuf,
    /// Selected pairs: curate's selected.txt or selected.csv. Default: every pair.
    #[arg(long, value_name = "FILE")]
    selected: Option<PathBuf>,
    /// Class maps <id>.png (OpenEarthMap ids, raw frame) handed to the generator as hints.
    #[arg(long, value_name = "DIR")]
    classes: Option<PathBuf>,
    /// Centre crop side, pixels (smaller images are kept whole).
    #[arg(long, default_value_t = SYNTHESIZE_CROP)]
    crop: usize,
    /// Seasons to generate (repeat or comma-separate).
    #[arg(long, value_delimiter = ',', value_parser = parse_season,
          default_value = "summer,autumn,winter,spring")]
    seasons: Vec<Season>,
    /// Seasonal generator.
    #[arg(long, value_enum, default_value_t = GeneratorKind::Builtin)]
    generator: GeneratorKind,
    /// Seed of the built-in generator.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// API model (gemini).
    #[arg(long, default_value = GEMINI_MODEL,
          help_heading = API, hide_short_help = true)]
    model: String,
    /// Seasonal prompts, TOML (gemini; default: the built-in prompts).
    #[arg(long, value_name = "FILE", help_heading = API, hide_short_help = true)]
    prompts: Option<PathBuf>,
    /// Environment variable holding the API key (gemini; the key is never logged).
    #[arg(long, default_value = GEMINI_API_KEY_ENV,
          help_heading = API, hide_short_help = true)]
    api_key_env: String,
    /// API endpoint (gemini).
    #[arg(long, default_value = GEMINI_BASE_URL,
          help_heading = API, hide_short_help = true)]
    api_url: String,
    /// Requests in flight at once (gemini).
    #[arg(long, default_value_t = 4, help_heading = API, hide_short_help = true)]
    max_concurrent: usize,
    /// Response cache, so a rerun never pays twice (gemini).
    ///
    /// Default: OUT/api-cache.
    #[arg(long, value_name = "DIR", help_heading = API, hide_short_help = true)]
    cache: Option<PathBuf>,
    /// Largest accepted global shift of a variant against its source, pixels.
    #[arg(long, default_value_t = 0.5, help_heading = FIDELITY, hide_short_help = true)]
    max_shift: f64,
    /// Smallest accepted edge score (NCC of the structure maps at zero shift).
    #[arg(long, default_value_t = 0.6, help_heading = FIDELITY, hide_short_help = true)]
    min_edge_score: f64,
    #[command(flatten)]
    shard: ShardArg,
}

/// Runs `seasonstereo synthesize`.
pub fn run(a: SynthesizeArgs, progress: &dyn Progress) -> Result<()> {
    let generator = a.generator()?;
    eprintln!("generator: {}", generator.name());
    let s = synthesize(&a.options(), generator.as_ref(), progress)?;
    let i = &s.images;
    println!(
        "images: {} processed, {} already done (skipped), {} in this shard of {}; variants: {} accepted, {} rejected by the fidelity check (see {})",
        i.done,
        i.skipped,
        i.in_shard,
        i.total,
        s.accepted,
        s.rejected,
        a.output.join("rejected.csv").display()
    );
    Ok(())
}

impl SynthesizeArgs {
    /// The stage's options for these flags.
    fn options(&self) -> SynthesizeOptions {
        let mut opts = SynthesizeOptions::new(&self.pairs, &self.raw, &self.output);
        opts.selected = self.selected.clone();
        opts.classes_dir = self.classes.clone();
        opts.crop = self.crop;
        opts.seasons = self.seasons.clone();
        opts.shard = self.shard.shard;
        opts.fidelity.max_shift_px = self.max_shift;
        opts.fidelity.min_edge_score = self.min_edge_score;
        opts
    }

    /// The season generator: the built-in model, or the generative API with its prompts.
    fn generator(&self) -> Result<Box<dyn SeasonGenerator>> {
        Ok(match self.generator {
            GeneratorKind::Builtin => Box::new(BuiltinSeasons::new(self.seed)),
            GeneratorKind::Gemini => {
                let prompts = match &self.prompts {
                    Some(p) => Prompts::load(p)?,
                    None => Prompts::default(),
                };
                let config = GeminiConfig {
                    base_url: self.api_url.clone(),
                    model: self.model.clone(),
                    api_key_env: self.api_key_env.clone(),
                    prompts,
                    max_concurrent: self.max_concurrent.max(1),
                    cache_dir: Some(
                        self.cache
                            .clone()
                            .unwrap_or_else(|| self.output.join("api-cache")),
                    ),
                    ..GeminiConfig::default()
                };
                Box::new(GeminiGenerator::new(config)?)
            }
        })
    }
}

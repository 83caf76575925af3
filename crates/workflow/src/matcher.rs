//! Which matcher computes a disparity: the one owner of that choice for every stage (`predict`,
//! `teacher`, `eval`, the demo, `reconstruct`). Census + MGM/SGM searches a disparity range;
//! MonSter++ with weights needs none (it searches up to its max disparity).
//!
//! The range belongs to the pair, not to the matcher: [`RangeSource`] says where a pair's comes
//! from (a flag, the cameras, the rectify record, or an estimate from the images).

use anyhow::{Context, Result};
use matching::{Aggregation, DisparityRange, SgmParams};
use raster::Image;
use serde_json::json;

use crate::pairs::PairFolder;
use crate::progress::{track, Progress};

#[cfg(feature = "network")]
pub use network::{MonsterOptions, Network};

/// Where a pair's disparity range comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RangeSource {
    /// Known: `--range`, the pair's cameras, or its rectify record.
    Given(DisparityRange),
    /// Estimated from the images ([`matching::estimate_range`]; less reliable on multi-date
    /// pairs than a range from the cameras).
    Estimate,
}

impl RangeSource {
    /// The flag's range, else an estimate.
    pub fn flag_or_estimate(flag: Option<DisparityRange>) -> Self {
        flag.map_or(RangeSource::Estimate, RangeSource::Given)
    }

    /// The flag's range, else the one `rectify` recorded for pair `stem` of `pairs`, else an
    /// estimate.
    pub fn for_pair(flag: Option<DisparityRange>, pairs: &PairFolder, stem: &str) -> Result<Self> {
        if let Some(r) = flag {
            return Ok(RangeSource::Given(r));
        }
        Ok(match pairs.rectify_record(stem)? {
            Some(record) => RangeSource::Given(record.disparity_range),
            None => RangeSource::Estimate,
        })
    }

    /// The range of the pair `left`, `right`.
    pub fn resolve(self, left: &Image, right: &Image) -> Result<DisparityRange> {
        match self {
            RangeSource::Given(r) => Ok(r),
            RangeSource::Estimate => matching::estimate_range(left, right)
                .context("estimating the disparity range (give one with --range)"),
        }
    }
}

/// The matcher of a run.
#[derive(Clone, Debug)]
pub enum Matcher {
    /// Census + MGM/SGM, then the left-right, uniqueness, median and speckle filters.
    Classical(SgmParams),
    /// MonSter++ with weights, loaded once.
    #[cfg(feature = "network")]
    Network(Network),
}

/// A disparity, the range it was searched over (`None` for the network) and the confidence of
/// each disparity ([`matching::match_pair_with_confidence`]; `None` for the network, which has
/// no cost volume to read it from).
pub struct Matched {
    pub disparity: Image,
    pub range: Option<DisparityRange>,
    pub confidence: Option<Image>,
}

/// At and above this disparity per metre of altitude the classical matcher uses its `P2` as
/// given; below it, [`Matcher::for_baseline`] scales `P2` down.
pub const FULL_P2_PIXELS_PER_METRE: f64 = 1.0;

/// `P2` for a baseline of `pixels_per_metre` (disparity per metre of altitude, after any
/// stretch): `p.p2 · min(1, ppm / FULL_P2_PIXELS_PER_METRE)²`, never under `P1 + 1` (an
/// unknown slope keeps `p.p2`).
///
/// Why: a jump of `k` pixels costs `P2` once, or `k · P1` as a ramp of one-pixel steps, and the
/// matcher takes the cheaper. On a narrow baseline a roof edge is a jump of a few pixels only,
/// so a `P2` chosen on wide baselines turns edges into ramps and small buildings into mounds.
/// On the 10 dev pairs under 1 px/m the square did better than a fixed `P2` and than a linear
/// scaling, in MAE and within 1 m; on the wider baselines a lower `P2` is worse (BENCHMARKS.md,
/// "`P2` scaled to narrow baselines").
pub fn baseline_p2(p: &SgmParams, pixels_per_metre: f64) -> u16 {
    if !pixels_per_metre.is_finite() {
        return p.p2;
    }
    let scale = (pixels_per_metre / FULL_P2_PIXELS_PER_METRE).clamp(0.0, 1.0);
    let p2 = (f64::from(p.p2) * scale * scale).round() as u16;
    p2.max(p.p1.saturating_add(1)).min(p.p2)
}

impl Matcher {
    /// The matcher for a tile whose baseline gives `pixels_per_metre` ([`baseline_p2`]), or
    /// `None` when it is this one (the network, or a baseline of 1 px/m or more).
    pub fn for_baseline(&self, pixels_per_metre: f64) -> Option<Matcher> {
        match self {
            Matcher::Classical(p) => {
                let p2 = baseline_p2(p, pixels_per_metre);
                (p2 != p.p2).then(|| Matcher::Classical(SgmParams { p2, ..p.clone() }))
            }
            #[cfg(feature = "network")]
            Matcher::Network(_) => None,
        }
    }

    /// The classical matcher's `P2`; `None` for the network.
    pub fn p2(&self) -> Option<u16> {
        match self {
            Matcher::Classical(p) => Some(p.p2),
            #[cfg(feature = "network")]
            Matcher::Network(_) => None,
        }
    }

    /// Short name, e.g. for Table 1's rows: `MGM (census)`, `SGM (census)`, `MonSter++ (vitl)`.
    pub fn name(&self) -> String {
        match self {
            Matcher::Classical(p) => match p.aggregation {
                Aggregation::Mgm => "MGM (census)".to_string(),
                Aggregation::Sgm => "SGM (census)".to_string(),
            },
            #[cfg(feature = "network")]
            Matcher::Network(n) => format!("MonSter++ ({})", n.options.preset),
        }
    }

    /// The matcher and its settings in words (reports, work-folder settings).
    pub fn describe(&self) -> String {
        match self {
            Matcher::Classical(p) => p.describe(),
            #[cfg(feature = "network")]
            Matcher::Network(n) => format!(
                "MonSter++ {} ({})",
                n.options.preset,
                n.options.weights.display()
            ),
        }
    }

    /// `sgm` for the classical matcher (MGM or SGM), `monsterpp` for the network.
    pub fn kind(&self) -> &'static str {
        match self {
            Matcher::Classical(_) => "sgm",
            #[cfg(feature = "network")]
            Matcher::Network(_) => "monsterpp",
        }
    }

    /// What a record needs, beside [`Matcher::kind`], to tell two matchers apart and to rerun
    /// one: a description and the settings (a JSON object).
    pub fn settings(&self) -> serde_json::Value {
        match self {
            Matcher::Classical(p) => json!({
                "description": p.describe(),
                "p1": p.p1,
                "p2": p.p2,
                "p2_adaptive": p.p2_adaptive,
                "aggregation": format!("{:?}", p.aggregation),
                "paths": format!("{:?}", p.paths),
                "census": [p.census.width, p.census.height],
                "lr_tolerance": p.lr_tolerance,
                "uniqueness": p.uniqueness,
                "subpixel": p.subpixel,
                "median": p.median,
            }),
            #[cfg(feature = "network")]
            Matcher::Network(n) => {
                let o = &n.options;
                json!({
                    "description": "MonSter++ (zero-shot, frozen)",
                    "weights": o.weights.display().to_string(),
                    "preset": o.preset,
                    "iters": o.iters,
                    "max_disp": o.max_disp,
                    "normalisation": format!("{:?}", o.normalisation),
                })
            }
        }
    }

    /// Progress label of one pair.
    pub fn label(&self) -> &'static str {
        match self {
            Matcher::Classical(_) => "matching (census + SGM)",
            #[cfg(feature = "network")]
            Matcher::Network(_) => "matching (MonSter++)",
        }
    }

    /// Peak bytes of matching a `width × height` pair over `range` (the network: its budget).
    pub fn memory_bytes(&self, (width, height): (usize, usize), range: DisparityRange) -> u64 {
        match self {
            Matcher::Classical(_) => {
                let n = matching::disparity_count(range).unwrap_or(1);
                matching::memory_bytes(width, height, n) as u64
            }
            #[cfg(feature = "network")]
            Matcher::Network(n) => n.memory_budget(),
        }
    }

    /// Whether pairs must take turns (one network, its own threads) rather than run side by side.
    pub fn one_at_a_time(&self) -> bool {
        !matches!(self, Matcher::Classical(_))
    }

    /// Whether [`Matcher::disparity`] gives a confidence with the disparity (the classical
    /// matcher reads it from its cost volume; the network has none).
    pub fn gives_confidence(&self) -> bool {
        matches!(self, Matcher::Classical(_))
    }

    /// The disparity of the rectified pair `left`, `right` (NaN = invalid). The classical
    /// matcher searches the range `range` gives; the network ignores it.
    pub fn disparity(
        &self,
        left: &Image,
        right: &Image,
        range: RangeSource,
        progress: &dyn Progress,
    ) -> Result<Matched> {
        match self {
            Matcher::Classical(params) => {
                let range = range.resolve(left, right)?;
                let total = 5 * left.height();
                let (disparity, confidence) = track(progress, self.label(), total, |cb| {
                    matching::match_pair_with_confidence(left, right, range, params, Some(cb))
                })?;
                Ok(Matched {
                    disparity,
                    range: Some(range),
                    confidence: Some(confidence),
                })
            }
            #[cfg(feature = "network")]
            Matcher::Network(n) => Ok(Matched {
                disparity: n.predict(left, right, progress)?,
                range: None,
                confidence: None,
            }),
        }
    }
}

#[cfg(feature = "network")]
mod network {
    use std::path::PathBuf;
    use std::sync::{Arc, Mutex};

    use anyhow::{anyhow, Context, Result};
    use nn::config::MonsterConfig;
    use nn::device::DeviceChoice;
    use nn::infer::{MonsterPredictor, Normalisation};
    use raster::Image;

    use crate::progress::{track, Progress};

    /// How to run MonSter++ (`--model monsterpp`).
    #[derive(Clone, Debug)]
    pub struct MonsterOptions {
        /// Weights: an upstream `.pth` state dict or safetensors (upstream key names).
        pub weights: PathBuf,
        /// Preset: `vitl` (the released checkpoints), `vitb`, `vits` or `tiny` (the fixture).
        pub preset: String,
        /// Refinement iterations (≥ 7); `None`: the preset's (32, 8 for tiny).
        pub iters: Option<usize>,
        /// Maximum disparity, a multiple of 32; `None`: the preset's (416, 64 for tiny).
        pub max_disp: Option<usize>,
        /// Mapping of the samples to 0–255.
        pub normalisation: Normalisation,
        /// Peak memory of one forward pass, bytes; larger pairs are cut into strips of rows.
        pub memory_budget: u64,
        /// Strip height in rows (forces tiling).
        pub tile_rows: Option<usize>,
        /// Overlap of consecutive strips, rows.
        pub tile_overlap: usize,
        pub device: DeviceChoice,
    }

    impl MonsterOptions {
        /// Defaults for `weights` and `preset`.
        pub fn new(weights: impl Into<PathBuf>, preset: &str) -> Self {
            Self {
                weights: weights.into(),
                preset: preset.to_string(),
                iters: None,
                max_disp: None,
                normalisation: Normalisation::AsIs,
                memory_budget: nn::infer::DEFAULT_MEMORY_BUDGET,
                tile_rows: None,
                tile_overlap: nn::infer::DEFAULT_TILE_OVERLAP,
                device: DeviceChoice::Auto,
            }
        }

        /// The network configuration these options describe.
        pub fn config(&self) -> Result<MonsterConfig> {
            let mut config = MonsterConfig::preset(&self.preset)?;
            if let Some(i) = self.iters {
                config.iters = i;
            }
            if let Some(d) = self.max_disp {
                config.max_disp = d;
            }
            config.validate()?;
            Ok(config)
        }

        /// Builds the network and loads the weights.
        pub fn load(self) -> Result<Network> {
            let config = self.config()?;
            let device = self.device.device().map_err(anyhow::Error::msg)?;
            let mut p =
                MonsterPredictor::load(config, &self.weights, device).with_context(|| {
                    format!(
                        "loading MonSter++ `{}` from {}",
                        self.preset,
                        self.weights.display()
                    )
                })?;
            p.normalisation = self.normalisation;
            p.memory_budget = self.memory_budget;
            p.tile_rows = self.tile_rows;
            p.tile_overlap = self.tile_overlap;
            Ok(Network::new(self, p))
        }
    }

    /// A loaded MonSter++: shared by the pairs or tiles of a run, which take turns.
    #[derive(Clone)]
    pub struct Network {
        pub options: MonsterOptions,
        /// Refinement iterations it runs.
        pub iters: usize,
        predictor: Arc<Mutex<MonsterPredictor>>,
    }

    impl std::fmt::Debug for Network {
        fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
            f.debug_struct("Network")
                .field("options", &self.options)
                .finish()
        }
    }

    impl Network {
        /// A network the caller loaded (e.g. from a training configuration), described by
        /// `options` in records.
        pub fn new(options: MonsterOptions, predictor: MonsterPredictor) -> Self {
            Network {
                iters: predictor.iters,
                options,
                predictor: Arc::new(Mutex::new(predictor)),
            }
        }

        /// Peak bytes of one pass.
        pub fn memory_budget(&self) -> u64 {
            self.predictor.lock().map_or(0, |p| p.memory_budget)
        }

        /// Lowers the memory budget of one pass (a tile inside a process budget).
        pub fn limit_memory(&self, bytes: u64) {
            if let Ok(mut p) = self.predictor.lock() {
                p.memory_budget = p.memory_budget.min(bytes);
            }
        }

        /// Disparity of a rectified pair: NaN where the left image has no data. Large pairs are
        /// cut into strips of rows, one progress step each.
        pub fn predict(
            &self,
            left: &Image,
            right: &Image,
            progress: &dyn Progress,
        ) -> Result<Image> {
            let predictor = self
                .predictor
                .lock()
                .map_err(|_| anyhow!("MonSter++ failed on another pair of this run"))?;
            let strips = predictor.plan(left.width(), left.height())?;
            let c = predictor.config();
            let label = format!(
                "MonSter++ ({}, {} iterations, max disparity {}{})",
                nn::infer::preset_name(c),
                predictor.iters,
                c.max_disp,
                if strips.len() > 1 {
                    format!(
                        ", {} strips of {} rows",
                        strips.len(),
                        strips[0].1 - strips[0].0
                    )
                } else {
                    String::new()
                }
            );
            let d = track(progress, &label, strips.len(), |cb| {
                predictor.predict_with_progress(left, right, &|done, total| cb(done, total))
            })?;
            Ok(d)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Wide baselines keep the given `P2`; narrow ones scale it by the square of their slope,
    /// never under `P1 + 1`; the network is left alone.
    #[test]
    fn p2_shrinks_with_the_square_of_a_narrow_baseline() {
        let p = SgmParams::default();
        assert_eq!((p.p1, p.p2), (16, 300));
        assert_eq!(baseline_p2(&p, 2.5), 300);
        assert_eq!(baseline_p2(&p, 1.0), 300);
        assert_eq!(baseline_p2(&p, 0.5), 75);
        assert_eq!(baseline_p2(&p, 0.4), 48);
        assert_eq!(baseline_p2(&p, 0.05), 17);
        assert_eq!(baseline_p2(&p, f64::NAN), 300);
        let classical = Matcher::Classical(p.clone());
        assert_eq!(classical.p2(), Some(300));
        assert!(classical.for_baseline(1.3).is_none());
        match classical.for_baseline(0.5) {
            Some(Matcher::Classical(q)) => assert_eq!(q, SgmParams { p2: 75, ..p }),
            _ => panic!("a narrow baseline changes P2"),
        }
    }
}

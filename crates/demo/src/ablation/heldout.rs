//! The held-out test worlds of the ablation, in the benchmark's layout so that `eval` scores them
//! like real test splits: seeds no training or validation world uses, each written by
//! [`save_world`] (pair, RPCs, truth DSM), plus a cross-season split of the same pairs with the
//! left view in winter and the right one in summer (same homographies, cameras and truth).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use synth::{BuiltinSeasons, Season};
use world::WorldParams;

use crate::season_variant;
use eval::world_io::{image_ids, save_world};
use eval::Split;
use workflow::pairs::PairFolder;
use workflow::progress::Progress;

/// Held-out seeds start here above the ablation's seed (training worlds use `seed + k`,
/// validation worlds `seed + 10000 + k`).
pub const HELDOUT_SEED_OFFSET: u64 = 20_000;

/// Split names of the table's columns.
pub const SYNCHRONIC: &str = "held-out synchronic";
pub const CROSS_SEASON: &str = "held-out winter ↔ summer";

/// The held-out splits and where `eval` finds their cameras and truth.
#[derive(Clone, Debug)]
pub struct HeldOut {
    /// The synchronic split, then the cross-season one.
    pub splits: Vec<Split>,
    pub rpc_dir: PathBuf,
    pub truth_dir: PathBuf,
    /// (world seed, pair stem) in split order.
    pub worlds: Vec<(u64, String)>,
    /// The first world's cross-season views (for the report).
    pub first_winter: PathBuf,
    pub first_summer: PathBuf,
}

/// The world name of held-out seed `seed` (AOI `HELDOUT_<seed>`: one AOI per world).
pub fn world_name(seed: u64) -> String {
    format!("HELDOUT_{seed}")
}

/// Writes the held-out worlds `seeds` (at least one) of `size` px under `dir`; each world's
/// seasons come from a built-in model seeded by the world, apart from the training set's.
pub fn write_heldout(
    dir: &Path,
    size: usize,
    seeds: &[u64],
    progress: &dyn Progress,
) -> Result<HeldOut> {
    let synchronic = dir.join("synchronic");
    let cross = dir.join("winter_summer");
    let mut worlds = Vec::new();
    progress.begin("held-out worlds", seeds.len());
    for (k, &seed) in seeds.iter().enumerate() {
        let world = world::generate(&WorldParams::new(size, seed), &world::Neutral, &|_, _| {})
            .map_err(anyhow::Error::msg)
            .with_context(|| format!("generating held-out world {seed}"))?;
        let name = world_name(seed);
        let pair = save_world(&world, &synchronic, &name)?;
        let (left_id, right_id) = image_ids(&name)?;
        let generator = BuiltinSeasons::new(seed);
        let winter = season_variant(&generator, &left_id, &world.left, Season::Winter)?;
        let summer = season_variant(&generator, &right_id, &world.right, Season::Summer)?;
        let out = PairFolder::new(&cross).paths(&pair.stem);
        raster::write_image(&out.left, &winter)?;
        raster::write_image(&out.right, &summer)?;
        copy(&pair.homography, &out.homography)?;
        copy(&pair.disparity, &out.disparity)?;
        worlds.push((seed, pair.stem));
        progress.advance(k + 1);
    }
    progress.end();
    let first = PairFolder::new(&cross).paths(&worlds[0].1);
    Ok(HeldOut {
        splits: vec![
            Split {
                name: SYNCHRONIC.into(),
                dir: synchronic.clone(),
            },
            Split {
                name: CROSS_SEASON.into(),
                dir: cross,
            },
        ],
        rpc_dir: synchronic.join("rpc"),
        truth_dir: synchronic.join("truth"),
        worlds,
        first_winter: first.left,
        first_summer: first.right,
    })
}

fn copy(from: &Path, to: &Path) -> Result<()> {
    if let Some(parent) = to.parent() {
        std::fs::create_dir_all(parent)
            .with_context(|| format!("creating {}", parent.display()))?;
    }
    std::fs::copy(from, to)
        .with_context(|| format!("copying {} to {}", from.display(), to.display()))?;
    Ok(())
}
